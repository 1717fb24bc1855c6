"""Simulated flights shared by the reprocessing and campaign tests (flown once per session).

Each is a real short flight: the flight daemon, the simulated autopilot over loopback UDP,
the simulated Xtion over one small rubble world (two access holes), 40 frames at 6
frames/s, the log rotated every 3 s. ``sortie_a`` and ``sortie_b`` fly different paths
(opposite corners first, another vehicle's boot clock) over the same world.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from holescan.capture import Flight, FlightConfig, FlightSummary
from holescan.detect import CameraIntrinsics
from holescan.flightlog import LogOptions
from holescan.geotag import AnnounceGate
from holescan.sim import RubbleWorld, SimAutopilot, SimPath, SimSource, WorldAnchor, make_world
from tests._support import free_udp_port

CAM = CameraIntrinsics.xtion()
ANCHOR = WorldAnchor(43.6532, -79.3832, 120.0)
GATE = AnnounceGate(min_p_hole=0.5, review_min_p_hole=0.05)
"""The sorties' gate (not the default)."""

Flown = tuple[list[Path], FlightSummary]


@pytest.fixture(scope="session")
def world() -> RubbleWorld:
    return make_world(
        11,
        (8.0, 6.0),
        n_access_holes=2,
        n_small_holes=2,
        n_cracks=1,
        n_depressions=1,
        n_stains=1,
        n_shadows=1,
    )


def fly(world: RubbleWorld, out: Path, name: str, reverse: bool, uptime_s: float) -> Flown:
    xs = [h.centre_xy[0] for h in world.access_holes]
    ys = [h.centre_xy[1] for h in world.access_holes]
    x0, x1 = max(min(xs) - 0.6, 1.8), min(max(xs) + 0.6, 6.2)
    y0, y1 = max(min(ys) - 0.4, 1.5), min(max(ys) + 0.4, 4.5)
    corners = ((x0, y0, 2.8), (x1, y0, 2.8), (x1, y1, 2.8), (x0, y1, 2.8))
    path = SimPath(
        home_lat_deg=ANCHOR.lat_deg,
        home_lon_deg=ANCHOR.lon_deg,
        home_alt_m=ANCHOR.alt_m,
        waypoints_enu=tuple(reversed(corners)) if reverse else corners,
        speed_m_s=0.8,
    )
    port = free_udp_port()
    with SimAutopilot(f"udpout:127.0.0.1:{port}", path, uptime_at_start_s=uptime_s) as ap:

        def source() -> SimSource:
            truth = lambda t: ap.truth_pose(ap.boot_ns_at_mono(t))  # noqa: E731
            return SimSource(world, ANCHOR, truth, CAM, fps=6.0)

        cfg = FlightConfig(
            log_prefix=out / name,
            max_frames=40,
            # Lossless colour (depth is always lossless): reprocessing sees the pixels the
            # flight detected on, and must find exactly its holes.
            log_options=LogOptions(max_file_s=3.0, color="png"),
            pose_wait_s=1.0,  # a loaded test machine can delay telemetry; the flight waits
            # Not the default gate: the log records it, reprocessing gives its tiers with it.
            announce_min_p_hole=GATE.min_p_hole,
            review_min_p_hole=GATE.review_min_p_hole,
        )
        summary = Flight(cfg, source, CAM, mavlink=f"udpin:127.0.0.1:{port}").run()
    files = list(summary.log.files)
    assert len(files) >= 2 and summary.frames_logged == 40
    assert summary.holes  # (how many frames the flight detected depends on the machine load)
    return files, summary


@pytest.fixture(scope="session")
def flight(world: RubbleWorld, tmp_path_factory: pytest.TempPathFactory) -> Flown:
    """Sortie A, logged as ``sortie_NNNN.mcap``."""
    return fly(world, tmp_path_factory.mktemp("flight"), "sortie", False, 37.25)


@pytest.fixture(scope="session")
def flight_b(world: RubbleWorld, tmp_path_factory: pytest.TempPathFactory) -> Flown:
    """Sortie B: the other way round, another vehicle (boot clock 5000 s), ``second_NNNN``."""
    return fly(world, tmp_path_factory.mktemp("flight_b"), "second", True, 5000.0)
