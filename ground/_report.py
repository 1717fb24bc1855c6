"""The offline flight report: one HTML file a rescue team opens without any network.

:func:`write_report` writes a single self-contained page: inline CSS, an inline SVG map of
the flight track and the holes drawn to scale in a local metric frame (there are no map
tiles offline), a table of the holes and, for each hole, its best colour and depth view
cropped around the detection box. Images are base64 PNG data URIs; the page needs no
script, font or URL from outside the file. The output is deterministic (no clock is read),
so two reports of the same flight are byte-identical.
"""

from __future__ import annotations

import base64
import html
import logging
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from importlib.metadata import version as _dist_version
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
import pymap3d
from shapely.geometry import LineString

from capture import crop_view
from geotag import Hole, VehiclePose
from ground._overlay import depth_colour
from holescan_errors import InputError

__all__ = [
    "SCORE_BANDS",
    "ScoreBand",
    "render_report",
    "score_band",
    "thumbnails",
    "write_report",
]

logger = logging.getLogger(__name__)

BestView = tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint16]]


@dataclass(frozen=True)
class ScoreBand:
    """A confidence class of holes: scores ``>= min_score`` (down to the next band) get ``rgb``."""

    name: str
    min_score: float
    rgb: tuple[int, int, int]

    @property
    def hex(self) -> str:
        """The colour as CSS ``#rrggbb``."""
        return "#{:02x}{:02x}{:02x}".format(*self.rgb)


SCORE_BANDS: tuple[ScoreBand, ...] = (
    ScoreBand("high", 0.7, (211, 47, 47)),
    ScoreBand("medium", 0.5, (239, 108, 0)),
    ScoreBand("low", -math.inf, (96, 125, 139)),
)
"""Colour classes of the detector score, most confident first."""

_TRACK = "#1565c0"
_THUMB_W = 200
_MAP_W = 1180
_MAP_MAX_H = 820
_PAD_PX = 40
_STRIP_PX = 56  # band under the map for the scale bar and the north arrow
_BADGE_R = 15
_MIN_SIGMA_PX = 7.0
_MIN_EXTENT_M = 20.0
_R95 = math.sqrt(-2.0 * math.log(0.05))  # 2-D Gaussian: P(r < 2.45 sigma) = 95 %


def score_band(score: float) -> ScoreBand:
    """The :data:`SCORE_BANDS` entry of a detector score in [0, 1] (NaN counts as low)."""
    for band in SCORE_BANDS:
        if score >= band.min_score:
            return band
    return SCORE_BANDS[-1]


def write_report(
    path: Path | str,
    *,
    title: str,
    holes: Sequence[Hole],
    track: Sequence[VehiclePose],
    views: Mapping[int, BestView],
    truth: Sequence[tuple[str, float, float]] = (),
    facts: Mapping[str, str] | None = None,
) -> Path:
    """Write the flight report to ``path`` as one self-contained HTML file.

    Parameters
    ----------
    path : the ``.html`` file to write (replaced atomically); its folder must exist.
    title : page heading, e.g. the flight's name.
    holes : the holes found (e.g. ``HoleTracker.confirmed()``); may be empty.
    track : vehicle poses in time order (WGS84); poses without a finite position are skipped.
    views : hole id -> ``(rgb (H, W, 3) uint8, depth (H, W) uint16 millimetres, 0 = no
        reading)`` of that hole's best view; ``hole.best_box`` (x, y, w, h pixels) is drawn
        on it. Holes without a view get a "no image" cell.
    truth : ground-truth holes ``(name, lat_deg, lon_deg)`` drawn as hollow diamonds.
    facts : flight facts shown at the top (file names, duration, detector mode...).

    Returns
    -------
    The path written.

    Raises
    ------
    InputError : duplicate hole ids, a hole without a finite position, a malformed view or
        a box outside its image, or a folder that cannot be written.
    """
    page = render_report(
        title=title, holes=holes, track=track, views=views, truth=truth, facts=facts
    )
    out = Path(path)
    tmp = out.with_name(out.name + ".part")
    try:
        tmp.write_text(page, encoding="utf-8")
        os.replace(tmp, out)
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise InputError(f"{out}: cannot write the report ({err.strerror})") from err
    logger.info(
        "report: %d holes, %d track poses -> %s (%d bytes)",
        len(holes),
        len(track),
        out,
        len(page.encode()),
    )
    return out


