"""Fitted coefficients of the hole-level confidence (:mod:`geotag._confidence`).

Written by ``benchmarks/calibrate_confidence.py --write``; do not edit by hand.
"""

FEATURES = ("best_logit",)
COEFFICIENTS = (1.0,)
INTERCEPT = 0.0
PROVENANCE = "placeholder: p_hole of the best frame (not fitted yet)"
