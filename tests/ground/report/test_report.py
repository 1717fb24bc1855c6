"""The offline flight report: parsed back, checked to scale, and rendered by headless Chromium."""

from __future__ import annotations

import base64
import dataclasses
import datetime as dt
import math
import re
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
import pymap3d
import pytest

from holescan.errors import InputError
from holescan.geotag import CIRCLE_95_PER_SIGMA, Hole, VehiclePose
from holescan.ground.report import SCORE_BANDS, render_report, score_band, thumbnails, write_report
from holescan.outputs import part_path

LAT0, LON0 = 47.3769, 8.5417
CHROMIUM = Path("/usr/bin/chromium")


def geo(north: float, east: float) -> tuple[float, float]:
    lat, lon, _ = pymap3d.enu2geodetic(east, north, 0.0, LAT0, LON0, 0.0)
    return float(lat), float(lon)


def lawnmower(legs: int = 4, length_m: float = 30.0, spacing_m: float = 8.0) -> list[VehiclePose]:
    """North/south legs from (0, 0), one pose per 0.5 m at 2.5 m/s."""
    poses, t_ns = [], 1_000_000_000
    for leg in range(legs):
        for i in range(int(length_m / 0.5) + 1):
            n = i * 0.5 if leg % 2 == 0 else length_m - i * 0.5
            lat, lon = geo(n, leg * spacing_m)
            poses.append(VehiclePose(t_ns, lat, lon, 430.0, 5.0, 0.0, 0.0, 0.0))
            t_ns += 200_000_000
    return poses