def render_report(
    *,
    title: str,
    holes: Sequence[Hole],
    track: Sequence[VehiclePose],
    views: Mapping[int, BestView],
    truth: Sequence[tuple[str, float, float]] = (),
    facts: Mapping[str, str] | None = None,
) -> str:
    """The page :func:`write_report` writes, as a string (same parameters)."""
    holes = sorted(holes, key=lambda h: h.id)
    _check_holes(holes)
    poses = [p for p in track if math.isfinite(p.lat_deg) and math.isfinite(p.lon_deg)]
    if len(poses) < len(track):
        logger.warning("report: %d track poses without a position skipped", len(track) - len(poses))
    frame = _LocalFrame.around(poses, holes, truth)
    t0_ns = poses[0].t_boot_ns if poses else min((h.t_first_boot_ns for h in holes), default=0)
    holes_html = _holes_section(holes, views, frame, t0_ns, truth, bool(poses))
    map_html = (
        f"<section><h2>Map</h2>{_legend(bool(truth))}{_maps(frame, holes, poses, truth)}</section>"
    )
    body = [
        f"<header><h1>{_e(title)}</h1>{_summary(holes, poses, frame)}"
        f"{_facts(facts or {})}</header>",
        *((map_html, holes_html) if holes else (holes_html, map_html)),
        f"<footer>holescan {_e(_dist_version('holescan'))} &middot; positions WGS84; map in a "
        "local "
        f"east/north frame around {_e(frame.origin_name)} "
        f"({frame.lat0:.7f}, {frame.lon0:.7f}); a hole lies within its 1&sigma; circle "
        f"with 39 % probability, within {_R95:.2f}&sigma; with 95 %.</footer>",
    ]
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{_e(title)}</title><style>{_CSS}</style></head>"
        f"<body><main>{''.join(body)}</main></body></html>\n"
    )


def _e(text: object) -> str:
    return html.escape(str(text), quote=True)


def _check_holes(holes: Sequence[Hole]) -> None:
    ids = [h.id for h in holes]
    if len(set(ids)) != len(ids):
        raise InputError(f"hole ids must be unique, got {ids}")
    for h in holes:
        if not (math.isfinite(h.lat_deg) and math.isfinite(h.lon_deg)):
            raise InputError(f"hole {h.id} has no finite position ({h.lat_deg}, {h.lon_deg})")


@dataclass(frozen=True)
class _LocalFrame:
    """East/north metres around (lat0, lon0) on the ellipsoid (pymap3d ENU at height 0)."""

    lat0: float
    lon0: float
    origin_name: str

    @classmethod
    def around(
        cls,
        poses: Sequence[VehiclePose],
        holes: Sequence[Hole],
        truth: Sequence[tuple[str, float, float]],
    ) -> _LocalFrame:
        if poses:
            return cls(poses[0].lat_deg, poses[0].lon_deg, "the start of the track")
        pts = [(h.lat_deg, h.lon_deg) for h in holes] + [(t[1], t[2]) for t in truth]
        if not pts:
            return cls(0.0, 0.0, "0, 0 (nothing to draw)")
        lat, lon = np.mean(np.asarray(pts, float), axis=0)
        return cls(float(lat), float(lon), "the centroid of the holes")

    def en(self, lat: npt.ArrayLike, lon: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """East, north metres of WGS84 points (arrays of equal shape)."""
        lat_a, lon_a = np.asarray(lat, float), np.asarray(lon, float)
        e, n, _ = pymap3d.geodetic2enu(
            lat_a, lon_a, np.zeros_like(lat_a), self.lat0, self.lon0, 0.0
        )
        return np.asarray(e, float), np.asarray(n, float)


# --- header -----------------------------------------------------------------------------


def _track_length_m(frame: _LocalFrame, poses: Sequence[VehiclePose]) -> float:
    if len(poses) < 2:
        return 0.0
    e, n = frame.en([p.lat_deg for p in poses], [p.lon_deg for p in poses])
    return float(np.hypot(np.diff(e), np.diff(n)).sum())


def _summary(holes: Sequence[Hole], poses: Sequence[VehiclePose], frame: _LocalFrame) -> str:
    stats = [
        ("holes found", str(len(holes))),
        ("seen twice or more", str(sum(h.sightings >= 2 for h in holes))),
        (
            f"score &ge; {SCORE_BANDS[0].min_score:.1f}",
            str(sum(score_band(h.score) is SCORE_BANDS[0] for h in holes)),
        ),
    ]
    if poses:
        dur_s = (poses[-1].t_boot_ns - poses[0].t_boot_ns) * 1e-9
        stats += [
            ("track length", f"{_track_length_m(frame, poses):.0f} m"),
            ("track duration", _duration(dur_s)),
        ]
    cells = "".join(f'<div class="stat"><b>{v}</b>{k}</div>' for k, v in stats)
    return f'<div class="summary">{cells}</div>'


def _duration(seconds: float) -> str:
    m, s = divmod(max(seconds, 0.0), 60.0)
    return f"{int(m)} min {s:04.1f} s" if m else f"{s:.1f} s"


def _facts(facts: Mapping[str, str]) -> str:
    if not facts:
        return ""
    rows = "".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in facts.items())
    return f'<table class="facts">{rows}</table>'


