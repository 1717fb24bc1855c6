"""``holescan fly --sensor sim``: the one flight path, flown over the simulated sortie.

The ``[sim]`` table of the fly configuration is checked here (the flight side keeps it as
written and never imports the simulator); :func:`fly_sim` opens a
:class:`~sim._sortie.SimSortie` (world, simulated autopilot, simulated Xtion) and hands its
frame source and autopilot link to :func:`capture.fly`; with ``--mavlink CONN`` the
autopilot at CONN flies instead and the simulated Xtion renders from the pose it reports
(:class:`~sim._reported.ReportedPoseCamera`).
"""

from __future__ import annotations

import dataclasses
import math
import statistics
import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from holescan.capture import (
    ITEMS,
    FlyConfig,
    FlyReport,
    PreflightLimits,
    PreflightReport,
    SensorSetup,
    check_table,
    fly,
    format_report,
    numbers,
    preflight,
    require_go,
)
from holescan.detect import CameraIntrinsics
from holescan.geotag import AnnounceGate, local_en_m
from holescan.sim._reported import ReportedPoseCamera
from holescan.sim._sortie import DEFAULT_ANCHOR, SimSortie, SortieParams, TrueHole
from holescan.sim._source import SimSource, WorldAnchor

__all__ = [
    "SIM_TABLE",
    "SimFlyReport",
    "check_sim",
    "fly_sim",
    "format_sim_report",
    "sortie_params",
]

SIM_LIMITS = PreflightLimits(sensor_s=30.0)
"""The pre-flight limits with the simulated Xtion: its first frame is a render (a world
built, then ray-cast on a CPU another job may hold), seconds where the real sensor streams
at once; the real sensor's 6 s would refuse a simulator that is only slow, not broken."""

_NUM = (int, float)
SIM_TABLE: Mapping[str, tuple[tuple[type, ...], Any]] = {
    "world_seed": ((int,), 7),
    "size_m": ((list,), [10.0, 10.0]),
    "margin_m": (_NUM, 3.5),
    "n_access_holes": ((int,), 3),
    "distractors": ((bool,), True),
    "lat_deg": (_NUM, DEFAULT_ANCHOR.lat_deg),
    "lon_deg": (_NUM, DEFAULT_ANCHOR.lon_deg),
    "alt_m": (_NUM, DEFAULT_ANCHOR.alt_m),
    "altitude_m": (_NUM, 3.0),
    "speed_m_s": (_NUM, None),
    "heading_deg": (_NUM, None),
    "wobble_deg": (_NUM, 1.5),
    "clock_offset_s": (_NUM, 1234.5),
    "drift_ppm": (_NUM, 15.0),
    "eph_m": (_NUM, 1.2),
    "fps": (_NUM, 30.0),
    "noise_seed": ((int,), 0),
}
"""The ``[sim]`` table: key -> (types, default), as :func:`capture.check_table` takes it."""


def sortie_params(
    table: Mapping[str, Any], where: str = "fly configuration"
) -> tuple[SortieParams, dict[str, Any]]:
    """The sortie a ``[sim]`` table describes, and its settings as flat ``sim.key`` records."""
    s = check_table("sim", table, SIM_TABLE, where)
    size = numbers(where, "sim.size_m", s["size_m"], 2)
    params = SortieParams(
        world_seed=s["world_seed"],
        size_m=(size[0], size[1]),
        margin_m=float(s["margin_m"]),
        n_access_holes=s["n_access_holes"],
        distractors=s["distractors"],
        anchor=WorldAnchor(float(s["lat_deg"]), float(s["lon_deg"]), float(s["alt_m"])),
        altitude_m=float(s["altitude_m"]),
        speed_m_s=None if s["speed_m_s"] is None else float(s["speed_m_s"]),
        heading_deg=None if s["heading_deg"] is None else float(s["heading_deg"]),
        wobble_deg=float(s["wobble_deg"]),
        clock_offset_s=float(s["clock_offset_s"]),
        drift_ppm=float(s["drift_ppm"]),
        eph_m=float(s["eph_m"]),
        fps=float(s["fps"]),
        noise_seed=s["noise_seed"],
    )
    return params, {f"sim.{k}": v for k, v in s.items()}


@dataclass(frozen=True)
class SimFlyReport:
    """A simulated flight: the flight's :class:`capture.FlyReport` and the simulator's side.

    late_frames, render_ms_median : the simulated camera's lateness (frames due more than
    one period ago when rendered) and render time (None when nothing was rendered).
    truth : the simulated world's access holes.
    """

    flight: FlyReport
    late_frames: int
    render_ms_median: float | None
    truth: tuple[TrueHole, ...]