def make_view(seed: int, box: tuple[int, int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Textured rubble with a dark elliptic opening in ``box`` that is 0.8 m deeper."""
    rng = np.random.default_rng(seed)
    rgb = rng.integers(80, 190, (480, 640, 3)).astype(np.uint8)
    x, y, w, h = box
    centre, axes = (x + w // 2, y + h // 2), (w // 2, h // 2)
    cv2.ellipse(rgb, centre, axes, 0, 0, 360, (25, 20, 15), -1)
    yy, xx = np.mgrid[:480, :640]
    r2 = ((xx - centre[0]) / axes[0]) ** 2 + ((yy - centre[1]) / axes[1]) ** 2
    depth = np.where(r2 < 1, 3800, 3000).astype(np.uint16)
    depth[:10] = 0  # a strip without readings
    return rgb, depth


def hole(
    hid: int, north: float, east: float, score: float, sigma: float, major: float, n: int
) -> Hole:
    lat, lon = geo(north, east)
    t = 1_000_000_000 + hid * 4_000_000_000
    box = (200 + 20 * hid, 150, 100 + 10 * hid, 80)
    return Hole(
        hid,
        lat,
        lon,
        420.0,
        sigma,
        score,
        n,
        t,
        t + 2_500_000_000,
        10 * hid,
        box,
        major,
        0.7 * major,
    )


@pytest.fixture
def flight() -> dict[str, object]:
    holes = [
        hole(1, 6.0, 4.0, 0.91, 0.35, 0.9, 12),
        hole(2, 7.2, 4.5, 0.58, 0.5, 0.7, 4),
        hole(3, 22.0, 17.0, 0.31, 1.6, 1.4, 1),
        hole(4, 26.0, 24.5, 0.77, 0.25, 0.6, 9),
    ]
    views = {h.id: make_view(h.id, h.best_box) for h in holes if h.id != 3}
    truth = [("T1 <north & rubble>", *geo(6.3, 4.1)), ("T2", *geo(21.0, 16.5))]
    facts = {"log": "flight_0001.mcap", "frames": "4312", "note": "<script>alert(1)</script>"}
    return {
        "title": "Sector B <west> & C",
        "holes": holes,
        "track": lawnmower(),
        "views": views,
        "truth": truth,
        "facts": facts,
    }


class Page(HTMLParser):
    """Collects what the tests look at: table rows, SVG shapes, texts, every src/href."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.stack: list[str] = []
        self.rows: list[list[str]] = []
        self.imgs: list[dict[str, str]] = []
        self.urls: list[str] = []
        self.tags: set[str] = set()
        self.svg: list[tuple[str, dict[str, str]]] = []
        self.svg_text: list[tuple[dict[str, str], str]] = []
        self.text: list[str] = []
        self._cell: list[str] | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = {k: v or "" for k, v in attrs}
        self.tags.add(tag)
        self.urls += [v for k, v in a.items() if k in ("src", "href", "xlink:href", "action")]
        if tag == "tr" and "tbody" in self.stack:
            self.rows.append([])
        if tag == "td" and self.rows and "tbody" in self.stack:
            self._cell = []
        if tag == "img":
            self.imgs.append(a)
        if "svg" in self.stack or tag == "svg":
            self.svg.append((tag, a))
        if tag not in ("img", "meta", "br", "rect", "circle", "path", "line", "polyline"):
            self.stack.append(tag)

    def handle_endtag(self, tag: str) -> None:
        if tag == "td" and self._cell is not None:
            self.rows[-1].append(" ".join("".join(self._cell).split()))
            self._cell = None
        if tag in self.stack:
            while self.stack.pop() != tag:
                pass

    def handle_data(self, data: str) -> None:
        self.text.append(data)
        if self._cell is not None:
            self._cell.append(data + " ")
        if self.stack and self.stack[-1] == "text" and self.svg:
            self.svg_text.append((self.svg[-1][1], data))


def parse(page: str) -> Page:
    p = Page()
    p.feed(page)
    p.close()
    return p


def decode_png(uri: str) -> npt.NDArray[np.uint8]:
    assert uri.startswith("data:image/png;base64,")
    buf = np.frombuffer(base64.b64decode(uri.split(",", 1)[1]), np.uint8)
    img = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    assert img is not None
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def near(img: np.ndarray, rgb: tuple[int, int, int], tol: int = 6) -> int:
    """Number of pixels within ``tol`` of ``rgb`` in every channel."""
    return int(np.all(np.abs(img[..., :3].astype(int) - rgb) <= tol, axis=-1).sum())


def test_table_rows_thumbnails_and_escaping(flight: dict, tmp_path: Path) -> None:
    out = write_report(tmp_path / "report.html", **flight)
    page = out.read_text(encoding="utf-8")
    p = parse(page)
    holes: list[Hole] = flight["holes"]
    assert len(p.rows) == len(holes)
    for row, h in zip(p.rows, holes, strict=True):
        assert row[0] == str(h.id)
        assert row[1] == "announced"  # no tiers given: announced
        p_hole = f"{h.p_hole:.2f}" if math.isfinite(h.p_hole) else "—"
        assert row[2].startswith(f"{p_hole} {h.score:.2f} ({score_band(h.score).name})")
        assert f"{h.lat_deg:.7f} {h.lon_deg:.7f}" in row[3]
        # sigma_h is the 68 % circle (issue 14): the 95 % one is 2.448 / 1.510 times it.
        r95 = math.sqrt(math.log(0.05) / math.log(0.32))
        assert row[4].startswith(f"{r95 * h.sigma_h_m:.2f} m")
        assert f"1σ {h.sigma_h_m:.2f} m" in row[4]
        assert row[5] == f"{h.major_m:.2f} × {h.minor_m:.2f} m"
        assert row[6] == f"{h.sightings} / {h.views}"
        t0_ns = flight["track"][0].t_boot_ns
        first, last = ((t - t0_ns) / 1e9 for t in (h.t_first_boot_ns, h.t_last_boot_ns))
        assert row[7] == f"{first:.1f} – {last:.1f}"
    # distance and bearing from the take-off point: hole 1 is 6 m north, 4 m east
    bearing = math.degrees(math.atan2(4, 6))
    assert f"{math.hypot(6, 4):.1f} m at {bearing:03.0f}° from start" in p.rows[0][3]
    assert p.rows[0][8] == "T1 <north & rubble> 0.32 m"  # nearest truth, unescaped on parse
    assert p.rows[2][-1] == "no image"  # hole 3 has no view
    # everything is inside the file: no URL but data URIs, no script
    assert not re.search(r"https?://", page)
    assert p.urls
    assert all(u.startswith("data:image/png;base64,") for u in p.urls)
    assert "script" not in p.tags
    assert "link" not in p.tags
    assert "<script>alert(1)</script>" in "".join(p.text)  # shown as text, escaped in the file
    assert "Sector B <west> & C" in "".join(p.text)
    # two thumbnails per hole with a view, 200 px wide, the box drawn in the hole's colour
    assert len(p.imgs) == 2 * 3
    for img in p.imgs:
        t = decode_png(img["src"])
        assert t.shape[1] == int(img["width"]) <= 200
        assert t.shape[0] == int(img["height"]) <= 200
        hid = int(img["alt"].split()[1])
        assert near(t, score_band(holes[hid - 1].score).rgb, tol=3) > 150
    assert part_path(out).exists() is False


def test_map_is_to_scale(flight: dict) -> None:
    p = parse(render_report(**flight))
    start = next(i for i, (t, a) in enumerate(p.svg) if t == "svg" and a.get("class") == "map")
    p.svg = p.svg[start:]  # the map, not the legend's swatches
    svg = p.svg[0][1]
    assert svg["viewbox"] == f"0 0 {svg['width']} {svg['height']}"
    # metres per pixel from the scale bar: its two halves and its label
    bar = [a for tag, a in p.svg if tag == "rect" and a.get("height") == "8"]
    label = next(t for a, t in p.svg_text if a.get("class") == "scale" and t.endswith(" m"))
    px_per_m = sum(float(a["width"]) for a in bar) / float(label.split()[0])
    # opening circles: diameter = major axis; centres: distances as on the ground
    holes: list[Hole] = flight["holes"]
    openings = [a for tag, a in p.svg if tag == "circle" and a.get("fill") == "#1b1b1b"]
    assert len(openings) == len(holes)
    for a, h in zip(openings, holes, strict=True):
        assert 2 * float(a["r"]) / px_per_m == pytest.approx(h.major_m, abs=0.02)
    xy = np.array([(float(a["cx"]), float(a["cy"])) for a in openings])
    d_px = np.hypot(*(xy[3] - xy[0]))
    assert d_px / px_per_m == pytest.approx(math.hypot(26 - 6, 24.5 - 4), rel=2e-3)
    assert xy[3][1] < xy[0][1]
    assert xy[3][0] > xy[0][0]
    # uncertainty circles: the 95 % circle, but never smaller than the visible minimum
    sig = [a for tag, a in p.svg if tag == "circle" and a.get("fill-opacity") == "0.16"]
    for a, h in zip(sig, holes, strict=True):
        r = max(CIRCLE_95_PER_SIGMA * h.sigma_h_m * px_per_m, 7.0)
        assert float(a["r"]) == pytest.approx(r, abs=0.06)
    # an id badge per hole, in its band colour; the two truth markers with their names
    ids = [t for a, t in p.svg_text if a.get("class") == "id"]
    assert ids == [str(h.id) for h in holes]
    texts = [t for _, t in p.svg_text]
    assert {"T1 <north & rubble>", "T2", "N", "start", "end"} <= set(texts)
    badges = [a["fill"] for tag, a in p.svg if tag == "circle" and a.get("r") == "15"]
    assert badges == [score_band(h.score).hex for h in holes]


def scale_of(shapes: list[tuple[str, dict[str, str]]], texts: list[str]) -> float:
    """Pixels per metre of one map, from its scale bar's two halves and its label."""
    bar = [a for tag, a in shapes if tag == "rect" and a.get("height") == "8"]
    label = next(t for t in texts if re.fullmatch(r"\d+(\.\d+)? m", t))
    return sum(float(a["width"]) for a in bar) / float(label.split()[0])


def test_close_up_when_the_holes_fill_little_of_the_flight(flight: dict) -> None:
    transit = [
        VehiclePose(i * 100_000_000, *geo(0.0, -300.0 + i), 430.0, 5.0, 0.0, 0.0, 0.0)
        for i in range(300)
    ]
    p = parse(render_report(**{**flight, "track": transit + flight["track"]}))
    starts = [i for i, (t, a) in enumerate(p.svg) if t == "svg" and a.get("class") == "map"]
    assert len(starts) == 2
    assert "Close-up of the holes" in p.text
    overview, close = p.svg[starts[0] : starts[1]], p.svg[starts[1] :]
    texts = [t for _, t in p.svg_text]
    split = len(texts) - texts[::-1].index("start") - 1  # close-up texts begin after this
    s_over = scale_of(overview, [t for t in texts[:split] if t.endswith(" m")])
    s_close = scale_of(close, [t for t in texts[split:] if t.endswith(" m")])
    assert s_close > 4 * s_over
    for shapes, px_per_m in ((overview, s_over), (close, s_close)):
        openings = [a for tag, a in shapes if tag == "circle" and a.get("fill") == "#1b1b1b"]
        for a, h in zip(openings, flight["holes"], strict=True):  # radii have 0.1 px steps
            assert 2 * float(a["r"]) / px_per_m == pytest.approx(h.major_m, abs=0.12 / px_per_m)


def test_no_hole_and_no_track(tmp_path: Path) -> None:
    page = write_report(
        tmp_path / "empty.html", title="Empty", holes=[], track=lawnmower(2), views={}
    ).read_text()
    p = parse(page)
    assert "No hole found" in p.text
    assert p.rows == []
    assert "svg" in p.tags
    assert not p.imgs
    assert page.index("No hole found") < page.index("<svg")  # the news comes first
    # holes but no track: the map is centred on the holes and has no track line
    h = hole(1, 3.0, 2.0, 0.8, 0.4, 0.8, 3)
    p = parse(render_report(title="t", holes=[h], track=[], views={}))
    assert len(p.rows) == 1
    assert "polyline" not in {t for t, _ in p.svg}
    assert "from start" not in p.rows[0][2]
    # nothing at all: still a page with its map frame
    p = parse(render_report(title="nothing", holes=[], track=[], views={}))
    assert "No hole found" in p.text
    assert [t for t, a in p.svg if t == "svg" and a.get("class") == "map"] == ["svg"]


def test_deterministic_output(flight: dict) -> None:
    """The page depends on the flight only (no clock, no random id): the same flight built
    again from new objects gives the same bytes, and what the page shows is the input."""
    page = render_report(**flight)
    rebuilt = {
        **flight,
        "holes": [dataclasses.replace(h) for h in flight["holes"]],
        "track": [dataclasses.replace(q) for q in flight["track"]],
        "views": {k: (rgb.copy(), depth.copy()) for k, (rgb, depth) in flight["views"].items()},
        "truth": list(flight["truth"]),
        "facts": dict(flight["facts"]),
    }
    assert render_report(**rebuilt) == page
    # what it shows is the known input: ids, scores and positions of the holes in order ...
    p = parse(page)
    holes: list[Hole] = flight["holes"]
    assert [row[0] for row in p.rows] == [str(h.id) for h in holes]
    for row, h in zip(p.rows, holes, strict=True):
        assert f"{h.score:.2f}" in row[2]
        assert f"{h.lat_deg:.7f} {h.lon_deg:.7f}" in row[3]
    # ... each colour thumbnail centred on its hole's dark opening (drawn in the box's middle)
    colour = [img for img in p.imgs if img["alt"].endswith(" colour")]
    assert [int(img["alt"].split()[1]) for img in colour] == sorted(flight["views"])
    for img in colour:
        t = decode_png(img["src"]).astype(int)
        cy, cx = t.shape[0] // 2, t.shape[1] // 2
        assert np.all(np.abs(t[cy - 3 : cy + 4, cx - 3 : cx + 4] - (25, 20, 15)) <= 8), img["alt"]
    # ... and nothing of the moment it was rendered (no date, no time of day) in its text
    text = " ".join(p.text)
    assert not re.search(rf"\b{dt.datetime.now(dt.UTC).year}\b", text)
    assert not re.search(r"\b\d{1,2}:\d{2}\b", text)


def test_thumbnail_at_image_corner() -> None:
    rgb, depth = make_view(0, (0, 0, 40, 30))
    rgb[5:25, 5:35] = (0, 255, 0)  # inside the box
    t_rgb, t_depth = thumbnails(rgb, depth, (0, 0, 40, 30), (255, 0, 255))
    # crop 64 x 54 px (box + 24 px margin, clipped at the corner), scaled by 200 / 64
    assert t_rgb.shape == t_depth.shape == (169, 200, 3)
    assert near(t_rgb[10:80, 10:100], (0, 255, 0), tol=2) > 3000
    assert near(t_rgb[85:100, :130], (255, 0, 255), tol=3) > 100  # bottom edge of the box
    assert near(t_rgb[100:], (255, 0, 255), tol=40) == 0
    assert near(t_depth, (255, 0, 255), tol=3) > 300
    # the strip without readings stays black in the depth picture, the rest is coloured
    assert np.all(t_depth[:25, 132:] == 0)
    assert np.all(t_depth[40:80, 150:].max(axis=-1) > 0)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"holes": "dup"}, "unique"),
        ({"holes": "nan"}, "finite position"),
        ({"views": "box"}, "outside"),
        ({"views": "dtype"}, "uint16"),
    ],
)
def test_bad_input(flight: dict, change: dict[str, str], message: str) -> None:
    holes: list[Hole] = list(flight["holes"])
    views = dict(flight["views"])
    kind = next(iter(change.values()))
    if kind == "dup":
        holes.append(holes[0])
    elif kind == "nan":
        holes[1] = hole(2, math.nan, 0.0, 0.5, 0.5, 0.5, 2)
    elif kind == "box":
        rgb, depth = views[1]
        views[1] = (rgb[:100, :100].copy(), depth[:100, :100].copy())
    else:
        views[2] = (views[2][0], views[2][1].astype(np.float32))
    with pytest.raises(InputError, match=message):
        render_report(**{**flight, "holes": holes, "views": views})