# --- map --------------------------------------------------------------------------------


@dataclass(frozen=True)
class _View:
    """Metres -> SVG pixels, north up, one scale on both axes."""

    e_min: float
    n_max: float
    scale: float  # px per metre
    x0: float
    y0: float
    width: int
    height: int

    def xy(self, e: float, n: float) -> tuple[float, float]:
        return self.x0 + (e - self.e_min) * self.scale, self.y0 + (self.n_max - n) * self.scale


def _fit(e: np.ndarray, n: np.ndarray) -> _View:
    if e.size == 0:
        e, n = np.zeros(1), np.zeros(1)
    e_lo, e_hi, n_lo, n_hi = float(e.min()), float(e.max()), float(n.min()), float(n.max())
    grow_e = max(_MIN_EXTENT_M - (e_hi - e_lo), 0.0) / 2
    grow_n = max(_MIN_EXTENT_M - (n_hi - n_lo), 0.0) / 2
    e_lo, e_hi, n_lo, n_hi = e_lo - grow_e, e_hi + grow_e, n_lo - grow_n, n_hi + grow_n
    inner_w = _MAP_W - 2 * _PAD_PX
    scale = inner_w / (e_hi - e_lo)
    inner_h = (n_hi - n_lo) * scale
    if inner_h > _MAP_MAX_H - 2 * _PAD_PX - _STRIP_PX:
        inner_h = _MAP_MAX_H - 2 * _PAD_PX - _STRIP_PX
        scale = inner_h / (n_hi - n_lo)
    x0 = (_MAP_W - (e_hi - e_lo) * scale) / 2
    height = round(inner_h + 2 * _PAD_PX + _STRIP_PX)
    return _View(e_lo, n_hi, scale, x0, _PAD_PX, _MAP_W, height)


def _nice_step(length_m: float) -> float:
    """The largest 1, 2, 5 x 10^k not above ``length_m``."""
    unit = 10.0 ** math.floor(math.log10(length_m))
    for f in (5.0, 2.0, 1.0):
        if f * unit <= length_m:
            return f * unit
    return unit


def _fmt_m(m: float) -> str:
    return f"{m:g} m" if m < 1000 else f"{m / 1000:g} km"


def _maps(
    frame: _LocalFrame,
    holes: Sequence[Hole],
    poses: Sequence[VehiclePose],
    truth: Sequence[tuple[str, float, float]],
) -> str:
    """The whole flight, plus a close-up when the holes fill under a third of it."""
    te, tn = frame.en([p.lat_deg for p in poses], [p.lon_deg for p in poses])
    he, hn = frame.en([h.lat_deg for h in holes], [h.lon_deg for h in holes])
    ge, gn = frame.en([t[1] for t in truth], [t[2] for t in truth])
    reach = np.nan_to_num(
        np.array([max(h.sigma_h_m, _finite(h.major_m) / 2, 0.0) for h in holes]),
        nan=0.0,
        posinf=0.0,
    )
    all_e = np.concatenate([te, he - reach, he + reach, ge])
    all_n = np.concatenate([tn, hn - reach, hn + reach, gn])
    geo = (te, tn, he, hn, ge, gn)
    out = [_map_svg(_fit(all_e, all_n), holes, truth, geo, "the flight")]
    if holes:
        hole_e = np.concatenate([he - reach, he + reach])
        hole_n = np.concatenate([hn - reach, hn + reach])
        span = max(np.ptp(hole_e), np.ptp(hole_n), _MIN_EXTENT_M)
        if 3 * span < max(np.ptp(all_e), np.ptp(all_n)):
            out.append(
                f"<h3>Close-up of the holes</h3>"
                f"{_map_svg(_fit(hole_e, hole_n), holes, truth, geo, 'the holes')}"
            )
    return "".join(out)


