"""Fitted by ``python benchmarks/calibrate.py`` (do not edit by hand)."""

# (raw default-mode score, probability of a true access hole); linear between.
P_HOLE_TABLE: tuple[tuple[float, float], ...] = ((0.0, 0.0), (1.0, 1.0))
