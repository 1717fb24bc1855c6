"""Run one flight as configured: sensor, autopilot link, flight daemon, ground-station server.

:func:`fly` composes a :class:`~capture._flyconfig.FlyConfig` and the
:class:`~capture._flyconfig.SensorSetup` it is given (the Xtion, a recording, or the
simulator's, from :func:`sim.fly_sim`) into a :class:`~capture._daemon.Flight` and a
:class:`missions.HoleMissionServer` (on the ``gcs`` link when one is configured; else on
the one link to the autopilot, which routes to the ground station on its other port, as
on a real vehicle: companion on TELEM2, radio on TELEM1) that serves the holes passing the
announce gate as a mission, announces each new or moved one by STATUSTEXT and sends its
card (best view and facts, under the byte budget) through the daemon's ``on_holes``.
:func:`format_report` is the operator's summary.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from holescan.capture._daemon import Flight
from holescan.capture._diskbudget import DiskBudget, preflight_disk_budget
from holescan.capture._flightrecords import FlightSummary
from holescan.capture._flyconfig import FlyConfig
from holescan.capture._livemap import LiveMap, LiveMapStats
from holescan.capture._mavlink import Telemetry
from holescan.capture._sensorsetup import SensorSetup, open_sensor
from holescan.flightlog.diskspace import DiskSpace
from holescan.geotag import AnnounceGate, Hole, HoleView, Tier
from holescan.link import TelemetryError
from holescan.missions import HoleMissionServer, MapLayer

__all__ = ["FlyReport", "fly", "format_report"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FlyReport:
    """What :func:`fly` did.

    summary : the daemon's :class:`~capture._daemon.FlightSummary`. sensor : what was flown.
    announced : STATUSTEXTs sent to the ground station, in order.
    cards_sent, card_bytes : hole cards (best view + facts) sent whole, and the MAVLink
    bytes they took.
    tiles_sent, tile_bytes : live map tiles sent whole and their MAVLink bytes.
    map_stats : the live map's counters (None: no live map).
    map_tiles : the newest bytes of every map tile the flight held at its end
        ((layer, tx, ty) -> picture), what the ground station should hold.
    disk : the disk budget said before take-off (None: not checked).
    """

    summary: FlightSummary
    sensor: str
    announced: tuple[str, ...] = ()
    cards_sent: int = 0
    card_bytes: int = 0
    tiles_sent: int = 0
    tile_bytes: int = 0
    map_stats: LiveMapStats | None = None
    map_tiles: Mapping[tuple[MapLayer, int, int], bytes] = field(default_factory=dict)
    disk: DiskBudget | None = None


def fly(
    cfg: FlyConfig,
    setup: SensorSetup | None = None,
    *,
    stop: threading.Event | None = None,
    disk: DiskSpace | None = None,
) -> FlyReport:
    """Run one flight as configured; return when it ends (limit reached, source ended, stop).

    ``setup`` gives the frame source and autopilot link (None: :func:`open_sensor` of the
    configuration: the Xtion or a recording).

    ``stop`` (e.g. set by a SIGINT/SIGTERM handler) ends the flight cleanly: capture stops,
    the detection worker is drained and the MCAP log is finished and closed.

    Before anything starts, the disk budget is said (and the flight refused with
    :class:`~capture.errors.DiskBudgetError` when the planned flight does not fit and the
    configuration says refuse: :func:`~capture._diskbudget.preflight_disk_budget`).
    ``disk`` : where the log folder's free space is read (default: the real file system),
    before take-off and by the log writer's image reserve during the flight.
    """
    announced: list[str] = []
    budget = preflight_disk_budget(cfg, disk)
    fc = cfg.flight_config()
    if setup is None:
        setup = open_sensor(cfg)
    links: list[Telemetry] = []  # the flight's telemetry links, newest last

    def via_autopilot(fn: Callable[[Any], None]) -> None:
        if not links:
            raise TelemetryError("no autopilot link yet")
        links[-1].send_with(fn)

    with contextlib.ExitStack() as stack:
        server: HoleMissionServer | None = None
        if cfg.gcs or setup.mavlink:
            # With --gcs its own link; else the one link to the autopilot, which routes the
            # announcements, the hole mission and the cards to the GCS on its other port.
            server = stack.enter_context(
                HoleMissionServer(
                    cfg.gcs,
                    cfg.sysid,
                    rel_alt_m=cfg.hole_rel_alt_m,
                    clearance_m=cfg.hole_clearance_m,
                    card_bytes_per_s=cfg.hole_card_bytes_per_s,
                    sender=None if cfg.gcs else via_autopilot,
                    # its own --gcs link; else the telemetry link's signing (below) applies
                    signing=cfg.signing if cfg.gcs else None,
                )
            )
        shared = server if server is not None and not cfg.gcs else None

        def on_holes(
            served: list[Hole],
            news: list[Hole],
            views: Mapping[int, HoleView],
            tiers: Mapping[int, Tier],
        ) -> None:
            for h in news:
                _log.info(
                    "hole %d (%s) at %.7f, %.7f (p_hole %.2f, score %.2f, %d sightings)",
                    h.id,
                    tiers[h.id],
                    h.lat_deg,
                    h.lon_deg,
                    h.p_hole,
                    h.score,
                    h.sightings,
                )
            if server is not None:
                server.update_holes(served)
                # announced first: their STATUSTEXTs and cards go before the review ones
                for h in sorted(news, key=lambda h: tiers[h.id] != "announced"):
                    if (said := server.announce(h, tiers[h.id])) is not None:
                        announced.append(said)  # None: this hole's last text said the same
                    if h.id in views:
                        server.send_card(h, views[h.id].jpeg, views[h.id].why, tiers[h.id])

        live_map: LiveMap | None = None
        if server is not None and cfg.live_map is not None:
            live_map = stack.enter_context(LiveMap(setup.camera, fc.mount, cfg.live_map))
            server.set_tiles(live_map)
        mavlink = setup.mavlink
        _log.info(
            "flight log %s; sensor %s; MAVLink %s; ground station %s",
            fc.log_prefix,
            cfg.sensor,
            mavlink or "none",
            cfg.gcs or ("through the autopilot" if mavlink else "none"),
        )
        hook = setup.on_telemetry

        def telemetry(conn: str, **kw: Any) -> Telemetry:
            log_message = kw.pop("on_message", None)

            def on_message(msg: Any, t_mono_ns: int) -> None:
                if log_message is not None:
                    log_message(msg, t_mono_ns)
                if shared is not None:
                    shared.feed(msg)
                elif server is not None:  # its own link: the vehicle's status goes along
                    server.relay(msg)

            if shared is not None and cfg.signing is not None:
                # One link carries the holes too: signed as the hole server's own link
                # would be (the autopilot must hold the same key, or nothing is heard).
                kw.setdefault("signing_key", cfg.signing.key)
            tel = Telemetry(conn, baud=cfg.baud, on_message=on_message, **kw)
            links.append(tel)
            if hook is not None:
                hook(tel)
            return tel

        def flush_shared() -> None:
            if shared is None:
                return
            if live_map is not None:  # the last tiles are due (sent while the cards drain;
                live_map.close()  # not waited for: the vehicle's own traffic comes first)
                live_map.finish()
            if not shared.flush_cards(timeout_s=10.0):
                _log.warning("hole pictures still queued when the autopilot link closed")

        flight = Flight(
            fc,
            setup.factory,
            setup.camera,
            mavlink=mavlink,
            telemetry_factory=telemetry,
            usb_reset=setup.usb_reset,
            on_holes=on_holes,
            # On the shared link the last pictures must go out before the link closes.
            before_close=flush_shared if shared else None,
            on_frame=live_map.offer if live_map is not None else None,
            disk=disk,
        )
        if stop is not None:
            flight.stop = stop
        summary = flight.run()
        map_tiles: dict[tuple[MapLayer, int, int], bytes] = {}
        if live_map is not None:
            live_map.close()  # the last changes cut into tiles
            live_map.finish()  # every tile not sent yet is due now
            map_tiles = dict(live_map.outbox())
        if server is not None:
            if shared is None:
                server.flush_cards(timeout_s=10.0)  # let the last pictures go out
                if live_map is not None:
                    live_map.flush(timeout_s=10.0)  # and the last tiles
                    server.flush_cards(timeout_s=5.0)  # the last one out whole
            c = server.cards
            counts = (c.cards_sent, c.bytes_sent, c.tiles_sent, c.tile_bytes_sent)
        else:
            counts = (0, 0, 0, 0)
    return FlyReport(
        summary,
        str(cfg.sensor),
        tuple(announced),
        *counts,
        map_stats=live_map.stats if live_map is not None else None,
        map_tiles=map_tiles,
        disk=budget,
    )


def format_report(report: FlyReport, gate: AnnounceGate | None = None) -> str:
    """A few lines for the operator: frames, log, detector, telemetry, holes."""
    s = report.summary
    c = s.counters
    dur = max(s.duration_s, 1e-9)
    size_mb = s.log.bytes_written / 1e6
    lines = [
        f"flight: {s.duration_s:.1f} s, sensor {report.sensor}",
        f"frames: captured {c.frames_captured}, logged {s.frames_logged}, dropped from the log "
        f"{c.frames_log_dropped}, unposed {c.frames_unposed}",
        f"detector: {c.frames_detected} frames ({c.frames_detected / dur:.1f}/s, mean "
        f"{c.detect_ms_total / max(c.frames_detected, 1):.1f} ms), {s.detect_skipped} of "
        f"{s.detect_offered} skipped for newer frames, {c.frames_shed} not offered while the "
        f"log caught up, {c.detect_errors} errors, "
        f"{c.frames_no_depth} without depth (closer than the sensor's range or nothing "
        "ranged), "
        f"{c.detections} detections, {c.pose_refusals} not posed ({c.pose_invalid} the "
        "autopilot had no position for)",
        f"sensor: {c.sensor_failures} failures, {c.sensor_reopens} reopens",
        f"log: {len(s.log.files)} file(s), {size_mb:.1f} MB, {s.log.frames_synced} frames synced"
        + (f", error: {s.log.error}" if s.log.error else ""),
    ]
    if s.telemetry:
        tel = s.telemetry
        lines.append(
            f"telemetry: {sum(tel.get('messages', {}).values())} messages, "
            f"{tel.get('bad_bytes', 0)} garbage bytes, {tel.get('bad_packets', 0)} bad packets, "
            f"rates by {tel.get('rate_method')}, clock by {tel.get('clock_source')}"
        )
    gate = gate or AnnounceGate()
    said = {int(t.split()[1]) for t in report.announced}
    confirmed = gate.select(s.holes, said)
    lines.append(
        f"holes: {len(confirmed)} announced (p_hole >= {gate.min_p_hole:g}, >= "
        f"{gate.min_sightings} sightings over >= {gate.min_span_s:g} s) of {len(s.holes)}, "
        f"the rest candidates; "
        f"{c.announcements} announcements, {len(report.announced)} sent to the ground station"
    )
    if report.disk is not None:
        lines.append(report.disk.describe())
    if s.log.images_stopped_t_unix_ns is not None:
        lines.append(
            f"disk reserve reached: frames stopped being logged ({s.log.frames_not_logged} "
            "not logged); telemetry, detections and holes were kept"
        )
    if report.cards_sent or report.card_bytes:
        lines.append(
            f"hole pictures: {report.cards_sent} sent, {report.card_bytes} B "
            f"({report.card_bytes / dur:.0f} B/s over the flight)"
        )
    ms = report.map_stats
    if ms is not None:
        lines.append(
            f"live map: {ms.fused} of {ms.offered} frames fused "
            f"({ms.cpu_ms / max(ms.offered, 1):.2f} ms CPU per frame), "
            f"{report.tiles_sent} tiles sent, {report.tile_bytes} B "
            f"({report.tile_bytes / dur:.0f} B/s); pictures and tiles together "
            f"{(report.card_bytes + report.tile_bytes) / dur:.0f} B/s"
        )
    for h in confirmed:
        lines.append(
            f"  hole {h.id}: {h.lat_deg:.7f}, {h.lon_deg:.7f} +-{h.sigma_h_m:.2f} m, score "
            f"{h.score:.2f}, {h.sightings} sightings, {h.major_m:.2f} x {h.minor_m:.2f} m"
        )
    return "\n".join(lines)
