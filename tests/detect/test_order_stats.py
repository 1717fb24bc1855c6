"""detect._order_stats gives numpy's medians and percentiles, value and dtype."""

from __future__ import annotations

import numpy as np
import pytest

from holescan.detect._order_stats import median, percentile


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_same_as_numpy_on_random_arrays(dtype: type) -> None:
    rng = np.random.default_rng(5)
    for _ in range(1000):
        n = int(rng.integers(1, 300))
        values = (rng.random(n) * rng.choice([0.01, 1.0, 4.0]) + rng.choice([0.0, 2.5])).astype(
            dtype
        )
        if rng.random() < 0.3:  # ties, as quantised depth has
            values = np.round(values, 2).astype(dtype)
        for got, want in (
            (median(values), np.median(values)),
            (percentile(values, 90), np.percentile(values, 90)),
            (percentile(values, 99.5), np.percentile(values, 99.5)),
            (percentile(values, 10), np.percentile(values, 10)),
        ):
            assert got == want and got.dtype == want.dtype, (n, got, want)


def test_input_is_not_reordered() -> None:
    values = np.array([3.0, 1.0, 2.0, 5.0])
    median(values), percentile(values, 90)
    assert values.tolist() == [3.0, 1.0, 2.0, 5.0]
