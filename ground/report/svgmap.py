"""The report's map: the inline SVG of track, holes and truth to scale, and its legend.

Positions are drawn in the map's :class:`geotag.LocalFrame` (east/north metres)."""

from __future__ import annotations

import html
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from shapely.geometry import LineString

from holescan.geotag import CIRCLE_95_PER_SIGMA, Hole, LocalFrame, VehiclePose
from holescan.ground.report.bands import SCORE_BANDS, score_band

__all__ = ["legend_html", "maps_svg"]


_TRACK = "#1565c0"
_MAP_W = 1180
_MAP_MAX_H = 820
_PAD_PX = 40
_STRIP_PX = 56  # band under the map for the scale bar and the north arrow
_BADGE_R = 15
_MIN_SIGMA_PX = 7.0
_MIN_EXTENT_M = 20.0


def _e(text: object) -> str:
    return html.escape(str(text), quote=True)


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


def maps_svg(
    frame: LocalFrame,
    holes: Sequence[Hole],
    poses: Sequence[VehiclePose],
    truth: Sequence[tuple[str, float, float]],
    breaks: Sequence[int] = (),
) -> str:
    """The whole flight, plus a close-up when the holes fill under a third of it.

    breaks : indices into ``poses`` where another flight's line starts."""
    te, tn = frame.to_en([p.lat_deg for p in poses], [p.lon_deg for p in poses])
    he, hn = frame.to_en([h.lat_deg for h in holes], [h.lon_deg for h in holes])
    ge, gn = frame.to_en([t[1] for t in truth], [t[2] for t in truth])
    reach = np.nan_to_num(
        np.array(
            [max(CIRCLE_95_PER_SIGMA * h.sigma_h_m, _finite(h.major_m) / 2, 0.0) for h in holes]
        ),
        nan=0.0,
        posinf=0.0,
    )
    all_e = np.concatenate([te, he - reach, he + reach, ge])
    all_n = np.concatenate([tn, hn - reach, hn + reach, gn])
    cuts = sorted({*breaks, *_track_breaks(poses)})  # several flights: one line each
    geo = (np.insert(te, cuts, np.nan), np.insert(tn, cuts, np.nan), he, hn, ge, gn)
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
            max(CIRCLE_95_PER_SIGMA * h.sigma_h_m * view.scale, _MIN_SIGMA_PX)
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


_TRACK_GAP_NS = 60_000_000_000


def _track_breaks(poses: Sequence[VehiclePose]) -> list[int]:
    """Where the track is another flight: the boot clock goes back or jumps over a minute
    (each autopilot boot starts its own clock)."""
    t = [p.t_boot_ns for p in poses]
    return [i for i in range(1, len(t)) if not 0 <= t[i] - t[i - 1] <= _TRACK_GAP_NS]


def _track_svg(view: _View, te: np.ndarray, tn: np.ndarray) -> str:
    """The track as a line from a start triangle to an end square; NaN separates flights."""
    gaps = np.flatnonzero(np.isnan(te))
    if gaps.size:
        bounds = [-1, *gaps.tolist(), te.size]
        return "".join(
            _track_svg(view, te[a + 1 : b], tn[a + 1 : b]) for a, b in itertools.pairwise(bounds)
        )
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


def legend_html(with_truth: bool) -> str:
    """The map's legend: a swatch per band and mark, as HTML."""

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
        + f"95 % circle of the position (radius {CIRCLE_95_PER_SIGMA:.2f}&sigma;)",
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
