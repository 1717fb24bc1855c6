"""The unread bands at the border of registered structured-light depth, per recording.

A Kinect v1 / Xtion depth image warped onto the colour camera has no reading along its
border, where the depth camera's view does not cover the colour camera's. How wide each band
is depends on who registers (the host, as freenect and ROS do for a Kinect v1, or OpenNI2's
driver, as on an Xtion) and on the unit, not on the frame: :func:`draw_bands` draws them once
per flight or recording, from one of the measured :class:`BandProfile` (``docs/sensor-model.md``
compares them with real frames). Widths are pixels at 640 px wide.

Examples
--------
>>> b = draw_bands(np.random.default_rng(1), 640)
>>> b.profile in [p.name for p in BAND_PROFILES] and b.right > 0
True
>>> draw_bands(np.random.default_rng(1), 640) == b  # seeded
True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "BAND_PROFILES",
    "KINECT_HOST_REGISTERED",
    "OPENNI2_REGISTERED",
    "BandProfile",
    "Bands",
    "draw_bands",
]


@dataclass(frozen=True)
class BandProfile:
    """The unread border bands of one way of registering depth onto the colour camera.

    Each ``(lo, hi)`` is the range of a band's width in pixels at 640 px wide, drawn once
    per recording (:func:`draw_bands`): the warp is the device's and the driver's, the same
    for every frame; what moves it between recordings is the unit's calibration and the
    scene's depth (the colour camera sits ~2.5 cm from the infrared one: f x 2.5 cm / Z,
    7 px at 2 m, 4 px at 3.5 m).
    """

    name: str
    left_px: tuple[int, int]
    right_px: tuple[int, int]
    top_px: tuple[int, int]
    bottom_px: tuple[int, int]

    def __post_init__(self) -> None:
        for lo, hi in (self.left_px, self.right_px, self.top_px, self.bottom_px):
            if not 0 <= lo <= hi:
                raise ValueError(f"band range {(lo, hi)} of {self.name!r}: need 0 <= lo <= hi")


#: Kinect v1 depth registered onto colour on the host (freenect, ROS): FIELD-NOTES (TUM,
#: SUN RGB-D: right 28-43, top 12-13, bottom 8-10, left 2-11) and those frames measured by
#: ``unread_stats`` (TUM 14 / 33 / 14 / 13, SUN 2 / 45 / 15 / 10 left / right / top / bottom).
KINECT_HOST_REGISTERED = BandProfile(
    "kinect-v1 host-registered",
    left_px=(0, 14),
    right_px=(24, 45),
    top_px=(8, 15),
    bottom_px=(6, 13),
)
#: OpenNI2 registering in its driver (an Xtion's usual path): the real OpenNI2 frame in
#: ``tests/data/real/mrpt-openni2`` (left 23, right 16, top 16, bottom 6), widest on the
#: left, +- the depth-dependent part of the registration shift (4 px across, 2 px down).
OPENNI2_REGISTERED = BandProfile(
    "openni2 driver-registered",
    left_px=(19, 27),
    right_px=(12, 20),
    top_px=(14, 18),
    bottom_px=(4, 8),
)
BAND_PROFILES = (KINECT_HOST_REGISTERED, OPENNI2_REGISTERED)


@dataclass(frozen=True)
class Bands:
    """The border bands of one recording, pixels at its frame width (``profile``: the name
    of the :class:`BandProfile` they were drawn from)."""

    left: int
    right: int
    top: int
    bottom: int
    profile: str = ""

    @property
    def ltrb(self) -> tuple[int, int, int, int]:
        """(left, top, right, bottom), the order scene records carry them in."""
        return (self.left, self.top, self.right, self.bottom)


def draw_bands(
    rng: np.random.Generator, width: int, profiles: tuple[BandProfile, ...] = BAND_PROFILES
) -> Bands:
    """The border bands of one recording (a flight, a recorded sequence) ``width`` px wide:
    one of ``profiles`` chosen uniformly, then each band's width in its range (both ends
    included), scaled to the width. Pass the result to every frame of the recording
    (``structured_light_frame(..., bands=)``).

    >>> draw_bands(np.random.default_rng(0), 320, (OPENNI2_REGISTERED,)).left in range(9, 15)
    True
    """
    if not profiles:
        raise ValueError("draw_bands needs at least one band profile")
    prof = profiles[int(rng.integers(len(profiles)))]
    k = width / 640.0

    def px(r: tuple[int, int]) -> int:
        return round(int(rng.integers(r[0], r[1] + 1)) * k)

    return Bands(
        left=px(prof.left_px),
        right=px(prof.right_px),
        top=px(prof.top_px),
        bottom=px(prof.bottom_px),
        profile=prof.name,
    )
