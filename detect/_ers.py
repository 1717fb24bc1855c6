"""Entropy Rate Superpixels (Liu, Tuzel, Ramalingam, Chellappa, CVPR 2011).

The over-segmentation the paper mode runs on the depth image. The method, as in the
authors' C++ (``MERCLazyGreedy``), reimplemented here:

1. One vertex per pixel, 8-connected: for pixel ``(y, x)`` in raster order the edges to
   the right, down, down-right and up-right neighbours. Edge distance
   ``d = |I_a - I_b|`` (times sqrt 2 on diagonals), similarity
   ``w = exp(-d**2 / (2 sigma**2))``.
2. Every vertex carries a self-loop holding the weight of its unselected edges
   (initially the sum of its incident ``w``); all weights are divided by the total.
3. Adding edge ``(i, j)`` to the selected set gains, in entropy rate,
   ``g_H = [f(w + c_i) + f(w + c_j) - f(c_i) - f(c_j) - 2 f(w)] / ln 2`` with
   ``f(x) = x ln x`` and ``c = loop - w``; in balance of the cluster sizes (fractions
   ``a``, ``b`` of the pixels) ``g_B = [-f(a + b) + f(a) + f(b)] / ln 2 + 1``.
   The objective weighs them as ``g_H + lambda g_B`` with
   ``lambda = lambda' K max g_H / max g_B`` over the initial edges.
4. Lazy greedy: a max-heap on the gains; the root's gain is recomputed and, if it
   changed, the edge sinks and the next root is tried; an up-to-date root is accepted
   (its two clusters are merged, ``loop[i] -= w``, ``loop[j] -= w``); edges inside one
   cluster are dropped. Stop when ``K`` clusters remain.

Each cluster is a tree of pixel-graph edges, so every superpixel is one 8-connected
region, and because the pixel grid is connected the greedy always reaches exactly ``K``.

Differences from the C++, all in degenerate corners: ``0 ln 0 = 0`` (and rounding
residues below 0 count as 0) where the C++ lets ``NaN`` zero the whole gain; a
non-cycle edge whose gain drops to exactly 0 stays in the heap (the C++ discards it,
which could stop the greedy short of ``K``); when every similarity underflows to 0 the
weights are left unnormalised instead of dividing by 0. Union-find uses path halving
with the C++'s union-by-size rule, and labels are numbered by ascending cluster root
as ``DisjointSetToLabel`` does.
"""

from __future__ import annotations

import math
import numbers

import numba
import numpy as np
import numpy.typing as npt

from holescan.errors import HolescanError, InputError

__all__ = ["ers_superpixels"]

_LN2 = math.log(2.0)
_SQRT2 = math.sqrt(2.0)


def ers_superpixels(
    image: npt.ArrayLike, k: int, lam: float = 0.5, sigma: float = 5.0
) -> npt.NDArray[np.int32]:
    """Partition a grey image into exactly ``k`` entropy-rate superpixels.

    Parameters
    ----------
    image : (H, W) ndarray, uint8 or float
        Grey levels (the paper mode passes depth rescaled to 0..255). Any real dtype;
        values must be finite.
    k : int
        Number of superpixels, ``1 <= k <= H * W``.
    lam : float
        ``lambda'``, weight of the balancing term relative to the entropy rate
        (ERS default 0.5); must be >= 0.
    sigma : float
        Width of the Gaussian similarity, in grey levels (ERS default 5.0); > 0.

    Returns
    -------
    labels : (H, W) int32 ndarray
        Labels ``0 .. k-1``; every label is one 8-connected region.

    Raises
    ------
    InputError
        If the image is not a finite real 2-D array or ``k``, ``lam``, ``sigma`` are
        out of range.
    """
    img = _validated_image(image)
    height, width = img.shape
    n = height * width
    if isinstance(k, bool) or not isinstance(k, numbers.Integral):
        raise InputError(f"k must be an integer number of superpixels, got {k!r}")
    k = int(k)
    if not 1 <= k <= n:
        raise InputError(f"k must be between 1 and the number of pixels ({n}), got {k}")
    if not (math.isfinite(lam) and lam >= 0.0):
        raise InputError(f"lam (lambda') must be a finite number >= 0, got {lam!r}")
    if not (math.isfinite(sigma) and sigma > 0.0):
        raise InputError(f"sigma must be a finite number > 0, got {sigma!r}")

    ea, eb, dist = _grid_edges(img)
    w = np.exp(-(dist * dist) / (2.0 * sigma * sigma))
    loop = np.bincount(ea, weights=w, minlength=n) + np.bincount(eb, weights=w, minlength=n)
    total = float(loop.sum())
    if total > 0.0:
        w /= total
        loop /= total
    roots, clusters = _lazy_greedy(n, ea, eb, w, loop, k, lam * k)
    if clusters != k:  # impossible on a connected grid; guard against silent truncation
        raise HolescanError(f"ERS stopped at {clusters} clusters instead of {k}")
    _, labels = np.unique(roots, return_inverse=True)
    return labels.reshape(height, width).astype(np.int32)


