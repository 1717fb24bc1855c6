"""Fitted by ``python benchmarks/calibrate.py`` (do not edit by hand).

Data: synth200s2, alien7, hard101, fitted 2026-12-06.
- synth200s2: 91 images with a detection; sensor: not recorded
- alien7: 28 images with a detection; sensor: structured-light
- hard101: 30 images with a detection; sensor: structured-light
Calibration split (seed 0): 109 detections; held-out Brier score 0.0312.
"""

# p_hole = 1 / (1 + exp(-(a * score + b))) for a raw default-mode score.
P_HOLE_LOGISTIC: tuple[float, float] = (19.9450, -7.7994)