def test_unwritable_folder(flight: dict, tmp_path: Path) -> None:
    with pytest.raises(InputError, match="cannot write"):
        write_report(tmp_path / "missing" / "r.html", **flight)


@pytest.mark.skipif(not CHROMIUM.exists(), reason="needs Debian chromium (/usr/bin/chromium)")
def test_renders_in_headless_chromium(flight: dict, tmp_path: Path) -> None:
    out = write_report(tmp_path / "report.html", **flight)
    shot = tmp_path / "shot.png"
    cmd = [
        str(CHROMIUM),
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        f"--user-data-dir={tmp_path / 'profile'}",
        f"--screenshot={shot}",
        "--window-size=1280,2000",
        out.resolve().as_uri(),
    ]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)
    assert res.returncode == 0, res.stderr[-2000:]
    img = cv2.imread(str(shot), cv2.IMREAD_COLOR)
    assert img is not None
    assert img.shape[:2] == (2000, 1280)
    img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    assert float(img.std()) > 20.0  # not a blank page
    # every score band used by a hole shows up, in its own colour (badges on map and table)
    for band in SCORE_BANDS:
        assert near(img, band.rgb, tol=4) > 1500, band  # the legend alone has < 800
    assert near(img, (21, 101, 192), tol=20) > 2000  # the track line (legend alone: ~300)
    # the thumbnails' opening colour is there too: the images decoded and drew
    assert near(img, (25, 20, 15), tol=6) > 5000
