"""Fitted coefficients of the hole-level confidence (:mod:`geotag._confidence`).

Written by ``benchmarks/calibrate_confidence.py --write``; do not edit by hand.
"""

FEATURES = ("best_logit", "median_gap", "log_views", "strong_log_views", "size_spread", "scatter")
COEFFICIENTS = (1, -1.20911, 0.414506, 0.147312, -0.0853311, 0.107744)
INTERCEPT = 0.0
PROVENANCE = (
    "benchmarks/calibrate_confidence.py, 2026-12-03: 1079 examples (871 true) from "
    "alien, hover, line, survey; flight seeds 1-16, scene images with even ids of "
    "alien9; l2 0.01"
)
