"""The simulators' random stream: xorshift64* seeded per frame, usable inside numba kernels.

Fast and reproducible: one ``(1,) uint64`` state array per frame, advanced in place by the
compiled kernels that draw from it. Normal deviates are read from an inverse-CDF table of
4096 equiprobable values (``normal_table()``), cheaper in a kernel than a Box-Muller pair
and exact enough for sensor noise.
"""

from __future__ import annotations

import functools

import numpy as np
import numpy.typing as npt
from numba import njit
from scipy.special import ndtri

__all__ = ["TABLE_BITS", "next_u64", "normal", "normal_table", "stream_state", "uniform"]

F64 = npt.NDArray[np.float64]
U64 = npt.NDArray[np.uint64]

TABLE_BITS = 12


@functools.cache
def normal_table() -> F64:
    """The 4096 equiprobable standard-normal values ``normal`` draws from."""
    n = 1 << TABLE_BITS
    return np.asarray(ndtri((np.arange(n) + 0.5) / n), dtype=np.float64)


@njit(cache=True, inline="always")
def next_u64(state: U64) -> np.uint64:
    """Advance ``state`` (a (1,) uint64 array) and return the next 64-bit value."""
    x = state[0]
    x ^= x >> np.uint64(12)
    x ^= x << np.uint64(25)
    x ^= x >> np.uint64(27)
    state[0] = x
    return np.uint64(x * np.uint64(0x2545F4914F6CDD1D))


@njit(cache=True, inline="always")
def uniform(state: U64) -> float:
    """A uniform deviate in [0, 1) with 53 bits."""
    return float(next_u64(state) >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@njit(cache=True, inline="always")
def normal(state: U64, table: F64) -> float:
    """A standard-normal deviate read from ``table`` (``normal_table()``)."""
    return float(table[int(next_u64(state) >> np.uint64(64 - TABLE_BITS))])


def stream_state(rng: np.random.Generator) -> U64:
    """A new stream's state, seeded from ``rng`` (the frame's generator)."""
    seed = int(rng.integers(1, 2**63 - 1))
    return np.array([seed], dtype=np.uint64)
