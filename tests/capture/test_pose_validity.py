"""Issue 20: a pose the autopilot does not have never geotags anything (flight end to end).

The pymavlink autopilot reproduces what ArduPilot SITL did on the companion's link: a boot
without a GPS fix (GLOBAL_POSITION_INT at lat = lon = 0, GPS_RAW_INT fix_type 1, EKF in
constant-position mode), a fix that arrives late, and a fix lost in flight (the EKF
dead-reckons, its position drifting away). Frames are logged and detected throughout;
holes come only from frames the autopilot had a position for, at the right place.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Mapping
from pathlib import Path

from holescan.capture import Flight, FlightConfig
from holescan.flightlog import LoggedFrame, LoggedMavlink, read_flight_log
from holescan.geotag import Hole, HoleView, MergeParams, local_en_m
from holescan.link import mavlink
from holescan.sim import SimAutopilot, SimPath
from tests._support import free_udp_port
from tests.capture.test_daemon import CAM, ScriptedSource

HOME = (43.6532, -79.3832)  # SimPath's default home
POSE_WAIT_NS = round(FlightConfig.pose_wait_s * 1e9)  # the default, as _fly flies


def _hover() -> SimPath:
    """Hovering within a centimetre: the scripted frames' hole stays where it is."""
    return SimPath(
        waypoints_enu=((0.0, 0.0, 2.5), (0.01, 0.0, 2.5), (0.01, 0.01, 2.5)), speed_m_s=0.005
    )


Flown = tuple[Flight, list[Hole], list[LoggedFrame], list[LoggedMavlink]]


def _fly(tmp_path: Path, ap_fix: bool, script: list[tuple[float, bool]], n_frames: int) -> Flown:
    """Fly ``n_frames`` of the scripted hole over the hovering autopilot; ``script`` sets
    its GPS fix when that many frames were captured (30 a second). Returns the flight, every
    hole it announced (in order), the logged frames and the autopilot's logged messages."""
    port = free_udp_port()
    announced: list[Hole] = []

    def on_holes(
        served: list[Hole], news: list[Hole], views: Mapping[int, HoleView], tiers: object
    ) -> None:
        announced.extend(news)

    with SimAutopilot(f"udpout:127.0.0.1:{port}", _hover(), gps_fix=ap_fix) as ap:
        cfg = FlightConfig(log_prefix=tmp_path / "flight", max_frames=n_frames, startup_sync_s=1.0)
        flight = Flight(
            cfg,
            lambda: ScriptedSource(n_frames + 10),
            CAM,
            mavlink=f"udpin:127.0.0.1:{port}",
            on_holes=on_holes,
        )

        def switch() -> None:
            for at_frame, fix in script:
                while flight.counters.frames_captured < at_frame and not flight.stop.is_set():
                    time.sleep(0.01)
                ap.gps_fix = fix

        threading.Thread(target=switch, daemon=True).start()
        summary = flight.run()
    records = list(read_flight_log(summary.log.files, kinds={LoggedFrame, LoggedMavlink}))
    frames = [r for r in records if isinstance(r, LoggedFrame)]
    assert summary.frames_logged == n_frames == len(frames)  # every frame logged
    return flight, announced, frames, [r for r in records if isinstance(r, LoggedMavlink)]


def _lost_as_reported(messages: list[LoggedMavlink]) -> tuple[int, int]:
    """(from, to) autopilot boot ns: from the first GPS_RAW_INT without a 3-D fix to the
    first with one again, by the messages' own times (the estimator's status, which can
    say it sooner, carries no time)."""
    mav = mavlink.MAVLink(None)
    lost: int | None = None
    for r in messages:
        if r.name != "GPS_RAW_INT":
            continue
        msg = mav.decode(bytearray(r.packet))
        t = int(msg.time_usec) * 1000
        if lost is None and msg.fix_type < 3:
            lost = t
        elif lost is not None and msg.fix_type >= 3 and t > lost:
            return lost, t
    raise AssertionError(f"the autopilot never reported the fix lost and back: {lost}")


def _dist_home_m(h: Hole) -> float:
    return math.hypot(*local_en_m(h.lat_deg, h.lon_deg, *HOME))


def test_boot_without_fix_geotags_nothing(tmp_path: Path) -> None:
    flight, announced, frames, _ = _fly(tmp_path, False, [], 75)
    assert flight.tracker.holes() == [] and announced == []  # no Null Island hole
    c = flight.counters
    assert c.frames_detected >= 3 and c.detections >= 3  # detected all the same
    assert c.pose_refusals == c.pose_invalid >= 3, c
    assert "no position yet" in flight.invalid or "fix" in flight.invalid, flight.invalid
    assert all(f.pose is None for f in frames)


def test_late_fix_places_holes_only_from_then_on(tmp_path: Path) -> None:
    flight, announced, frames, _ = _fly(tmp_path, False, [(60, True)], 150)
    holes = flight.tracker.holes()
    assert len(holes) == 1, holes  # one opening, one hole (not a second at 0/0)
    assert all(_dist_home_m(h) < 1.0 for h in holes + announced), holes
    assert flight.counters.pose_invalid >= 1, flight.counters
    posed = [f for f in frames if f.pose is not None]
    assert posed and frames[0].pose is None
    assert all(abs(f.pose.lat_deg - HOME[0]) < 1e-3 for f in posed if f.pose is not None)


def test_fix_lost_in_flight_places_nothing_while_lost(tmp_path: Path) -> None:
    # Lost from frame 60 to 120 (2 s): the EKF drifts 1.5 m/s east meanwhile (3 m).
    flight, announced, frames, messages = _fly(tmp_path, True, [(60, False), (120, True)], 180)
    lost, back = _lost_as_reported(messages)
    assert flight.counters.pose_invalid >= 1, flight.counters
    posed = [f for f in frames if f.pose is not None and f.t_boot_ns is not None]
    assert posed
    # From the autopilot's first word that the fix is gone to its word that it is back,
    # nothing is posed (after it, only once the position has settled: the jump back is an
    # estimator reset). A message is stamped when its sample was taken and arrives later:
    # a frame is posed with what has arrived when its own positions have (their wait, 0.5 s,
    # bounds it), so frames of the first tens of ms after the word may still be posed.
    late = [f.frame.index for f in posed if lost + POSE_WAIT_NS <= (f.t_boot_ns or 0) < back]
    assert late == [], late
    first = frames.index(posed[0])
    assert any(f.pose is None for f in frames[first:]), "the frames while lost: unposed"
    # Before that word the companion cannot know: a pose drifts as the estimator dead-
    # reckons (1.5 m/s) until the next GPS_RAW_INT (5 Hz) says so, later when a starved
    # simulator sends it late. Every hole lies within that drift of the opening, and one
    # hole it is while no sighting drifted beyond the tracker's gate (a sighting farther
    # off may stand apart: the companion had no way to tell).
    drift = [
        math.hypot(*local_en_m(f.pose.lat_deg, f.pose.lon_deg, *HOME)) for f in posed if f.pose
    ]
    far = max(drift)
    holes = flight.tracker.holes()
    assert holes and all(_dist_home_m(h) < far + 0.2 for h in holes + announced), (far, holes)
    if far < MergeParams().min_radius_m:
        assert len(holes) == 1, (far, holes)  # the drift while lost (3 m) would make a second
