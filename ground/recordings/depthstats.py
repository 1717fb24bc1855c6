"""What a depth frame did not read: the unread fraction and the bands at the frame border.

These are the statistics a sensor model is checked against (see ``docs/real-recordings.md``
for them measured on real structured-light frames): a registered Kinect v1 / Xtion depth
image has unread bands along its border (depth warped onto the colour camera), projector
shadows beside near edges, and dropouts on dark or far surfaces.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["UnreadStats", "border_band_px", "unread_stats"]


def border_band_px(unread: npt.NDArray[np.bool_], side: str, min_fraction: float = 0.5) -> int:
    """Width in pixels of the unread band along one side of the frame.

    The band is the run of whole columns (``left``/``right``) or rows (``top``/``bottom``),
    counted from that edge, in which at least ``min_fraction`` of the pixels are unread.

    Parameters
    ----------
    unread : (H, W) bool ndarray, True where the depth has no reading.
    side : "left", "right", "top" or "bottom".

    Examples
    --------
    >>> m = np.zeros((4, 6), bool); m[:, -2:] = True; m[0, :] = True
    >>> border_band_px(m, "right"), border_band_px(m, "top"), border_band_px(m, "left")
    (2, 1, 0)
    """
    if side in ("left", "right"):
        frac = unread.mean(axis=0)
    elif side in ("top", "bottom"):
        frac = unread.mean(axis=1)
    else:
        raise ValueError(f"side must be left, right, top or bottom, got {side!r}")
    if side in ("right", "bottom"):
        frac = frac[::-1]
    below = np.flatnonzero(frac < min_fraction)
    return int(below[0]) if below.size else int(frac.size)


@dataclass(frozen=True)
class UnreadStats:
    """Unread depth in one frame.

    unread : fraction of all pixels without a reading.
    left, right, top, bottom : border band widths, pixels (:func:`border_band_px`).
    inside : unread fraction of the frame without its border bands.
    """

    unread: float
    left: int
    right: int
    top: int
    bottom: int
    inside: float


def unread_stats(depth: npt.NDArray[np.integer]) -> UnreadStats:
    """:class:`UnreadStats` of ``depth`` ((H, W) integer ndarray, 0 = no reading).

    Examples
    --------
    >>> d = np.full((10, 20), 1500, np.uint16); d[:, -3:] = 0; d[5, 5] = 0
    >>> s = unread_stats(d)
    >>> (s.right, s.left, round(s.unread, 3), round(s.inside, 4))
    (3, 0, 0.155, 0.0059)
    """
    unread = np.asarray(depth) == 0
    h, w = unread.shape
    left, right = border_band_px(unread, "left"), border_band_px(unread, "right")
    top, bottom = border_band_px(unread, "top"), border_band_px(unread, "bottom")
    inner = unread[top : max(top, h - bottom), left : max(left, w - right)]
    return UnreadStats(
        unread=float(unread.mean()),
        left=left,
        right=right,
        top=top,
        bottom=bottom,
        inside=float(inner.mean()) if inner.size else 1.0,
    )
