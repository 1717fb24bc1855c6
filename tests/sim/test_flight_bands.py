"""The simulated Xtion's unread border bands belong to the flight: one draw, every frame."""

from __future__ import annotations

import math

from holescan.detect import CameraIntrinsics
from holescan.geotag import VehiclePose
from holescan.sim import SimSource, WorldAnchor, make_world
from holescan.sim.registration_bands import BAND_PROFILES

CAM = CameraIntrinsics.xtion()
ANCHOR = WorldAnchor(43.6532, -79.3832, 120.0)


def _hover(t_mono_ns: int) -> VehiclePose:
    """2.8 m over the middle of the 8 x 6 m world, drifting 0.3 m/s east."""
    east, north = 4.0 + 0.3 * t_mono_ns * 1e-9, 3.0
    lat = ANCHOR.lat_deg + math.degrees(north / 6_378_137.0)
    lon = ANCHOR.lon_deg + math.degrees(east / (6_378_137.0 * math.cos(math.radians(lat))))
    return VehiclePose(t_mono_ns, lat, lon, ANCHOR.alt_m + 2.8, 2.8, 0.0, 0.0, 0.0, ve=0.3)


def test_every_frame_of_a_flight_has_the_flights_bands() -> None:
    world = make_world(3, (8.0, 6.0), n_access_holes=1, n_stains=0, n_shadows=0)
    src = SimSource(world, ANCHOR, _hover, CAM, seed=5)
    b = src.bands
    assert b == SimSource(world, ANCHOR, _hover, CAM, seed=5).bands  # seeded
    assert b.profile in {p.name for p in BAND_PROFILES} and b.right > 0
    h, w = CAM.height, CAM.width
    for t in (0, 200_000_000, 400_000_000):
        _, depth, _, _ = src.render_at(t)
        assert not depth[:, : b.left].any() and not depth[:, w - b.right :].any()
        assert not depth[: b.top].any() and not depth[h - b.bottom :].any()
        # just inside the bands the ground reads (the misregistration adds at most 4 px)
        inner = depth[b.top + 5 : h - b.bottom - 5, b.left + 5 : w - b.right - 5]
        assert (inner > 0).mean() > 0.8
    profiles = {SimSource(world, ANCHOR, _hover, CAM, seed=s).bands.profile for s in range(8)}
    assert len(profiles) == 2  # flights come from both ways of registering