def _map_svg(
    view: _View,
    holes: Sequence[Hole],
    truth: Sequence[tuple[str, float, float]],
    geo: tuple[np.ndarray, ...],
    what: str,
) -> str:
    """One map: grid, track, holes, truth, ids, scale bar and north arrow in ``view``."""
    te, tn, he, hn, ge, gn = geo
    out = [
        f'<svg class="map" width="{view.width}" height="{view.height}" '
        f'viewBox="0 0 {view.width} {view.height}" role="img" '
        f'aria-label="map of {what}">',
        f'<rect width="{view.width}" height="{view.height}" fill="#fbfbf8"/>',
    ]
    step = _nice_step(view.width / 5 / view.scale)
    out.append(_grid(view, step))
    out.append(_track_svg(view, te, tn))
    placed: list[tuple[float, float]] = []
    centres = [view.xy(float(e), float(n)) for e, n in zip(he, hn, strict=True)]
    for h, (x, y) in zip(holes, centres, strict=True):
        band = score_band(h.score)
        r = (
            max(h.sigma_h_m * view.scale, _MIN_SIGMA_PX)
            if math.isfinite(h.sigma_h_m)
            else _MIN_SIGMA_PX
        )
        out.append(
            f'<circle cx="{x:.1f}" cy="{y:.1f}" r="{r:.1f}" fill="{band.hex}" '
            f'fill-opacity="0.16" stroke="{band.hex}" stroke-width="1.5"/>'
        )
    for h, (x, y) in zip(holes, centres, strict=True):
        major = _finite(h.major_m)
        if major > 0:
            out.append(
                f'<circle cx="{x:.1f}" cy="{y:.1f}" r="{major / 2 * view.scale:.1f}" '
                'fill="#1b1b1b" fill-opacity="0.85" stroke="#fff" stroke-width="1"/>'
            )
        out.append(
            f'<path d="M{x - 4:.1f},{y:.1f}h8M{x:.1f},{y - 4:.1f}v8" stroke="#1b1b1b" '
            'stroke-width="1.5"/>'
        )
    for h, (x, y) in zip(holes, centres, strict=True):
        clear_px = _finite(h.major_m) / 2 * view.scale + _BADGE_R + 6
        dist = min(max(_BADGE_R + 14.0, clear_px), 80.0)
        placed.append(_badge_place(view, x, y, dist, centres, placed))
    for (name, _, _), e, n in zip(truth, ge, gn, strict=True):
        x, y = view.xy(float(e), float(n))
        lx, ly, anchor = _truth_label_place(x, y, len(name), placed)
        out.append(
            f'<path d="M{x:.1f},{y - 9:.1f}l9,9l-9,9l-9,-9z" fill="none" '
            'stroke="#000" stroke-width="2"/>'
            f'<text x="{lx:.1f}" y="{ly:.1f}" text-anchor="{anchor}" class="truth">'
            f"{_e(name)}</text>"
        )
    for h, (x, y), (bx, by) in zip(holes, centres, placed, strict=True):
        band = score_band(h.score)
        out.append(
            f'<line x1="{x:.1f}" y1="{y:.1f}" x2="{bx:.1f}" y2="{by:.1f}" '
            f'stroke="{band.hex}" stroke-width="2"/>'
            f'<circle cx="{bx:.1f}" cy="{by:.1f}" r="{_BADGE_R}" fill="{band.hex}" '
            'stroke="#fff" stroke-width="2"/>'
            f'<text x="{bx:.1f}" y="{by + 6:.1f}" class="id">{h.id}</text>'
        )
    bottom = view.height - _STRIP_PX  # the strip covers whatever was drawn past the map area
    out.append(
        f'<rect y="{bottom}" width="{view.width}" height="{_STRIP_PX}" fill="#fbfbf8"/>'
        f'<line x1="0" y1="{bottom}" x2="{view.width}" y2="{bottom}" stroke="#999"/>'
    )
    out.append(_scale_bar(view, step))
    out.append(_north_arrow(view))
    out.append("</svg>")
    return "".join(out)


def _finite(v: float) -> float:
    return v if math.isfinite(v) else 0.0