def fly_sim(
    cfg: FlyConfig,
    *,
    stop: threading.Event | None = None,
    home: tuple[float, float, float] | None = None,
    bench: bool = True,
) -> SimFlyReport:
    """Fly ``cfg`` over the simulated world its ``[sim]`` table describes.

    Without ``cfg.mavlink``: the whole simulated sortie (its own simulated autopilot on a
    free loopback port). With it: the autopilot there flies, and the simulated Xtion renders
    each frame from the pose it reports, the world placed at its home (``home``, lat/lon/MSL,
    places it at once; see :mod:`sim._reported`). Everything else is :func:`capture.fly`'s.
    ``bench=False``: the simulated sensor and the autopilot must pass
    :func:`capture.require_go` first (``holescan fly`` without ``--bench``).
    """
    params, record = sortie_params(cfg.sim_table)
    cfg = dataclasses.replace(cfg, record={**cfg.record, **record})
    if cfg.mavlink is not None:
        cam = ReportedPoseCamera(params, CameraIntrinsics.xtion(), cfg.flight.mount, home=home)
        setup = SensorSetup(cam.source, cam.camera, cfg.mavlink, on_telemetry=cam.attach)
        if not bench:
            require_go(cfg, setup, limits=SIM_LIMITS)
        report = fly(cfg, setup, stop=stop)
        return _report(report, cam.sources, cam.truth)
    key = cfg.signing.key if cfg.signing is not None else None  # the autopilot holds it
    with SimSortie(
        params, mount=cfg.flight.mount, mavlink=cfg.mavlink, signing_key=key, sysid=cfg.sysid
    ) as sortie:
        setup = SensorSetup(sortie.source, sortie.camera, sortie.mavlink)
        if not bench:
            require_go(cfg, setup, limits=SIM_LIMITS)
        report = fly(cfg, setup, stop=stop)
    return _report(report, sortie.sources, sortie.truth)


def check_sim(
    cfg: FlyConfig,
    *,
    items: Sequence[str] = ITEMS,
    home: tuple[float, float, float] | None = None,
) -> PreflightReport:
    """``holescan check --sensor sim``: :func:`capture.preflight` of the simulated Xtion and
    autopilot that :func:`fly_sim` would fly with (``cfg.mavlink``: that autopilot, the
    simulated Xtion rendering from the pose it reports)."""
    params, _record = sortie_params(cfg.sim_table)
    if cfg.mavlink is not None:
        cam = ReportedPoseCamera(params, CameraIntrinsics.xtion(), cfg.flight.mount, home=home)
        setup = SensorSetup(cam.source, cam.camera, cfg.mavlink, on_telemetry=cam.attach)
        return preflight(cfg, setup, items=items, limits=SIM_LIMITS)
    key = cfg.signing.key if cfg.signing is not None else None
    with SimSortie(
        params, mount=cfg.flight.mount, mavlink=cfg.mavlink, signing_key=key, sysid=cfg.sysid
    ) as sortie:
        setup = SensorSetup(sortie.source, sortie.camera, sortie.mavlink)
        return preflight(cfg, setup, items=items, limits=SIM_LIMITS)


def _report(
    report: FlyReport, sources: Sequence[SimSource], truth: tuple[TrueHole, ...]
) -> SimFlyReport:
    render_ms = [ms for src in sources for ms in src.render_ms]
    return SimFlyReport(
        report,
        late_frames=sum(src.late_frames for src in sources),
        render_ms_median=statistics.median(render_ms) if render_ms else None,
        truth=truth,
    )


def format_sim_report(report: SimFlyReport, gate: AnnounceGate | None = None) -> str:
    """:func:`capture.format_report`, then the simulator's lateness and the truth found."""
    gate = gate or AnnounceGate()
    lines = [format_report(report.flight, gate)]
    ms = report.render_ms_median
    lines.append(
        f"sim: render {ms:.1f} ms/frame median, {report.late_frames} frames late"
        if ms is not None
        else "sim: no frame rendered"
    )
    said = {int(t.split()[1]) for t in report.flight.announced}
    confirmed = gate.select(report.flight.summary.holes, said)
    for t in report.truth:
        near = [
            (math.hypot(*local_en_m(h.lat_deg, h.lon_deg, t.lat_deg, t.lon_deg)), h.id)
            for h in confirmed
        ]
        d, hid = min(near, default=(math.inf, 0))
        found = f"hole {hid} at {d:.2f} m" if d <= 0.5 else "not reported"
        lines.append(f"  true access hole {t.id} ({t.x_m:.1f}, {t.y_m:.1f} m): {found}")
    return "\n".join(lines)
