"""``holescan fly --sensor sim --mavlink CONN``: the simulated Xtion flown by any autopilot.

The autopilot here is the pymavlink one, flying the survey over the simulated world, but it
is only a peer at ``CONN``: the camera renders each frame from the pose the flight's own
telemetry reports (not the simulator's truth), the world placed at the autopilot's home.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

from holescan.capture import parse_fly_config
from holescan.detect import CameraIntrinsics
from holescan.flightlog import LoggedDetections, LoggedFrame, read_flight_log
from holescan.geotag import local_en_m, project_to_pixel
from holescan.sim import SimAutopilot, anchor_at_home, fly_sim, sortie_params
from holescan.sim._sortie import loop_length_m, make_sortie_world, survey_path
from tests._support import free_udp_port

TABLE = {"size_m": [4.0, 4.0], "world_seed": 15, "n_access_holes": 4, "fps": 10.0}


def test_anchor_at_home_puts_home_margin_inside_the_world() -> None:
    home = (43.6532, -79.3832, 120.0)
    a = anchor_at_home(home, 3.5)
    east, north = local_en_m(home[0], home[1], a.lat_deg, a.lon_deg)
    assert east == pytest.approx(3.5, abs=1e-3) and north == pytest.approx(3.5, abs=1e-3)
    assert a.alt_m == 120.0


def test_an_area_of_one_survey_line_is_flown_as_a_racetrack() -> None:
    size = (3.0, 3.0)
    # One camera footprint wide: the planner gives one straight line; the simulated
    # vehicle flies it out and back (a loop it can repeat), never a 2-point "loop".
    params, _ = sortie_params({"size_m": list(size), "world_seed": 3})
    world = make_sortie_world(params)
    plan, path = survey_path(world, params)
    assert len(plan.lines) == 1
    pts = path.waypoints_enu
    assert len(pts) >= 4
    SimAutopilot("udpout:127.0.0.1:9", path)  # its trajectory is flyable (never entered)
    ((a, b),) = plan.lines
    line_m = math.hypot(*local_en_m(a.lat_deg, a.lon_deg, b.lat_deg, b.lon_deg))
    assert loop_length_m(path) > 2.0 * line_m  # out along the line and back


def _fly_once(tmp_path: Path) -> tuple[Any, SimAutopilot, list[Any], dict[int, int]]:
    """One simulated sortie flown from the telemetry's poses: its report, the simulator,
    the logged frames and, for each true hole, the frames the detector took
    and the flight placed with the hole squarely in view (its centre in the middle of the
    image, from the frame's logged pose)."""
    params, _ = sortie_params(TABLE)
    world = make_sortie_world(params)
    plan, path = survey_path(world, params)
    home = (plan.path[0].lat_deg, plan.path[0].lon_deg, params.anchor.alt_m)
    port = free_udp_port()
    cfg = parse_fly_config(
        {
            "sensor": "sim",
            "sim": TABLE,
            "holes": {"announce_min_sightings": 3},
            # a loaded machine can delay telemetry: the flight holds each frame up to 1 s
            # for the telemetry after it (as the reprocessing sorties); it can stall the
            # renderer for seconds: no sensor reopen (as the sim accuracy test)
            "capture": {"pose_wait_s": 1.0, "frame_timeout_s": 60.0},
        },
        # 90 frames, however long rendering takes on a busy machine (180 s: a hang guard);
        # the detector takes a third to a half of them, fewer loaded
        {
            "log_dir": tmp_path,
            "mavlink": f"udpin:127.0.0.1:{port}",
            "duration_s": 180.0,
            "max_frames": 90,
        },
    )
    with SimAutopilot(f"udpout:127.0.0.1:{port}", path, eph_m=0.01) as ap:
        report = fly_sim(cfg, home=home)
    s = report.flight.summary
    frames = [r for r in read_flight_log(s.log.files) if isinstance(r, LoggedFrame)]
    detected = {
        r.frame_index
        for r in read_flight_log(s.log.files, kinds={LoggedDetections})
        if isinstance(r, LoggedDetections)
    }
    cam = CameraIntrinsics.xtion()
    looked: dict[int, int] = {}
    for f in frames:
        if f.pose is None or f.frame.index not in detected:
            continue
        for t in report.truth:
            u, v = project_to_pixel(t.lat_deg, t.lon_deg, t.alt_m, cam, cfg.flight.mount, f.pose)
            if abs(u - cam.width / 2) < cam.width / 4 and abs(v - cam.height / 2) < cam.height / 4:
                looked[t.id] = looked.get(t.id, 0) + 1
    return report, ap, frames, looked


@pytest.mark.slow
def test_sim_camera_renders_from_the_reported_pose(tmp_path: Path) -> None:
    params, _ = sortie_params(TABLE)
    # The flight must find a true hole it looked at: squarely in view in at least 2 frames
    # its detector took and the flight placed. Which frames those are is the machine's (the
    # detector takes the newest frame whenever it is free: fewer loaded; once, in a full
    # parallel run, none of 90 frames), so that, not the flight path, is what a hole must be
    # found from; a flight that looked at none is flown again (at most 3 flights), every
    # flight's poses checked.
    for attempt in range(3):
        report, ap, frames, looked = _fly_once(tmp_path / f"flight{attempt}")
        s = report.flight.summary
        # fly_sim never saw the simulator: frames were rendered from the telemetry's poses,
        # which the logged frames carry; they match the simulator's truth at the frame time.
        errors = []
        for f in frames:
            if f.pose is None or f.t_boot_ns is None:
                continue
            t = ap.truth_pose(f.t_boot_ns)
            errors.append(
                math.hypot(*local_en_m(f.pose.lat_deg, f.pose.lon_deg, t.lat_deg, t.lon_deg))
            )
        assert len(errors) >= 30 and sorted(errors)[len(errors) // 2] < 0.1, errors
        assert s.counters.frames_captured == 90, s.counters
        assert report.render_ms_median is not None
        truth = report.truth
        assert len(truth) == 4 and abs(truth[0].lat_deg - params.anchor.lat_deg) < 1e-3
        assert ap.received.get("TIMESYNC", 0) > 0
        looked_at = [t for t in truth if looked.get(t.id, 0) >= 2]
        if looked_at:
            break
    assert looked_at, looked  # the sortie flies over holes and the detector sees some
    off = [
        min(math.hypot(*local_en_m(h.lat_deg, h.lon_deg, t.lat_deg, t.lon_deg)) for h in s.holes)
        for t in looked_at
        if s.holes
    ]
    assert off and min(off) < 0.5, (looked, off, s.holes)  # one of them found, in place