def _grid(view: _View, step: float) -> str:
    """Faint lines every ``step`` metres east and north of the origin, over the map area."""
    bottom = view.height - _STRIP_PX
    e_lo = view.e_min - view.x0 / view.scale
    e_hi = view.e_min + (view.width - view.x0) / view.scale
    n_hi = view.n_max + view.y0 / view.scale
    n_lo = view.n_max - (bottom - view.y0) / view.scale
    lines = []
    for k in range(math.ceil(e_lo / step), math.floor(e_hi / step) + 1):
        x, _ = view.xy(k * step, 0.0)
        lines.append(f"M{x:.1f},0V{bottom}")
    for k in range(math.ceil(n_lo / step), math.floor(n_hi / step) + 1):
        _, y = view.xy(0.0, k * step)
        lines.append(f"M0,{y:.1f}H{view.width}")
    return f'<path d="{"".join(lines)}" stroke="#dcdcd6" stroke-width="1"/>'


def _track_svg(view: _View, te: np.ndarray, tn: np.ndarray) -> str:
    if te.size == 0:
        return ""
    pts = list(zip(te.tolist(), tn.tolist(), strict=True))
    if len(pts) > 2:  # drop vertices that move the line by less than half a pixel
        line = LineString(pts).simplify(0.5 / view.scale, preserve_topology=False)
        pts = list(line.coords)
    xy = [view.xy(e, n) for e, n in pts]
    out = []
    if len(xy) > 1:
        d = " ".join(f"{x:.1f},{y:.1f}" for x, y in xy)
        out.append(
            f'<polyline points="{d}" fill="none" stroke="{_TRACK}" stroke-width="2.5" '
            'stroke-linejoin="round"/>'
        )
    (sx, sy), (ex, ey) = xy[0], xy[-1]
    out.append(
        f'<path d="M{sx:.1f},{sy - 10:.1f}l9,16h-18z" fill="#2e7d32" stroke="#fff" '
        f'stroke-width="1.5"/><text x="{sx + 12:.1f}" y="{sy + 5:.1f}" '
        'class="mark">start</text>'
    )
    if len(xy) > 1:
        out.append(
            f'<rect x="{ex - 7:.1f}" y="{ey - 7:.1f}" width="14" height="14" '
            f'fill="{_TRACK}" stroke="#fff" stroke-width="1.5"/>'
            f'<text x="{ex + 12:.1f}" y="{ey + 5:.1f}" class="mark">end</text>'
        )
    return "".join(out)


def _badge_place(
    view: _View,
    x: float,
    y: float,
    dist: float,
    centres: Sequence[tuple[float, float]],
    placed: Sequence[tuple[float, float]],
) -> tuple[float, float]:
    """Centre of a hole's id badge: the first of 8 spots ``dist`` px around it clear of others."""
    best, best_cost = (x, y), math.inf
    for k in range(8):
        a = math.radians(-45 + 45 * k)  # screen y points down: up-right first, clockwise
        bx, by = x + dist * math.cos(a), y + dist * math.sin(a)
        cost = 0.0
        if not (
            _BADGE_R < bx < view.width - _BADGE_R
            and _BADGE_R < by < view.height - _STRIP_PX - _BADGE_R
        ):
            cost += 100.0
        for px, py in placed:
            cost += max(0.0, 2.2 * _BADGE_R - math.hypot(bx - px, by - py))
        for cx, cy in centres:
            cost += max(0.0, _BADGE_R + 4 - math.hypot(bx - cx, by - cy))
        if cost < best_cost - 1e-9:
            best, best_cost = (bx, by), cost
        if cost == 0.0:
            break
    return best


def _scale_bar(view: _View, step: float) -> str:
    x0, y0 = 20.0, view.height - _STRIP_PX + 22
    seg = step * view.scale / 2
    parts = [
        f'<rect x="{x0 + i * seg:.1f}" y="{y0:.1f}" width="{seg:.1f}" height="8" '
        f'fill="{"#222" if i % 2 == 0 else "#fff"}" stroke="#222"/>'
        for i in range(2)
    ]
    parts.append(
        f'<text x="{x0:.1f}" y="{y0 - 5:.1f}" class="scale">0</text>'
        f'<text x="{x0 + 2 * seg:.1f}" y="{y0 - 5:.1f}" class="scale" '
        f'text-anchor="middle">{_fmt_m(step)}</text>'
        f'<text x="{x0 + 2 * seg + 14:.1f}" y="{y0 + 9:.1f}" class="note">grid '
        f"{_fmt_m(step)}</text>"
    )
    return "".join(parts)