def _validated_image(image: npt.ArrayLike) -> npt.NDArray[np.float64]:
    arr = np.asarray(image)
    if arr.ndim != 2 or arr.size == 0:
        raise InputError(f"image must be a non-empty (H, W) array, got shape {arr.shape}")
    if arr.dtype == np.bool_ or not (
        np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)
    ):
        raise InputError(f"image must hold real numbers (uint8 or float), got {arr.dtype}")
    img = arr.astype(np.float64)
    if not np.all(np.isfinite(img)):
        raise InputError("image contains NaN or infinite values; replace them first")
    return img


def _grid_edges(
    img: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.float64]]:
    """8-connected grid edges in the C++ order: per pixel right, down, down-right, up-right.

    Returns endpoint indices ``a``, ``b`` (raster index ``y * W + x``) and the distance
    ``|I_a - I_b|`` (times sqrt 2 on diagonals), each of shape (E,).
    """
    height, width = img.shape
    idx = np.arange(height * width, dtype=np.int64).reshape(height, width)
    a = np.full((height, width, 4), -1, dtype=np.int64)
    b = np.full((height, width, 4), -1, dtype=np.int64)
    d = np.zeros((height, width, 4), dtype=np.float64)
    # right: (y, x) - (y, x+1)
    a[:, :-1, 0] = idx[:, :-1]
    b[:, :-1, 0] = idx[:, 1:]
    d[:, :-1, 0] = np.abs(img[:, :-1] - img[:, 1:])
    # down: (y, x) - (y+1, x)
    a[:-1, :, 1] = idx[:-1, :]
    b[:-1, :, 1] = idx[1:, :]
    d[:-1, :, 1] = np.abs(img[:-1, :] - img[1:, :])
    # down-right: (y, x) - (y+1, x+1)
    a[:-1, :-1, 2] = idx[:-1, :-1]
    b[:-1, :-1, 2] = idx[1:, 1:]
    d[:-1, :-1, 2] = _SQRT2 * np.abs(img[:-1, :-1] - img[1:, 1:])
    # up-right: (y, x) - (y-1, x+1)
    a[1:, :-1, 3] = idx[1:, :-1]
    b[1:, :-1, 3] = idx[:-1, 1:]
    d[1:, :-1, 3] = _SQRT2 * np.abs(img[1:, :-1] - img[:-1, 1:])
    valid = a >= 0
    return a[valid], b[valid], d[valid]


@numba.njit(cache=True)  # type: ignore[misc]
def _xlogx(x: float) -> float:
    return x * math.log(x) if x > 0.0 else 0.0


@numba.njit(cache=True)  # type: ignore[misc]
def _er_gain(w: float, ci: float, cj: float) -> float:
    """Entropy-rate gain (bits) of moving weight ``w`` from two self-loops to edge (i, j)."""
    if w <= 0.0:
        return 0.0
    return (
        _xlogx(w + ci) + _xlogx(w + cj) - _xlogx(ci) - _xlogx(cj) - 2.0 * _xlogx(w)
    ) / _LN2


