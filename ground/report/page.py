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
import functools
import html
import logging
import math
from collections.abc import Mapping, Sequence
from importlib import resources
from importlib.metadata import version as _dist_version
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from holescan.errors import InputError
from holescan.geotag import (
    CIRCLE_95_PER_SIGMA,
    Hole,
    LocalFrame,
    VehiclePose,
    crop_view,
    holes_found,
)
from holescan.ground.images.overlay import depth_colour
from holescan.ground.report.bands import SCORE_BANDS, ScoreBand, score_band
from holescan.ground.report.svgmap import legend_html, maps_svg
from holescan.outputs import atomic_output

__all__ = ["BestView", "render_report", "thumbnails", "write_report"]


logger = logging.getLogger(__name__)

BestView = tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint16]]
"""A hole's best view: rgb (H, W, 3) uint8 and depth (H, W) uint16 millimetres."""

_THUMB_W = 200
_R95 = CIRCLE_95_PER_SIGMA  # sigma_h is the 68 % circle; the 95 % one is 1.62 times it


def _e(text: object) -> str:
    return html.escape(str(text), quote=True)


def write_report(
    path: Path | str,
    *,
    title: str,
    holes: Sequence[Hole],
    track: Sequence[VehiclePose],
    views: Mapping[int, BestView],
    truth: Sequence[tuple[str, float, float]] = (),
    facts: Mapping[str, str] | None = None,
    track_breaks: Sequence[int] = (),
    search_map: str | None = None,
    tiers: Mapping[int, str] | None = None,
) -> Path:
    """Write the flight report to ``path`` as one self-contained HTML file.

    Parameters
    ----------
    path : the ``.html`` file to write (replaced atomically, through the output-path rule
        :func:`outputs.atomic_output`); its folder must exist.
    title : page heading, e.g. the flight's name.
    holes : the holes found (e.g. ``HoleTracker.confirmed()``); may be empty.
    track : vehicle poses in time order (WGS84); poses without a finite position are skipped.
    views : hole id -> ``(rgb (H, W, 3) uint8, depth (H, W) uint16 millimetres, 0 = no
        reading)`` of that hole's best view; ``hole.best_box`` (x, y, w, h pixels) is drawn
        on it. Holes without a view get a "no image" cell.
    truth : ground-truth holes ``(name, lat_deg, lon_deg)`` drawn as hollow diamonds.
    facts : flight facts shown at the top (file names, duration, detector mode...).
    track_breaks : indices into ``track`` where another flight's track starts (a campaign):
        each flight is drawn as its own line. The line also breaks where the boot clock
        goes back or jumps by more than a minute.
    search_map : the search map's section (:func:`ground.report.searchmap.search_map_section`),
        shown after the map.
    tiers : hole id -> tier (``announced``, ``review``, ``confirmed``, ``rejected``; None:
        every hole ``announced``), shown per hole; "holes found" counts
        :data:`geotag.FOUND_TIERS`.

    Returns
    -------
    The path written.

    Raises
    ------
    InputError : duplicate hole ids, a hole without a finite position, a malformed view or
        a box outside its image, or a folder that cannot be written.
    """
    page = render_report(
        title=title,
        holes=holes,
        track=track,
        views=views,
        truth=truth,
        facts=facts,
        track_breaks=track_breaks,
        search_map=search_map,
        tiers=tiers,
    )
    out = Path(path)
    with atomic_output(out, force=True) as f:
        f.write(page.encode("utf-8"))
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
    track_breaks: Sequence[int] = (),
    search_map: str | None = None,
    tiers: Mapping[int, str] | None = None,
) -> str:
    """The page :func:`write_report` writes, as a string (same parameters)."""
    holes = sorted(holes, key=lambda h: h.id)
    tiers = {h.id: (tiers or {}).get(h.id, "announced") for h in holes}
    _check_holes(holes)
    kept = [i for i, p in enumerate(track) if math.isfinite(p.lat_deg) and math.isfinite(p.lon_deg)]
    poses = [track[i] for i in kept]
    breaks = sorted({sum(i < b for i in kept) for b in track_breaks} - {0, len(poses)})
    if len(poses) < len(track):
        logger.warning("report: %d track poses without a position skipped", len(track) - len(poses))
    frame, origin_name = _map_frame(poses, holes, truth)
    t0_ns = poses[0].t_boot_ns if poses else min((h.t_first_boot_ns for h in holes), default=0)
    holes_html = _holes_section(holes, views, frame, t0_ns, truth, bool(poses), tiers)
    maps = maps_svg(frame, holes, poses, truth, breaks)
    map_html = f"<section><h2>Map</h2>{legend_html(bool(truth))}{maps}</section>"
    map_html += search_map or ""
    body = [
        f"<header><h1>{_e(title)}</h1>{_summary(holes, poses, frame, tiers)}"
        f"{_facts(facts or {})}</header>",
        *((map_html, holes_html) if holes else (holes_html, map_html)),
        f"<footer>holescan {_e(_dist_version('holescan'))} &middot; positions WGS84; map in a "
        "local "
        f"east/north frame around {_e(origin_name)} "
        f"({frame.lat0_deg:.7f}, {frame.lon0_deg:.7f}); the circles are 95 % circles: a hole "
        f"lies within {_R95:.2f}&sigma; of its position with 95 % probability (within "
        "1&sigma; with 68 %). Holes found: announced, for review and confirmed by an "
        "operator; sightings: frames a hole was detected in, from distinct viewpoints (views)."
        "</footer>",
    ]
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{_e(title)}</title><style>{_css()}</style></head>"
        f"<body><main>{''.join(body)}</main></body></html>\n"
    )


