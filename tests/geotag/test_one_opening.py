"""One opening, one hole: however the detector boxes it and whichever way the vehicle passes.

The case of issue 21: a moving line over one opening gave two holes 2.6 cm apart
(1.27 x 0.74 and 1.29 x 0.69 m, 144 and 18 sightings): in 18 frames the detector boxed the
opening twice, and the tracker, which gives each hole one sighting per frame, started a
second hole with the second box and fed it whenever the opening was boxed twice again.
"""

from __future__ import annotations

import math

import pymap3d
import pytest

from holescan.detect import FeatureScores
from holescan.geotag import HoleSighting, HoleTracker

LAT0, LON0, ALT0 = 47.3769, 8.5417, 400.0
F = FeatureScores(0.9, 0.8, 0.7, 0.6, 0.5)
GPS = 1.2


def sighting(
    k: int,
    north: float,
    east: float = 0.0,
    *,
    major: float = 1.27,
    minor: float = 0.74,
    score: float = 0.8,
    cut: bool = False,
    x_px: int = 300,
) -> HoleSighting:
    lat, lon, alt = pymap3d.ned2geodetic(north, east, 0.0, LAT0, LON0, ALT0)
    return HoleSighting(
        float(lat),
        float(lon),
        float(alt),
        math.hypot(GPS, 0.03),
        score,
        major,
        minor,
        1_000_000_000 + k * 100_000_000,
        k,
        (x_px, 200, 120, 70),
        F,
        sigma_gps_m=GPS,
        range_m=3.0,
        sigma_opening_m=0.03,
        cut_by_border=cut,
    )


def line_pass(reverse: bool) -> list[list[HoleSighting]]:
    """162 frames over one opening: enters cut by the border, whole, boxed twice in 18
    frames (1.29 x 0.69 m, 2.6 cm away), split into two halves in 6, leaves cut."""
    frames = []
    for k in range(162):
        x = 640 - 4 * k if not reverse else 4 * k
        if k < 8:  # entering: only its near part in view, off its centre
            frames.append([sighting(k, 0.45, major=0.35, minor=0.3, cut=True, x_px=0)])
        elif k >= 154:
            frames.append([sighting(k, -0.45, major=0.4, minor=0.3, cut=True, x_px=600)])
        elif k % 8 == 3:  # boxed twice
            frames.append(
                [
                    sighting(k, 0.0, major=1.29, minor=0.69, score=0.5, x_px=x),
                    sighting(k, 0.026, score=0.7, x_px=x),
                ]
            )
        elif k % 24 == 5:  # split into two halves
            frames.append(
                [
                    sighting(k, 0.32, major=0.64, minor=0.7, score=0.6, x_px=x),
                    sighting(k, -0.32, major=0.63, minor=0.7, score=0.55, x_px=x),
                ]
            )
        else:
            frames.append([sighting(k, 0.01 * math.sin(k), x_px=x)])
    return frames[::-1] if reverse else frames


@pytest.mark.parametrize("reverse", [False, True])
def test_a_moving_line_over_one_opening_is_one_hole(reverse: bool) -> None:
    frames = line_pass(reverse)
    t0 = frames[0][0].t_boot_ns
    tracker = HoleTracker()
    for k, f in enumerate(frames):  # the reverse pass: same views, the other way round
        tracker.update([_at(s, t0 + k * 100_000_000) for s in f])
    (hole,) = tracker.holes()
    assert hole.id == 1
    assert hole.sightings == len(frames)  # one sighting per frame, each frame counted
    n, e, _ = pymap3d.geodetic2ned(hole.lat_deg, hole.lon_deg, ALT0, LAT0, LON0, ALT0)
    assert math.hypot(n, e) < 0.1
    assert 1.2 < hole.major_m < 1.35  # the whole opening's size, not a part's


def _at(s: HoleSighting, t_ns: int) -> HoleSighting:
    from dataclasses import replace

    return replace(s, t_boot_ns=t_ns)


def test_a_part_seen_first_is_fused_into_the_whole_when_their_openings_overlap() -> None:
    tracker = HoleTracker()
    tracker.update([sighting(0, 0.8, major=0.4, minor=0.3, cut=True)])  # beyond the gate
    tracker.update([sighting(1, 0.0)])
    for k in range(2, 10):
        tracker.update([sighting(k, 0.0)])
    (hole,) = tracker.holes()
    assert (hole.id, hole.sightings) == (1, 10)
    assert tracker.merged() == {2: 1}
    tracker.update([sighting(10, 5.0, major=0.8)])  # another opening: a new id, never 2
    assert [h.id for h in tracker.holes()] == [1, 3]


def test_two_openings_seen_apart_in_one_frame_are_never_fused() -> None:
    tracker = HoleTracker()
    for k in range(20):  # 0.9 m apart, 0.7 m wide: their estimates never overlap
        tracker.update([sighting(k, 0.0, major=0.7), sighting(k, 0.9, major=0.7)])
    assert [h.sightings for h in tracker.holes()] == [20, 20]
    # later seen one at a time, from a drifting GPS that brings them within 0.7 m
    for k in range(20, 30):
        tracker.update([sighting(k, 0.35, major=0.7)])
    assert len(tracker.holes()) == 2
