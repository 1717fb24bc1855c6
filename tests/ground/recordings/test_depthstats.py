"""Unread fraction and border bands of a depth frame, on frames with known bands."""

from __future__ import annotations

import numpy as np
import pytest

from holescan.ground.recordings import border_band_px, unread_stats


def test_bands_of_a_registered_frame() -> None:
    depth = np.full((480, 640), 2000, np.uint16)
    depth[:, -33:] = 0  # right band
    depth[:14, :] = 0  # top band
    depth[-9:, :] = 0  # bottom band
    depth[:, :3] = 0  # left band
    depth[200:210, 300:310] = 0  # a dropout inside
    s = unread_stats(depth)
    assert (s.left, s.right, s.top, s.bottom) == (3, 33, 14, 9)
    inner = (480 - 14 - 9) * (640 - 3 - 33)
    assert s.inside == pytest.approx(100 / inner)
    assert s.unread == pytest.approx(float((depth == 0).mean()))


def test_a_band_counts_columns_mostly_unread() -> None:
    unread = np.zeros((10, 10), bool)
    unread[:6, -1] = True  # 60 % of the last column: band
    unread[:4, -2] = True  # 40 %: not
    assert border_band_px(unread, "right") == 1
    assert border_band_px(unread, "right", min_fraction=0.3) == 2
    with pytest.raises(ValueError, match="side"):
        border_band_px(unread, "middle")


def test_all_unread_frame() -> None:
    s = unread_stats(np.zeros((4, 5), np.uint16))
    assert s.unread == 1.0 and s.inside == 1.0 and s.right == 5 and s.top == 4