def _check_holes(holes: Sequence[Hole]) -> None:
    ids = [h.id for h in holes]
    if len(set(ids)) != len(ids):
        raise InputError(f"hole ids must be unique, got {ids}")
    for h in holes:
        if not (math.isfinite(h.lat_deg) and math.isfinite(h.lon_deg)):
            raise InputError(f"hole {h.id} has no finite position ({h.lat_deg}, {h.lon_deg})")


def _map_frame(
    poses: Sequence[VehiclePose],
    holes: Sequence[Hole],
    truth: Sequence[tuple[str, float, float]],
) -> tuple[LocalFrame, str]:
    """The map's east/north frame (height 0) and the name of its origin."""
    if poses:
        return LocalFrame(poses[0].lat_deg, poses[0].lon_deg), "the start of the track"
    pts = [(h.lat_deg, h.lon_deg) for h in holes] + [(t[1], t[2]) for t in truth]
    if not pts:
        return LocalFrame(0.0, 0.0), "0, 0 (nothing to draw)"
    lat, lon = np.mean(np.asarray(pts, float), axis=0)
    return LocalFrame(float(lat), float(lon)), "the centroid of the holes"


# --- header -----------------------------------------------------------------------------


def _track_length_m(frame: LocalFrame, poses: Sequence[VehiclePose]) -> float:
    if len(poses) < 2:
        return 0.0
    e, n = frame.to_en([p.lat_deg for p in poses], [p.lon_deg for p in poses])
    return float(np.hypot(np.diff(e), np.diff(n)).sum())


def _summary(
    holes: Sequence[Hole],
    poses: Sequence[VehiclePose],
    frame: LocalFrame,
    tiers: Mapping[int, str],
) -> str:
    count = {t: sum(v == t for v in tiers.values()) for t in ("announced", "review", "confirmed")}
    stats = [
        ("holes found", str(holes_found(tiers.values()))),
        *((t if t != "review" else "for review", str(n)) for t, n in count.items() if n),
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


# --- holes table ------------------------------------------------------------------------


def _holes_section(
    holes: Sequence[Hole],
    views: Mapping[int, BestView],
    frame: LocalFrame,
    t0_ns: int,
    truth: Sequence[tuple[str, float, float]],
    have_track: bool,
    tiers: Mapping[int, str],
) -> str:
    if not holes:
        return (
            '<section class="none"><h2>No hole found</h2><p>The detector reported no '
            "hole on this flight. The map shows the area that was flown.</p></section>"
        )
    heads = [
        "Hole",
        "Tier",
        "p_hole / best frame's score",
        "Position (WGS84)",
        "95 % circle",
        "Opening",
        "Frames / views",
        "Seen (s from start)",
    ]
    if truth:
        heads.append("Nearest truth")
    heads += ["Colour view", "Depth view"]
    ge, gn = frame.to_en([t[1] for t in truth], [t[2] for t in truth])
    rows = []
    for h in holes:
        band = score_band(h.score)
        e, n = (float(v) for v in frame.to_en(h.lat_deg, h.lon_deg))
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
        p_hole = f"{h.p_hole:.2f}" if math.isfinite(h.p_hole) else "&mdash;"
        cells = [
            f'<td><span class="badge" style="background:{band.hex}">{h.id}</span></td>',
            f"<td>{_e(tiers[h.id])}</td>",
            f'<td><b class="score">{p_hole}</b><div class="note">{h.score:.2f} '
            f"({band.name})</div></td>",
            f'<td class="mono">{h.lat_deg:.7f}<br>{h.lon_deg:.7f}{where}</td>',
            f'<td class="nw">{_R95 * h.sigma_h_m:.2f} m<div class="note">1&sigma; '
            f"{h.sigma_h_m:.2f} m</div></td>",
            f'<td class="nw">{size}</td>',
            f'<td class="num">{h.sightings} / {h.views}</td>',
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
    :func:`ground.depth_colour` over the crop (near = bright).
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


@functools.cache
def _css() -> str:
    """The page's style sheet (``ground/report/report.css``, inlined: the page needs no file)."""
    css = resources.files("holescan.ground.report").joinpath("report.css")
    return css.read_text(encoding="utf-8")
