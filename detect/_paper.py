"""Paper mode: the access-hole detector of Kong et al. (JFR 2015) as published.

Pipeline (paper section 2; ``/work/shared/ALGORITHM.md``):

1. Over-segment the depth image into ``params.superpixels`` entropy-rate superpixels
   (:func:`detect._ers.ers_superpixels`) run, as the authors' prototype did, on the depth
   rescaled to grey ``255 z / max z``.
2. Region adjacency graph: superpixels sharing a boundary (8-connected).
3. Candidates: regions whose mean depth is a local maximum, deeper than every neighbour.
   Each candidate gets five scores in [0, 1]:

   - Sd, relative depth: ``ramp(d, searcher.depth_low_m, searcher.depth_high_m)`` with
     ``d`` the smallest depth difference to a neighbour (prototype);
   - Sw, width: an ellipse fitted to the region's 3-D points (outliers beyond 3 sigma
     dropped, projected to the best-fit plane), both axes against the searcher's;
   - Sr, fill: region area over the area of the box spanned by the two axes;
   - Sb, darkness: mean luminance Y of the region against ``params.dark_threshold``;
   - Sc, contrast: neighbours' mean Y minus the region's against
     ``params.contrast_threshold``.

4. ``S = sum_i w_i S_i + b`` (``params.weights``, ``params.bias``); one detection per
   candidate with the region's tight bounding box.

Choices where the paper is vague
--------------------------------
- **ERS input**: depth in sensor units rescaled to ``255 z / max z`` and truncated to
  uint8, as the prototype's call into the ERS mex file did; pixels without a reading are
  0 (black) there, which makes unread areas their own superpixels.
- **Invalid depth in region means**: a pixel without a reading counts as 4.0 m (the
  prototype's 4000 mm) when averaging a region's depth, so unread hole floors come out
  deep. ``depth_rel_m`` of such a region is then a lower bound.
- **Local maximum**: strictly deeper than every neighbour; a region without neighbours
  (``superpixels == 1``) is no candidate. Non-candidates give no detection.
- **Adjacency**: 8-connected, like the ERS pixel graph and MATLAB's ``bwlabel``.
- **Ellipse**: the "3 sigma" filter keeps the points within 3 standard deviations of
  the mean along each principal axis of the region's 3-D points; the plane is refitted
  to the kept points (PCA, normal = least-variance axis) and the ellipse axes are the
  moment ellipse's full axes, ``4 sqrt(eigenvalue)`` of the in-plane covariance (exact
  for a uniformly filled ellipse; a ``L`` x ``M`` rectangle gives ``1.155 L`` x
  ``1.155 M``).
- **Regions without depth** (``beyond_range``: over half of the pixels unread): the
  paper has no points to fit; the opening is measured where it is, at the rim: all its
  pixels are back-projected at ``rim_depth_m``. Otherwise only pixels with a reading
  are used.
- **Region area** for Sr: the sum of each kept pixel's footprint on the fitted plane,
  ``Z^2 / (fx fy |n . (x/z, y/z, 1)|)`` (the incidence factor is floored at 0.05 so a
  grazing plane cannot blow it up); ``Sr = min(1, area / (major minor))``, so a filled
  ellipse scores pi/4 and a rectangle 3/4.
- **Neighbour brightness** for Sc: the mean Y over all pixels of the neighbouring
  regions (paper), not the mean of their means (prototype).
- **rim_depth_m**: mean of the valid depth readings of all neighbouring regions'
  pixels (the surrounding terrain); if they have none, the mean of their region means.
- **Border**: a candidate touching the image border keeps its features but gets score
  0 (prototype), because only part of the opening is seen; it is still returned, so a
  caller can show or drop it.
- **Score range**: ``S`` is clipped to [0, 1] in case weights and bias do not keep it
  there.
- **Boxes** are inclusive of the last row and column (the prototype's ``max - min``
  was one pixel short).
- Not reproduced from the prototype (it is not in the paper): merging dark neighbouring
  superpixels before scoring, and treating mean depths <= 0.5 m as corrupt.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from holescan.detect._ers import ers_superpixels
from holescan.detect._scores import contrast_score, darkness_score, luminance, ramp, width_score
from holescan.detect._types import PAPER, CameraIntrinsics, Detection, DetectParams, FeatureScores
from holescan.errors import InputError

__all__ = ["detect_paper", "paper_superpixels", "score_regions"]

_log = logging.getLogger(__name__)

INVALID_DEPTH_M = 4.0
"""Depth a pixel without a reading counts as when averaging a region (prototype)."""
_BEYOND_RANGE_FRACTION = 0.5
_MIN_INCIDENCE = 0.05
_NO_DEPTH = (
    "depth image has no reading at all (every pixel is 0): check that the depth stream "
    "is running and registered, or that the scene is within the sensor's range"
)


def detect_paper(
    rgb: npt.NDArray[np.uint8],
    depth: npt.NDArray[np.uint16],
    camera: CameraIntrinsics,
    params: DetectParams = PAPER,
) -> list[Detection]:
    """Find access holes in one registered RGB-D frame with the published method.

    Parameters
    ----------
    rgb : (H, W, 3) uint8 ndarray
        Colour image registered to the depth image.
    depth : (H, W) uint16 ndarray
        Depth in units of ``camera.depth_unit_m`` (millimetres for the Xtion);
        0 = no reading.
    camera : CameraIntrinsics
        Intrinsics of the depth-registered camera; ``width`` x ``height`` must be W x H.
    params : DetectParams
        Uses ``superpixels``, ``ers_lambda``, ``ers_sigma``, ``dark_threshold``,
        ``contrast_threshold``, ``weights``, ``bias`` and ``searcher``.

    Returns
    -------
    list of Detection
        One per candidate region (local depth maximum), highest score first.

    Raises
    ------
    InputError
        On wrong shapes or dtypes, a size that differs from the camera's, a depth image
        without any reading, or an invalid number of superpixels.
    """
    _validate(rgb, depth, camera)
    labels = paper_superpixels(depth, params)
    detections = score_regions(labels, rgb, depth, camera, params)
    _log.debug("paper mode: %d superpixels, %d candidates", int(labels.max()) + 1, len(detections))
    return detections


def paper_superpixels(
    depth: npt.NDArray[np.uint16], params: DetectParams = PAPER
) -> npt.NDArray[np.int32]:
    """The ERS over-segmentation the paper mode scores.

    Parameters
    ----------
    depth : (H, W) uint16 ndarray
        Depth in sensor units, 0 = no reading; at least one reading.
    params : DetectParams
        Uses ``superpixels`` (K), ``ers_lambda`` and ``ers_sigma``.

    Returns
    -------
    labels : (H, W) int32 ndarray
        Superpixel ids ``0 .. K-1`` of ERS run on ``uint8(255 z / max z)``.
    """
    if not isinstance(depth, np.ndarray) or depth.dtype != np.uint16 or depth.ndim != 2:
        raise InputError("depth must be an (H, W) uint16 array")
    z_max = int(depth.max())
    if z_max == 0:
        raise InputError(_NO_DEPTH)
    grey = (255.0 * depth.astype(np.float64) / z_max).astype(np.uint8)
    return ers_superpixels(grey, params.superpixels, params.ers_lambda, params.ers_sigma)


@dataclass(frozen=True)
class _Regions:
    """Per-region sums over a label image, each of shape (K,)."""

    count: npt.NDArray[np.float64]
    valid: npt.NDArray[np.float64]
    depth_sum_valid: npt.NDArray[np.float64]
    mean_depth: npt.NDArray[np.float64]  # invalid pixels count as INVALID_DEPTH_M
    y_sum: npt.NDArray[np.float64]
    border: npt.NDArray[np.bool_]


def score_regions(
    labels: npt.NDArray[np.int32],
    rgb: npt.NDArray[np.uint8],
    depth: npt.NDArray[np.uint16],
    camera: CameraIntrinsics,
    params: DetectParams = PAPER,
) -> list[Detection]:
    """Score the regions of a given segmentation (steps 2-4 of the paper's pipeline).

    ``labels`` is an (H, W) integer ndarray of region ids ``0 .. K-1`` (each region one
    connected piece); the other arguments are as for :func:`detect_paper`, which calls
    this on the ERS superpixels.
    """
    _validate(rgb, depth, camera)
    if labels.shape != depth.shape:
        raise InputError(f"labels shape {labels.shape} differs from depth {depth.shape}")
    k = int(labels.max()) + 1
    depth_m = depth.astype(np.float64) * camera.depth_unit_m
    valid = depth > 0
    lum = luminance(rgb).astype(np.float64)
    regions = _region_sums(labels, k, depth_m, valid, lum)
    adjacent = _adjacency(labels, k)
    boxes = ndimage.find_objects(labels + 1, max_label=k)
    searcher = params.searcher

    detections = []
    for i in range(k):
        nbrs = np.flatnonzero(adjacent[i])
        box_slices = boxes[i]
        if nbrs.size == 0 or box_slices is None:
            continue
        diffs = regions.mean_depth[i] - regions.mean_depth[nbrs]
        if not np.all(diffs > 0.0):
            continue
        d = float(diffs.min())
        nbr_valid = float(regions.valid[nbrs].sum())
        if nbr_valid > 0:
            rim = float(regions.depth_sum_valid[nbrs].sum()) / nbr_valid
        else:
            rim = float(regions.mean_depth[nbrs].mean())
        beyond = bool(regions.valid[i] < (1.0 - _BEYOND_RANGE_FRACTION) * regions.count[i])

        rows, cols = box_slices
        mask = labels[box_slices] == i
        vv, uu = np.nonzero(mask)
        vv = vv + rows.start
        uu = uu + cols.start
        if beyond:
            z = np.full(vv.shape, rim)
        else:
            keep = valid[vv, uu]
            vv, uu = vv[keep], uu[keep]
            z = depth_m[vv, uu]
        major, minor, area = _ellipse(uu, vv, z, camera)

        region_y = float(regions.y_sum[i] / regions.count[i])
        nbr_y = float(regions.y_sum[nbrs].sum() / regions.count[nbrs].sum())
        features = FeatureScores(
            depth=ramp(d, searcher.depth_low_m, searcher.depth_high_m),
            width=width_score(
                major, minor, searcher.major_m, searcher.minor_m, searcher.min_fraction
            ),
            fill=min(1.0, area / (major * minor)) if major * minor > 0.0 else 0.0,
            darkness=darkness_score(region_y, params.dark_threshold),
            contrast=contrast_score(region_y, nbr_y, params.contrast_threshold),
        )
        score = 0.0
        if not regions.border[i]:
            total = sum(w * s for w, s in zip(params.weights, features.as_tuple(), strict=True))
            score = min(1.0, max(0.0, total + params.bias))
        detections.append(
            Detection(
                box=(cols.start, rows.start, cols.stop - cols.start, rows.stop - rows.start),
                score=score,
                features=features,
                depth_rel_m=d,
                major_m=major,
                minor_m=minor,
                rim_depth_m=rim,
                beyond_range=beyond,
            )
        )
    detections.sort(key=lambda det: det.score, reverse=True)
    return detections


def _validate(
    rgb: npt.NDArray[np.uint8], depth: npt.NDArray[np.uint16], camera: CameraIntrinsics
) -> None:
    h, w = camera.height, camera.width
    if not isinstance(depth, np.ndarray) or depth.dtype != np.uint16 or depth.shape != (h, w):
        got = (depth.shape, depth.dtype) if isinstance(depth, np.ndarray) else type(depth)
        raise InputError(f"depth must be a ({h}, {w}) uint16 array (camera size), got {got}")
    if not isinstance(rgb, np.ndarray) or rgb.dtype != np.uint8 or rgb.shape != (h, w, 3):
        got_rgb = (rgb.shape, rgb.dtype) if isinstance(rgb, np.ndarray) else type(rgb)
        raise InputError(f"rgb must be a ({h}, {w}, 3) uint8 array (camera size), got {got_rgb}")
    if not depth.any():
        raise InputError(_NO_DEPTH)


def _region_sums(
    labels: npt.NDArray[np.int32],
    k: int,
    depth_m: npt.NDArray[np.float64],
    valid: npt.NDArray[np.bool_],
    lum: npt.NDArray[np.float64],
) -> _Regions:
    flat = labels.ravel()
    count = np.bincount(flat, minlength=k).astype(np.float64)
    n_valid = _weighted_count(flat, valid.ravel().astype(np.float64), k)
    depth_sum = _weighted_count(flat, depth_m.ravel(), k)
    mean_depth = (depth_sum + (count - n_valid) * INVALID_DEPTH_M) / np.maximum(count, 1.0)
    y_sum = _weighted_count(flat, lum.ravel(), k)
    border = np.zeros(k, dtype=bool)
    for edge in (labels[0, :], labels[-1, :], labels[:, 0], labels[:, -1]):
        border[edge] = True
    return _Regions(count, n_valid, depth_sum, mean_depth, y_sum, border)


def _weighted_count(
    flat: npt.NDArray[np.int32], weights: npt.NDArray[np.float64], k: int
) -> npt.NDArray[np.float64]:
    return np.asarray(np.bincount(flat, weights=weights, minlength=k), dtype=np.float64)


def _adjacency(labels: npt.NDArray[np.int32], k: int) -> npt.NDArray[np.bool_]:
    """(K, K) bool matrix: regions touching across an 8-connected pixel pair."""
    adjacent = np.zeros((k, k), dtype=bool)
    pairs = (
        (labels[:, :-1], labels[:, 1:]),
        (labels[:-1, :], labels[1:, :]),
        (labels[:-1, :-1], labels[1:, 1:]),
        (labels[1:, :-1], labels[:-1, 1:]),
    )
    for a, b in pairs:
        differ = a != b
        adjacent[a[differ], b[differ]] = True
    return adjacent | adjacent.T


def _ellipse(
    u: npt.NDArray[np.intp],
    v: npt.NDArray[np.intp],
    z: npt.NDArray[np.float64],
    camera: CameraIntrinsics,
) -> tuple[float, float, float]:
    """Moment ellipse of pixels ``(u, v)`` at depths ``z`` metres, on their best-fit plane.

    Returns the full major and minor axes and the region's area on the plane (m, m, m^2);
    zeros when fewer than 3 points remain.
    """
    if z.size < 3:
        return 0.0, 0.0, 0.0
    xn = (u - camera.cx) / camera.fx
    yn = (v - camera.cy) / camera.fy
    pts = np.column_stack((xn * z, yn * z, z))
    _, axes = _principal(pts)
    coords = (pts - pts.mean(axis=0)) @ axes
    sd = coords.std(axis=0)
    keep = np.all(np.abs(coords) <= 3.0 * sd + 1e-9, axis=1)
    if int(keep.sum()) < 3:
        return 0.0, 0.0, 0.0
    var, axes = _principal(pts[keep])
    major = 4.0 * float(np.sqrt(max(var[2], 0.0)))
    minor = 4.0 * float(np.sqrt(max(var[1], 0.0)))
    normal = axes[:, 0]
    incidence = np.abs(normal[0] * xn[keep] + normal[1] * yn[keep] + normal[2])
    footprint = z[keep] ** 2 / (camera.fx * camera.fy * np.maximum(incidence, _MIN_INCIDENCE))
    return major, minor, float(footprint.sum())


def _principal(
    pts: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Eigenvalues (ascending) and eigenvectors (columns) of the points' covariance."""
    centred = pts - pts.mean(axis=0)
    cov = centred.T @ centred / pts.shape[0]
    var, axes = np.linalg.eigh(cov)
    return var, axes
