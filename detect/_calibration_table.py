"""Fitted by ``python benchmarks/calibrate.py`` (do not edit by hand).

Data: synth200s2, alien7, hard_dev.
Calibration split (seed 0): 201 detections; held-out Brier score 0.0421.
"""

# (raw default-mode score, probability of a true access hole); linear between.
P_HOLE_TABLE: tuple[tuple[float, float], ...] = (
    (0.0000, 0.0100),
    (0.1169, 0.0100),
    (0.3277, 0.5000),
    (0.3722, 0.6000),
    (0.4330, 0.8889),
    (0.5418, 0.9024),
    (0.8092, 0.9900),
    (1.0000, 0.9900),
)
