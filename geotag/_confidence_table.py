"""Fitted coefficients of the hole-level confidence (:mod:`geotag._confidence`).

Written by ``benchmarks/calibrate_confidence.py --write``; do not edit by hand.
"""

FEATURES = ("best_logit", "median_gap", "log_views", "strong_log_views", "size_spread", "scatter")
COEFFICIENTS = (1, 0.118521, -0.143416, -0.0913705, -0.0583844, 0.000502792)
INTERCEPT = 0.0
PROVENANCE = (
    "benchmarks/calibrate_confidence.py, 2026-12-06: 491 examples (330 true) from "
    "alien, hard, hover, line, survey; flight seeds 1-6, scene images with even ids "
    "of alien9, hard303; l2 0.01"
)
