"""Fitted coefficients of the hole-level confidence (:mod:`geotag._confidence`).

Written by ``benchmarks/calibrate_confidence.py --write``; do not edit by hand.
"""

FEATURES = ("best_logit", "median_gap", "log_views", "strong_log_views", "size_spread", "scatter")
COEFFICIENTS = (1, 0.184438, -0.357441, 0.122522, -0.188601, 0.000724131)
INTERCEPT = 0.0
PROVENANCE = (
    "benchmarks/calibrate_confidence.py, 2026-12-06: 1207 examples (708 true) from "
    "alien, hard, hover, line, survey; flight seeds 1-12 (structured-light sensor "
    "model under the vehicle's image motion), scene images with even ids of alien9, "
    "hard303; l2 0.01"
)
