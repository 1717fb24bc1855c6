"""The report's search-map section: orthophoto with the holes, the coverage layer, figures.

Pure HTML and CSS (a checkbox shows or hides the coverage layer; no script): the
orthophoto fused from the flight's own frames, north up, each hole drawn at its position
with its 95 % circle, the coverage (the probability an access hole would have been found,
red 0 .. green 1, transparent where nothing was seen) over it, the gaps outlined, and the
searched fraction of the planned (or surveyed) area.
"""

from __future__ import annotations

import base64
import html
from collections.abc import Sequence

import cv2
import numpy as np
import numpy.typing as npt
from shapely.geometry import Polygon

from holescan.geotag import CIRCLE_95_PER_SIGMA, Hole, LocalFrame
from holescan.mapping import MapLayers

__all__ = ["HONEST_POSITIONS", "coverage_rgba", "search_map_section"]

_MAX_PX = 900

HONEST_POSITIONS = (
    "The map and the holes are placed with the same poses (the flight's GNSS and attitude), "
    "so they carry the same errors: a hole sits on its picture in the orthophoto even when "
    "GNSS is off by metres, and both may be off together against another map."
)


def coverage_rgba(layers: MapLayers) -> npt.NDArray[np.uint8]:
    """(ny, nx, 4) RGBA: coverage red (0) -> yellow -> green (1), transparent where unseen."""
    c = np.clip(layers.coverage, 0.0, 1.0)
    r = np.clip(2.0 * (1.0 - c), 0.0, 1.0)
    g = np.clip(2.0 * c, 0.0, 1.0)
    a = np.where(layers.looks > 0, 170, 0)
    return np.stack([r * 255, g * 255, np.zeros_like(c), a], axis=-1).astype(np.uint8)


def _uri(img: npt.NDArray[np.uint8], kind: str) -> str:
    if kind == "jpeg":
        ok, buf = cv2.imencode(
            ".jpg", cv2.cvtColor(img, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 82]
        )
    else:
        ok, buf = cv2.imencode(".png", cv2.cvtColor(img, cv2.COLOR_RGBA2BGRA))
    if not ok:
        raise ValueError("image encoding failed")
    mime = "image/jpeg" if kind == "jpeg" else "image/png"
    return f"data:{mime};base64,{base64.b64encode(buf.tobytes()).decode()}"


def search_map_section(
    layers: MapLayers,
    frame: LocalFrame,
    holes: Sequence[Hole],
    *,
    searched_fraction: float,
    area_m2: float,
    planned: bool,
    threshold: float,
    gaps: Sequence[Polygon] = (),
    notes: Sequence[str] = (),
) -> str:
    """The section's HTML (one ``<section>``)."""
    g = layers.grid
    scale = min(1.0, _MAX_PX / max(g.nx, g.ny))
    w, h = max(1, round(g.nx * scale)), max(1, round(g.ny * scale))
    px_per_m = scale / g.cell_m
    seen = np.isfinite(layers.height_m)
    ortho = np.where(seen[..., None], layers.rgb, 235).astype(np.uint8)
    ortho = np.asarray(cv2.resize(ortho, (w, h), interpolation=cv2.INTER_AREA), np.uint8)
    cov = np.asarray(
        cv2.resize(coverage_rgba(layers), (w, h), interpolation=cv2.INTER_NEAREST), np.uint8
    )

    def px(e: float, n: float) -> tuple[int, int]:
        return (round((e - g.west_m) * px_per_m), round((g.north_m - n) * px_per_m))

    for p in gaps:
        ring = np.array([px(x, y) for x, y in p.exterior.coords], np.int32)
        cv2.polylines(cov, [ring], True, (0, 0, 255, 255), 2)
    for hole in holes:
        e, n = frame.to_en(hole.lat_deg, hole.lon_deg)
        c = px(float(e), float(n))
        r = max(3, round(CIRCLE_95_PER_SIGMA * hole.sigma_h_m * px_per_m))
        cv2.circle(ortho, c, r, (255, 0, 255), 2)
        cv2.putText(
            ortho,
            str(hole.id),
            (c[0] + r + 2, c[1]),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.5,
            (255, 0, 255),
            1,
        )
    bar_m = 1.0 if g.nx * g.cell_m < 20 else 5.0
    bar = f'<span class="scalebar" style="width:{bar_m * px_per_m:.0f}px">{bar_m:g} m</span>'
    what = "planned area" if planned else "surveyed area (hull of the cells seen)"
    lines = [
        f"Searched: <b>{searched_fraction:.1%}</b> of the {what} ({area_m2:.0f} m&sup2;): the "
        f"part where an access hole would have been detected with probability &ge; "
        f"{threshold:g}; {len(gaps)} gap(s) outlined in blue.",
        html.escape(HONEST_POSITIONS),
        *(html.escape(n) for n in notes),
    ]
    return (
        '<section class="searchmap"><h2>Search map</h2>'
        + "".join(f"<p>{t}</p>" for t in lines)
        + '<input type="checkbox" id="covlayer" checked> <label for="covlayer">coverage layer'
        "</label>"
        f'<div class="mapstack" style="position:relative;width:{w}px;height:{h}px">'
        f'<img alt="orthophoto with the holes" src="{_uri(ortho, "jpeg")}" '
        f'style="position:absolute;left:0;top:0;width:{w}px;height:{h}px">'
        f'<img class="cov" alt="coverage" src="{_uri(cov, "png")}" '
        f'style="position:absolute;left:0;top:0;width:{w}px;height:{h}px"></div>'
        f"<p>North up. {bar} Coverage: red 0, yellow 0.5, green 1; uncoloured: not seen.</p>"
        "<style>#covlayer:not(:checked) ~ .mapstack .cov{display:none}"
        ".scalebar{display:inline-block;border-bottom:3px solid #000;text-align:center}</style>"
        "</section>"
    )