def _north_arrow(view: _View) -> str:
    x, y = view.width - 40.0, view.height - _STRIP_PX + 24
    return (
        f'<text x="{x:.1f}" y="{y - 4:.1f}" text-anchor="middle" class="north">N</text>'
        f'<path d="M{x:.1f},{y:.1f}l9,26l-9,-7l-9,7z" fill="#222"/>'
    )


def _truth_label_place(
    x: float, y: float, n_chars: int, badges: Sequence[tuple[float, float]]
) -> tuple[float, float, str]:
    """Where a truth marker's name goes (x, baseline y, text-anchor): clear of the id badges."""
    w, h = 8.0 * n_chars, 16.0  # 14 px italic text, roughly
    best, best_cost = (x + 12, y + 18, "start"), math.inf
    for dx, dy, anchor in (
        (12, 18, "start"),
        (12, -8, "start"),
        (-12, 18, "end"),
        (-12, -8, "end"),
    ):
        left = x + dx if anchor == "start" else x + dx - w
        top = y + dy - h + 4
        cost = 0.0
        for bx, by in badges:
            ox = min(left + w, bx + _BADGE_R) - max(left, bx - _BADGE_R)
            oy = min(top + h, by + _BADGE_R) - max(top, by - _BADGE_R)
            cost += max(ox, 0.0) * max(oy, 0.0)
        if cost < best_cost:
            best, best_cost = (x + dx, y + dy, anchor), cost
        if cost == 0.0:
            break
    return best


def _band_range(i: int) -> str:
    """``SCORE_BANDS[i]``'s score range as HTML text: "&ge; 0.7", "0.5 &ndash; 0.7", "&lt; 0.5"."""
    lo = SCORE_BANDS[i].min_score
    hi = SCORE_BANDS[i - 1].min_score if i > 0 else math.inf
    if not math.isfinite(lo):
        return f"&lt; {hi:.1f}"
    return f"&ge; {lo:.1f}" if not math.isfinite(hi) else f"{lo:.1f} &ndash; {hi:.1f}"


def _legend(with_truth: bool) -> str:
    def sw(inner: str) -> str:
        return f'<svg width="34" height="28" viewBox="0 0 34 28">{inner}</svg>'

    items = [
        sw(f'<circle cx="17" cy="14" r="12" fill="{b.hex}" stroke="#fff" stroke-width="2"/>')
        + f"hole, score {_band_range(i)} ({b.name})"
        for i, b in enumerate(SCORE_BANDS)
    ]
    items += [
        sw(
            f'<circle cx="17" cy="14" r="12" fill="{SCORE_BANDS[0].hex}" fill-opacity="0.16" '
            f'stroke="{SCORE_BANDS[0].hex}" stroke-width="1.5"/>'
        )
        + "position &plusmn;1&sigma;",
        sw('<circle cx="17" cy="14" r="8" fill="#1b1b1b" fill-opacity="0.85"/>')
        + "opening (major axis, to scale)",
        sw(f'<line x1="2" y1="14" x2="32" y2="14" stroke="{_TRACK}" stroke-width="3"/>')
        + "flight track",
        sw(
            '<path d="M10,5l9,16h-18z" fill="#2e7d32"/><rect x="21" y="7" width="12" '
            f'height="12" fill="{_TRACK}"/>'
        )
        + "start / end",
    ]
    if with_truth:
        items.append(
            sw('<path d="M17,4l10,10l-10,10l-10,-10z" fill="none" stroke="#000" stroke-width="2"/>')
            + "ground truth"
        )
    return '<div class="legend">' + "".join(f"<span>{i}</span>" for i in items) + "</div>"


# --- holes table ------------------------------------------------------------------------


