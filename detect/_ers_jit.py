"""The numba kernels of :func:`detect.ers_superpixels` (imported on first use, so that
the flight side, which runs the default mode, never loads numba)."""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

_LN2 = math.log(2.0)


@numba.njit(cache=True)
def normalised_weights(
    n: int,
    ea: npt.NDArray[np.int64],
    eb: npt.NDArray[np.int64],
    dist: npt.NDArray[np.float64],
    sigma: float,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Gaussian similarities and self-loop weights, both divided by the total weight.

    Sums run sequentially in edge order so the rounding is the C++'s.
    """
    m = ea.shape[0]
    two_sigma_sq = 2.0 * sigma * sigma
    w = np.empty(m, dtype=np.float64)
    loop = np.zeros(n, dtype=np.float64)
    for e in range(m):
        w[e] = math.exp(-(dist[e] * dist[e]) / two_sigma_sq)
        loop[ea[e]] += w[e]
        loop[eb[e]] += w[e]
    total = 0.0
    for v in range(n):
        total += loop[v]
    if total > 0.0:  # all similarities underflow only on extreme images: keep them 0
        for e in range(m):
            w[e] /= total
        for v in range(n):
            loop[v] /= total
    return w, loop


@numba.njit(cache=True)
def _xlogx(x: float) -> float:
    return x * math.log(x) if x > 0.0 else 0.0


@numba.njit(cache=True)
def _er_gain(w: float, ci: float, cj: float, xlogx_w: float) -> float:
    """Entropy-rate gain (bits) of moving weight ``w`` from two self-loops to edge (i, j).

    ``xlogx_w`` is ``w ln w``, cached per edge.
    """
    if w <= 0.0:
        return 0.0
    return (_xlogx(w + ci) + _xlogx(w + cj) - _xlogx(ci) - _xlogx(cj) - 2.0 * xlogx_w) / _LN2


@numba.njit(cache=True)
def _b_gain(n: int, si: int, sj: int, xlogx_frac: npt.NDArray[np.float64]) -> float:
    """Balancing gain (bits, offset by 1) of merging clusters of ``si`` and ``sj`` pixels.

    ``xlogx_frac[s]`` caches ``(s / n) ln(s / n)``.
    """
    return float((-_xlogx(si / n + sj / n) + xlogx_frac[si] + xlogx_frac[sj]) / _LN2 + 1.0)


@numba.njit(cache=True)
def _find(parent: npt.NDArray[np.int32], x: int) -> int:
    while parent[x] != x:
        parent[x] = parent[parent[x]]
        x = parent[x]
    return x


# The heap is one flat float64 array: slot i (1-indexed) holds its gain at [2i] and its
# edge id at [2i + 1], so a node and its sibling share a cache line. Ties keep the parent
# above and prefer the left child, as the C++ ``MaxHeapify``.


@numba.njit(cache=True)
def _sift_down(heap: npt.NDArray[np.float64], size: int, i: int) -> None:
    """Restore the max-heap property below slot ``i``."""
    key = heap[2 * i]
    item = heap[2 * i + 1]
    while True:
        child = 2 * i
        if child > size:
            break
        if child < size and heap[2 * child + 2] > heap[2 * child]:
            child += 1
        if not heap[2 * child] > key:
            break
        heap[2 * i] = heap[2 * child]
        heap[2 * i + 1] = heap[2 * child + 1]
        i = child
    heap[2 * i] = key
    heap[2 * i + 1] = item


@numba.njit(cache=True)
def _remove_root(heap: npt.NDArray[np.float64], size: int) -> int:
    """Drop the root, returning the new size.

    Bottom-up (Floyd): the hole descends along the larger children to a leaf, then the
    last element climbs back while its parent is not larger. This places every element
    exactly where "move the last element to the root and sift down" would, with about
    half the comparisons.
    """
    key = heap[2 * size]
    item = heap[2 * size + 1]
    size -= 1
    if size == 0:
        return 0
    i = 1
    while 2 * i <= size:
        child = 2 * i
        if child < size and heap[2 * child + 2] > heap[2 * child]:
            child += 1
        heap[2 * i] = heap[2 * child]
        heap[2 * i + 1] = heap[2 * child + 1]
        i = child
    while i > 1 and not heap[2 * (i // 2)] > key:
        parent = i // 2
        heap[2 * i] = heap[2 * parent]
        heap[2 * i + 1] = heap[2 * parent + 1]
        i = parent
    heap[2 * i] = key
    heap[2 * i + 1] = item
    return size


@numba.njit(cache=True)
def lazy_greedy(
    n: int,
    ea: npt.NDArray[np.int64],
    eb: npt.NDArray[np.int64],
    w: npt.NDArray[np.float64],
    loop: npt.NDArray[np.float64],
    k: int,
    lam_k: float,
) -> tuple[npt.NDArray[np.int64], int]:
    """Greedily select edges until ``k`` clusters remain; ``loop`` is updated in place.

    Returns the cluster root of every vertex and the number of clusters reached.
    """
    m = ea.shape[0]
    parent = np.arange(n).astype(np.int32)
    size = np.ones(n, dtype=np.int32)
    # Per-edge data interleaved so that one edge costs two cache misses, not four:
    # ends[2e], ends[2e+1] = endpoints; wx[2e], wx[2e+1] = w, w ln w.
    ends = np.empty(2 * m, dtype=np.int32)
    wx = np.empty(2 * m, dtype=np.float64)
    for e in range(m):
        ends[2 * e] = ea[e]
        ends[2 * e + 1] = eb[e]
        wx[2 * e] = w[e]
        wx[2 * e + 1] = _xlogx(w[e])
    xlogx_frac = np.empty(n + 1, dtype=np.float64)
    for s in range(n + 1):
        xlogx_frac[s] = _xlogx(s / n)

    # Heap filled in edge order, as the C++ builds it from its edge array.
    heap = np.empty(2 * (m + 1), dtype=np.float64)
    max_er = 0.0
    for e in range(m):
        g = _er_gain(w[e], loop[ea[e]] - w[e], loop[eb[e]] - w[e], wx[2 * e + 1])
        heap[2 * e + 2] = g
        heap[2 * e + 3] = e
        if g > max_er:
            max_er = g
    b0 = _b_gain(n, 1, 1, xlogx_frac)  # every initial edge joins two singletons
    max_b = max(1e-20, b0) if m > 0 else 1e-20
    balancing = lam_k * max_er / abs(max_b)
    for e in range(m):
        heap[2 * e + 2] += balancing * b0
    hsize = m
    for i in range(m // 2, 0, -1):
        _sift_down(heap, hsize, i)

    clusters = n
    while clusters > k and hsize > 0:
        e = int(heap[3])
        hsize = _remove_root(heap, hsize)
        a = ends[2 * e]
        b = ends[2 * e + 1]
        ra = _find(parent, a)
        rb = _find(parent, b)
        if ra != rb:
            # union by size as the C++ (ties: b's root survives)
            if size[rb] < size[ra]:
                parent[rb] = ra
                size[ra] += size[rb]
            else:
                parent[ra] = rb
                size[rb] += size[ra]
            clusters -= 1
            loop[a] -= wx[2 * e]
            loop[b] -= wx[2 * e]
        if clusters <= k:
            break
        # Lazy evaluation: gains only shrink (submodularity), so an up-to-date root is
        # the true maximum.
        while hsize > 0:
            e = int(heap[3])
            a = ends[2 * e]
            b = ends[2 * e + 1]
            ra = _find(parent, a)
            rb = _find(parent, b)
            if ra == rb:  # would close a cycle: drop it
                hsize = _remove_root(heap, hsize)
                continue
            we = wx[2 * e]
            g = _er_gain(we, loop[a] - we, loop[b] - we, wx[2 * e + 1]) + balancing * _b_gain(
                n, size[ra], size[rb], xlogx_frac
            )
            if g == heap[2]:
                break
            heap[2] = g
            _sift_down(heap, hsize, 1)

    roots = np.empty(n, dtype=np.int64)
    for v in range(n):
        roots[v] = _find(parent, v)
    return roots, clusters
