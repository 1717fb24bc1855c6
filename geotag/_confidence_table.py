"""Fitted coefficients of the hole-level confidence (:mod:`geotag._confidence`).

Written by ``benchmarks/calibrate_confidence.py --write``; do not edit by hand.
"""

FEATURES = ("best_logit", "median_gap", "log_views", "strong_log_views", "size_spread", "scatter")
COEFFICIENTS = (1, -1.07134, 0.398888, 0.12598, -0.0587757, 0.092223)
INTERCEPT = 0.0
PROVENANCE = (
    "benchmarks/calibrate_confidence.py, 2026-12-03: 1152 examples (924 true) from "
    "alien, hard, hover, line, survey; flight seeds 1-16, scene images with even ids "
    "of alien9, hard303; l2 0.01"
)