def _holes_section(
    holes: Sequence[Hole],
    views: Mapping[int, BestView],
    frame: _LocalFrame,
    t0_ns: int,
    truth: Sequence[tuple[str, float, float]],
    have_track: bool,
) -> str:
    if not holes:
        return (
            '<section class="none"><h2>No hole found</h2><p>The detector reported no '
            "hole on this flight. The map shows the area that was flown.</p></section>"
        )
    heads = [
        "Hole",
        "Score",
        "Position (WGS84)",
        "Uncertainty",
        "Opening",
        "Sightings",
        "Seen (s from start)",
    ]
    if truth:
        heads.append("Nearest truth")
    heads += ["Colour view", "Depth view"]
    ge, gn = frame.en([t[1] for t in truth], [t[2] for t in truth])
    rows = []
    for h in holes:
        band = score_band(h.score)
        e, n = (float(v) for v in frame.en(h.lat_deg, h.lon_deg))
        where = ""
        if have_track:
            bearing = math.degrees(math.atan2(e, n)) % 360.0
            where = (
                f'<div class="note">{math.hypot(e, n):.1f} m at {bearing:03.0f}&deg; '
                "from start</div>"
            )
        size = (
            f"{h.major_m:.2f} &times; {h.minor_m:.2f} m"
            if math.isfinite(h.major_m) and math.isfinite(h.minor_m)
            else "&mdash;"
        )
        first = (h.t_first_boot_ns - t0_ns) * 1e-9
        last = (h.t_last_boot_ns - t0_ns) * 1e-9
        cells = [
            f'<td><span class="badge" style="background:{band.hex}">{h.id}</span></td>',
            f'<td><b class="score">{h.score:.2f}</b><div class="note">{band.name}</div></td>',
            f'<td class="mono">{h.lat_deg:.7f}<br>{h.lon_deg:.7f}{where}</td>',
            f'<td class="nw">1&sigma; {h.sigma_h_m:.2f} m<div class="note">95 %: '
            f"{_R95 * h.sigma_h_m:.2f} m</div></td>",
            f'<td class="nw">{size}</td>',
            f'<td class="num">{h.sightings}</td>',
            f'<td class="nw">{first:.1f} &ndash; {last:.1f}</td>',
        ]
        if truth:
            d = np.hypot(ge - e, gn - n)
            k = int(np.argmin(d))
            cells.append(f'<td>{_e(truth[k][0])}<div class="note">{d[k]:.2f} m</div></td>')
        cells += _thumb_cells(h, views.get(h.id), band)
        rows.append(f"<tr>{''.join(cells)}</tr>")
    unknown = sorted(set(views) - {h.id for h in holes})
    if unknown:
        logger.warning("report: views for unknown hole ids %s ignored", unknown)
    head = "".join(f"<th>{t}</th>" for t in heads)
    return (
        f'<section><h2>Holes ({len(holes)})</h2><table class="holes"><thead><tr>{head}'
        f"</tr></thead><tbody>{''.join(rows)}</tbody></table></section>"
    )


def _thumb_cells(h: Hole, view: BestView | None, band: ScoreBand) -> list[str]:
    if view is None:
        return ['<td class="noimg" colspan="2">no image</td>']
    rgb, depth = view
    rgb_t, depth_t = thumbnails(rgb, depth, h.best_box, band.rgb)
    alt = f"hole {h.id}"
    return [
        f'<td><img src="{_png_uri(rgb_t)}" width="{rgb_t.shape[1]}" '
        f'height="{rgb_t.shape[0]}" alt="{alt} colour"></td>',
        f'<td><img src="{_png_uri(depth_t)}" width="{depth_t.shape[1]}" '
        f'height="{depth_t.shape[0]}" alt="{alt} depth"></td>',
    ]