@numba.njit(cache=True)  # type: ignore[misc]
def _b_gain(n: int, si: int, sj: int) -> float:
    """Balancing gain (bits, offset by 1) of merging clusters of ``si`` and ``sj`` pixels."""
    a = si / n
    b = sj / n
    return (-_xlogx(a + b) + _xlogx(a) + _xlogx(b)) / _LN2 + 1.0


@numba.njit(cache=True)  # type: ignore[misc]
def _find(parent: npt.NDArray[np.int64], x: int) -> int:
    while parent[x] != x:
        parent[x] = parent[parent[x]]
        x = parent[x]
    return x


@numba.njit(cache=True)  # type: ignore[misc]
def _sift_down(
    heap: npt.NDArray[np.int64], size: int, gain: npt.NDArray[np.float64], i: int
) -> None:
    """Restore the max-heap property below 1-indexed slot ``i`` (ties keep the parent)."""
    while True:
        left = 2 * i
        right = left + 1
        largest = i
        if left <= size and gain[heap[left]] > gain[heap[largest]]:
            largest = left
        if right <= size and gain[heap[right]] > gain[heap[largest]]:
            largest = right
        if largest == i:
            return
        tmp = heap[i]
        heap[i] = heap[largest]
        heap[largest] = tmp
        i = largest


@numba.njit(cache=True)  # type: ignore[misc]
def _lazy_greedy(
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
    parent = np.arange(n)
    size = np.ones(n, dtype=np.int64)
    gain = np.empty(m, dtype=np.float64)
    max_er = 0.0
    for e in range(m):
        g = _er_gain(w[e], loop[ea[e]] - w[e], loop[eb[e]] - w[e])
        gain[e] = g
        if g > max_er:
            max_er = g
    b0 = _b_gain(n, 1, 1)  # every initial edge joins two singletons
    max_b = max(1e-20, b0) if m > 0 else 1e-20
    balancing = lam_k * max_er / abs(max_b)
    for e in range(m):
        gain[e] += balancing * b0

    heap = np.empty(m + 1, dtype=np.int64)
    for e in range(m):
        heap[e + 1] = e
    hsize = m
    for i in range(m // 2, 0, -1):
        _sift_down(heap, hsize, gain, i)

    clusters = n
    while clusters > k and hsize > 0:
        e = heap[1]
        heap[1] = heap[hsize]
        hsize -= 1
        _sift_down(heap, hsize, gain, 1)
        ra = _find(parent, ea[e])
        rb = _find(parent, eb[e])
        if ra != rb:
            # union by size as the C++ (ties: b's root survives)
            if size[rb] < size[ra]:
                parent[rb] = ra
                size[ra] += size[rb]
            else:
                parent[ra] = rb
                size[rb] += size[ra]
            clusters -= 1
            loop[ea[e]] -= w[e]
            loop[eb[e]] -= w[e]
        if clusters <= k:
            break
        # Lazy evaluation: gains only shrink (submodularity), so an up-to-date root is
        # the true maximum.
        while hsize > 0:
            e = heap[1]
            ra = _find(parent, ea[e])
            rb = _find(parent, eb[e])
            if ra == rb:  # would close a cycle: drop it
                heap[1] = heap[hsize]
                hsize -= 1
                _sift_down(heap, hsize, gain, 1)
                continue
            g = _er_gain(w[e], loop[ea[e]] - w[e], loop[eb[e]] - w[e]) + balancing * _b_gain(
                n, size[ra], size[rb]
            )
            if g == gain[e]:
                break
            gain[e] = g
            _sift_down(heap, hsize, gain, 1)

    roots = np.empty(n, dtype=np.int64)
    for v in range(n):
        roots[v] = _find(parent, v)
    return roots, clusters
