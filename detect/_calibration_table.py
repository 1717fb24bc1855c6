"""Fitted by ``python benchmarks/calibrate.py`` (do not edit by hand).

Data: synth200s2, alien7, hard_dev.
Calibration split (seed 0): 201 detections; held-out Brier score 0.0355.
"""

# p_hole = 1 / (1 + exp(-(a * score + b))) for a raw default-mode score.
P_HOLE_LOGISTIC: tuple[float, float] = (15.9464, -5.8723)