def thumbnails(
    rgb: npt.NDArray[np.uint8],
    depth: npt.NDArray[np.uint16],
    box: tuple[int, int, int, int],
    colour: tuple[int, int, int] = SCORE_BANDS[0].rgb,
    width: int = _THUMB_W,
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint8]]:
    """Colour and depth crops around ``box`` (x, y, w, h px) with the box drawn, ``width`` wide.

    rgb : (H, W, 3) uint8; depth : (H, W) uint16 millimetres, 0 = no reading. The crop keeps
    a margin of 60 % of the box's larger side (at least 24 px) and is at most ``width`` px
    tall as well. Returns two (h, w, 3) uint8 RGB images; depth is coloured by
    :func:`ground._overlay.depth_colour` over the crop (near = bright).
    """
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise InputError(f"view colour must be (H, W, 3) uint8, got {rgb.shape} {rgb.dtype}")
    if depth.ndim != 2 or depth.dtype != np.uint16 or depth.shape != rgb.shape[:2]:
        raise InputError(
            f"view depth must be (H, W) uint16 matching the colour {rgb.shape[:2]}, "
            f"got {depth.shape} {depth.dtype}"
        )
    x, y, w, h = (int(v) for v in box)
    H, W = depth.shape
    if w <= 0 or h <= 0 or x < 0 or y < 0 or x + w > W or y + h > H:
        raise InputError(f"box {box} (x, y, w, h) is empty or outside the {W}x{H} view")
    rgb_c, (bx, by, _, _) = crop_view(rgb, (x, y, w, h), margin_frac=0.6)
    depth_c, _ = crop_view(depth, (x, y, w, h), margin_frac=0.6)
    ch, cw = depth_c.shape
    f = min(width / cw, width / ch)
    size = (max(round(cw * f), 1), max(round(ch * f), 1))
    interp = cv2.INTER_AREA if f < 1 else cv2.INTER_LINEAR
    out: list[npt.NDArray[np.uint8]] = []
    for img in (rgb_c, depth_colour(depth_c)):
        resized = cv2.resize(np.ascontiguousarray(img), size, interpolation=interp)
        t = np.ascontiguousarray(resized, dtype=np.uint8)
        p0 = (round(bx * f), round(by * f))
        p1 = (round((bx + w) * f) - 1, round((by + h) * f) - 1)
        cv2.rectangle(t, p0, p1, (255, 255, 255), 4, cv2.LINE_AA)
        cv2.rectangle(t, p0, p1, colour, 2, cv2.LINE_AA)
        out.append(t)
    return out[0], out[1]


def _png_uri(rgb: npt.NDArray[np.uint8]) -> str:
    ok, buf = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    if not ok:
        raise InputError("could not encode a thumbnail as PNG")
    return "data:image/png;base64," + base64.b64encode(buf.tobytes()).decode("ascii")


_CSS = """
body{margin:0;background:#eceff1;color:#1c1c1c;font:15px/1.4 "DejaVu Sans","Liberation Sans",
Arial,sans-serif}
main{max-width:1200px;margin:0 auto;padding:14px 10px 30px}
h1{font-size:30px;margin:6px 0 8px}
h3{font-size:18px;margin:14px 0 6px}
h2{font-size:22px;margin:22px 0 8px;border-bottom:2px solid #263238;padding-bottom:3px}
.summary{display:flex;flex-wrap:wrap;gap:10px;margin:8px 0 12px}
.stat{background:#fff;border:1px solid #cfd8dc;border-radius:6px;padding:6px 16px;
min-width:120px;color:#455a64}
.stat b{display:block;font-size:28px;color:#1c1c1c}
table.facts{border-collapse:collapse;background:#fff;font-size:14px}
table.facts th{text-align:left;padding:3px 14px 3px 8px;color:#455a64;font-weight:normal}
table.facts td{padding:3px 8px;font-family:"DejaVu Sans Mono",monospace;word-break:break-all}
.legend{display:flex;flex-wrap:wrap;gap:6px 22px;align-items:center;font-size:14px;
margin:4px 0 8px}
.legend span{display:inline-flex;align-items:center;gap:6px}
svg.map{display:block;background:#fff;border:1px solid #b0bec5}
svg text{font-family:"DejaVu Sans",sans-serif}
svg text.id{font-size:17px;font-weight:bold;fill:#fff;text-anchor:middle}
svg text.truth{font-size:14px;font-style:italic;fill:#000}
svg text.mark{font-size:14px;font-weight:bold;fill:#263238}
svg text.scale{font-size:14px;fill:#222}
svg text.note{font-size:13px;fill:#555}
svg text.north{font-size:22px;font-weight:bold;fill:#222}
table.holes{border-collapse:collapse;width:100%;background:#fff}
table.holes th{background:#263238;color:#fff;text-align:left;padding:7px 8px;font-size:14px}
table.holes td{border-top:1px solid #cfd8dc;padding:6px 8px;vertical-align:middle}
table.holes tr{break-inside:avoid}
.badge{display:inline-block;min-width:40px;padding:3px 8px;border-radius:24px;color:#fff;
font-size:28px;font-weight:bold;text-align:center}
.score{font-size:20px}
.num{font-size:20px;text-align:center}
.note{font-size:13px;color:#555}
.nw{white-space:nowrap}
.mono{font-family:"DejaVu Sans Mono",monospace;font-size:14px}
td img{display:block;border:1px solid #90a4ae}
td.noimg{color:#777;font-style:italic}
section.none{background:#fff;border:2px solid #263238;padding:4px 16px 10px;margin-top:18px}
footer{margin-top:20px;font-size:12px;color:#607d8b}
"""
