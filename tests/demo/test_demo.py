"""``holescan demo``: a short run of the whole system (simulated autopilot over loopback UDP,
capture daemon, simulated Xtion, mission server and a ground-station peer), its printed
score checked against the simulator's truth recomputed here from the world and the holes
read back from the flight log, its files parsed back, its report rendered by Chromium."""

from __future__ import annotations

import dataclasses
import json
import math
import re
import subprocess
from pathlib import Path

import cv2
import gpxpy
import pymap3d
import pytest
from shapely.geometry import Point, Polygon

from holescan import cli
from holescan.demo import REVIEW_PER_HA_MEASURED
from holescan.demo._run import DEMO_SORTIE
from holescan.flightlog import log_info
from holescan.geotag import AnnounceGate, Hole
from holescan.ground import read_flight_holes
from holescan.sim import TrueHole, make_sortie_world, true_holes

CHROMIUM = Path("/usr/bin/chromium")
R95 = math.sqrt(math.log(0.05) / math.log(0.32))  # the 95 % circle per sigma (Rayleigh)
SIZE = (6.0, 6.0)
MIN_FRAMES = 60


def distance_m(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    e, n, _ = pymap3d.geodetic2enu(lat1, lon1, 0.0, lat2, lon2, 0.0)
    return math.hypot(float(e), float(n))


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    base = tmp_path_factory.mktemp("demo")
    # The short run's lawnmower passes one access hole at the field's edge, whole in view
    # in about 3 frames: on a loaded machine the camera's frames can fall so that it is
    # whole in none (seen 2026-12-07: found for review, yet "not in view"). A run with no
    # hole in view checks nothing below, so it is flown again (at most 3 runs).
    for attempt in range(3):
        out = base / ("run" if attempt == 0 else f"run{attempt}")
        argv = ["demo", "--out", str(out), "--duration", "12", "--size", str(SIZE[0]), str(SIZE[1])]
        # 12 s give 60-70 frames alone; on a loaded machine the renderer gives a third of
        # that and the detector less still (it runs below capture): the flight goes on until
        # the camera delivered as many frames as alone, so there is as much to find.
        argv += ["--min-frames", str(MIN_FRAMES)]
        proc = subprocess.run(
            ["python", "-m", "holescan.cli", *argv],
            capture_output=True,
            text=True,
            timeout=480,  # a hang guard: 1-2 min alone, 3-4 min on a loaded machine
            check=False,
            cwd=Path(__file__).resolve().parents[2],
        )
        assert proc.returncode == 0, proc.stderr[-3000:]
        assert f"flying 12 s, at least {MIN_FRAMES} frames" in proc.stderr  # the progress display
        truth = json.loads((out / "demo.json").read_text())["truth"]
        if any(row["status"] != "not in view" for row in truth):
            break
    return out, proc.stdout


@pytest.mark.slow
def test_printed_score_is_the_truth(demo: tuple[Path, str]) -> None:
    out, text = demo
    sortie = dataclasses.replace(DEMO_SORTIE, size_m=SIZE)
    world = make_sortie_world(sortie)
    a = sortie.anchor
    truth = {t.id: t for t in true_holes(world, a)}
    flight = read_flight_holes(sorted(out.glob("flight_*.mcap")), thumbnails=False)
    told = json.loads((out / "demo.json").read_text())["announcements"]
    said = {int(t.split()[1]) for t in told if t.startswith("HOLE ")}
    confirmed = {h.id: h for h in AnnounceGate().select(flight.holes, said)}

    def centre_m(h: Hole, t: TrueHole) -> float:
        return distance_m(h.lat_deg, h.lon_deg, t.lat_deg, t.lon_deg)

    def finds(h: Hole, t: TrueHole) -> bool:  # within 0.5 m of the centre, or in the opening
        x, y, _ = pymap3d.geodetic2enu(h.lat_deg, h.lon_deg, a.alt_m, a.lat_deg, a.lon_deg, a.alt_m)
        inside = Polygon(world.holes[t.id].opening).contains(Point(float(x), float(y)))
        return centre_m(h, t) <= 0.5 or inside

    row = r"true hole (\d+) at \(([\d.]+), ([\d.]+)\) m, [\d.]+ m wide: (\w+)(.*)"
    rows = re.findall(row, text)
    assert sorted(int(r[0]) for r in rows) == sorted(truth)  # every true access hole listed
    found_ids = []
    for tid, x, y, status, rest in rows:
        t = truth[int(tid)]
        assert (float(x), float(y)) == (round(t.x_m, 1), round(t.y_m, 1))
        if status == "FOUND":
            m = re.search(
                r"as hole (\d+) \(p_hole [\d.]+, best frame's score [\d.]+\), (\d+) cm off", rest
            )
            assert m is not None
            h = confirmed[int(m[1])]  # a confirmed hole of the logged flight
            assert finds(h, t) and abs(100 * centre_m(h, t) - int(m[2])) <= 1
            found_ids.append(h.id)
        else:
            assert status in ("MISSED", "not")
    for tid, _, _, status, _ in rows:  # no confirmed hole left over could have found a missed one
        if status != "FOUND":
            t = truth[int(tid)]
            assert not any(finds(h, t) for h in confirmed.values() if h.id not in found_ids)
    false_ids = [int(i) for i in re.findall(r"hole (\d+): FALSE", text)]
    assert sorted(found_ids + false_ids) == sorted(confirmed)  # each confirmed hole scored once
    m = re.search(
        r"=> holes found \(announced \+ for review\): (\d+); true holes found (\d+) of (\d+) "
        r"in view, missed (\d+), announced false (\d+)",
        text,
    )
    assert m is not None
    n_found, found, in_view, missed, false = (int(v) for v in m.groups())
    assert (found, missed, false) == (len(found_ids), in_view - found, len(false_ids))
    assert found >= 1  # the demo's short run over the small field finds holes
    doc = json.loads((out / "demo.json").read_text())
    assert (doc["found"], doc["missed"], doc["false"]) == (found, missed, false)
    assert doc["holes_found"] == n_found == len(confirmed) + len(doc["review"])
    # The search map: the searched fraction, and why each true hole not found was missed.
    m = re.search(r"search map: ([\d.]+)% of the planned (\d+) m2 searched", text)
    assert m is not None and abs(float(m[1]) / 100 - doc["searched_fraction"]) < 1e-3
    assert int(m[2]) == SIZE[0] * SIZE[1]
    why = re.findall(r"the search map: (in a gap|seen and not detected) \(coverage ([\d.]+)", text)
    assert len(why) == len(rows) - found == len(doc["missed_why"])


def test_flight_log_ground_station_and_files(demo: tuple[Path, str]) -> None:
    out, text = demo
    doc = json.loads((out / "demo.json").read_text())
    logs = [Path(p) for p in doc["log_files"]]
    info = log_info(logs)  # every CRC of the flight log
    # The flight lasts 12 s and at least MIN_FRAMES frames (more on a fast machine):
    # every frame the sensor numbered is in the log, none dropped, and the printed count
    # and rate are the log's.
    n = info.frames
    assert n == doc["frames_captured"] >= MIN_FRAMES and n >= doc["frames_detected"] > 0
    assert not doc["interrupted"]  # flown to the end
    assert not info.dropped_frames and not info.frame_index_gaps, info
    rate = n / doc["capture_s"]
    assert f"frames: {n} captured ({rate:.1f}/s), {doc['frames_detected']} detected" in text
    assert "/mavlink/raw" in info.topics and "/holes" in info.topics
    confirmed = doc["found"] + doc["false"]
    # Each confirmed hole was announced to the ground station and served as a waypoint;
    # each hole for review was sent too (REVIEW), never a waypoint.
    texts = [t for t in doc["announcements"] if t.startswith("HOLE ")]
    told = [t for t in doc["announcements"] if not t.startswith("HOLE ")]
    assert len({t.split()[1] for t in texts}) == confirmed
    assert all(re.fullmatch(r"HOLE \d+ p[01]\.\d\d -?[\d.]+ -?[\d.]+", t) for t in texts)
    assert all(re.fullmatch(r"REVIEW \d+ p[01]\.\d\d -?[\d.]+ -?[\d.]+", t) for t in told)
    review = doc["review"]
    assert {int(t.split()[1]) for t in told} >= set(review)
    assert doc["mission_items"] == confirmed
    assert f"downloaded a mission of {confirmed} hole waypoints" in text
    # the live map flew too: its tiles reached the ground station's store, on disk
    tiles = doc["map_tiles_at_ground"]
    assert tiles >= 2 and f"{tiles} live-map tiles" in text
    assert len(list((out / "ground" / "map").glob("*m*-cov-*.png"))) * 2 >= tiles
    files = doc["files"]
    gpx = gpxpy.parse(Path(files["gpx"]).read_text())
    assert len(gpx.waypoints) == confirmed + len(review)
    assert sum(w.name.startswith("review ") for w in gpx.waypoints) == len(review)
    plan = json.loads(Path(files["plan"]).read_text())
    assert len(plan["mission"]["items"]) == confirmed
    feats = json.loads(Path(files["geojson"]).read_text())["features"]
    assert sorted(f["properties"]["tier"] for f in feats) == sorted(
        ["announced"] * confirmed + ["review"] * len(review)
    )
    # The stated review load: this flight's, per hectare, next to the measured figure.
    per_ha = round(len(review) / (doc["area_m2"] / 1e4))
    assert f"{len(review)} holes, {doc['review_true']} at a true opening, {per_ha} per " in text
    expected = f"expected at the default gate: about {REVIEW_PER_HA_MEASURED} per hectare ("
    assert expected + "benchmarks/bench_tiers" in text
    page = Path(files["report"]).read_text()
    shown = confirmed + len(review)
    # Two pictures per hole shown, and the search map's coverage layer.
    assert page.count("true hole") >= 4 and page.count("data:image/png;base64,") == 2 * shown + 1
    assert "Search map" in page
    for path in files.values():
        assert str(out) in path
    assert f"holescan reprocess {logs[0]}" in text


@pytest.mark.skipif(not CHROMIUM.exists(), reason="needs Debian chromium (/usr/bin/chromium)")
def test_report_renders_in_headless_chromium(demo: tuple[Path, str], tmp_path: Path) -> None:
    out, _ = demo
    shot = tmp_path / "shot.png"
    cmd = [
        str(CHROMIUM),
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        f"--user-data-dir={tmp_path / 'profile'}",
        f"--screenshot={shot}",
        "--window-size=1280,1600",
        (out / "flight_report.html").resolve().as_uri(),
    ]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)
    assert res.returncode == 0, res.stderr[-2000:]
    img = cv2.imread(str(shot), cv2.IMREAD_COLOR)
    assert img is not None and img.shape[:2] == (1600, 1280)
    assert float(img.std()) > 20.0  # a page was drawn, not a blank one


def test_bad_arguments(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        cli.main(["demo", "--duration", "0"])
    with pytest.raises(SystemExit):
        cli.main(["demo", "--min-frames", "-1"])
    (tmp_path / "flight_0000.mcap").write_bytes(b"x")
    assert cli.main(["demo", "--out", str(tmp_path), "--duration", "5"]) == 2
    assert "already holds a demo flight" in capsys.readouterr().err


@pytest.mark.slow
def test_every_output_agrees_on_ids_tiers_positions_and_sigma(demo: tuple[Path, str]) -> None:
    """One flight's outputs read back with independent parsers (json, xml.etree, zipfile,
    html.parser; none of holescan's readers): the same holes, ids, tiers, positions and
    sigma everywhere, candidates in none, "holes found" the same number."""
    import html.parser
    import xml.etree.ElementTree as ET
    import zipfile

    out, _ = demo
    doc = json.loads((out / "demo.json").read_text())
    found_ids = set(doc["tiers"]["announced"]) | set(doc["tiers"]["review"])
    tiers = dict.fromkeys(doc["tiers"]["announced"], "announced")
    tiers |= dict.fromkeys(doc["tiers"]["review"], "review")
    assert doc["holes_found"] == len(found_ids) == len(tiers)
    assert found_ids  # the demo's short run finds holes (test_printed_score_is_the_truth)
    gj = json.loads((out / "flight_holes.geojson").read_text())
    ref = {}
    for f in gj["features"]:
        p = f["properties"]
        lon, lat = f["geometry"]["coordinates"][:2]
        ref[p["hole_id"]] = (p["tier"], lat, lon, p["sigma_h_m"])
        assert p["r95_m"] == pytest.approx(p["sigma_h_m"] * R95, abs=2e-3)
    assert {i: v[0] for i, v in ref.items()} == tiers  # no candidate, every tier the same

    def same_place(hid: int, lat: float, lon: float, tol_m: float = 0.01) -> None:
        assert distance_m(lat, lon, ref[hid][1], ref[hid][2]) < tol_m, hid

    k = "{http://www.opengis.net/kml/2.2}"
    kml = ET.parse(out / "flight_holes.kml").getroot()
    for pm in kml.iter(f"{k}Placemark"):
        data = {d.get("name"): d.findtext(f"{k}value") for d in pm.iter(f"{k}Data")}
        hid = int(json.loads(data["hole_id"] or "0"))
        assert json.loads(data["tier"] or '""') == tiers[hid]
        lon, lat = (
            float(v) for v in (pm.findtext(f"{k}Point/{k}coordinates") or "").split(",")[:2]
        )
        same_place(hid, lat, lon)
    g = "{http://www.topografix.com/GPX/1/1}"
    wpts = ET.parse(out / "flight_holes.gpx").getroot().findall(f"{g}wpt")
    assert len(wpts) == len(tiers)
    for w in wpts:
        name = w.findtext(f"{g}name") or ""
        hid = int(name.split()[-1])
        assert name == (f"hole {hid}" if tiers[hid] == "announced" else f"review {hid}")
        same_place(hid, float(w.get("lat", "nan")), float(w.get("lon", "nan")))
        assert "(95 %)" in (w.findtext(f"{g}desc") or "")
    plan = json.loads((out / "flight_holes.plan").read_text())
    flown = {it["holescan"]["properties"]["hole_id"] for it in plan["mission"]["items"]}
    assert flown == {i for i, t in tiers.items() if t == "announced"}  # review: never flown
    with zipfile.ZipFile(out / "flight_map.kmz") as z:  # the search map: no candidate
        names = [
            pm.findtext(f"{k}name") for pm in ET.fromstring(z.read("doc.kml")).iter(f"{k}Placemark")
        ]
    assert sorted(names) == sorted(
        f"hole {i}" if t == "announced" else f"review {i}" for i, t in tiers.items()
    )
    package = out / "flight_holes_datapackage.zip"  # what TAK gets: the announced holes
    cots = []
    if package.exists() or any(t == "announced" for t in tiers.values()):  # none: no package
        with zipfile.ZipFile(package) as z:
            cots = [ET.fromstring(z.read(n)) for n in z.namelist() if n.endswith(".cot")]
    on_tak = {}
    for ev in cots:
        hid = int(ev.get("uid", "").rsplit("-", 1)[-1])
        pt = ev.find("point")
        assert pt is not None
        same_place(hid, float(pt.get("lat", "nan")), float(pt.get("lon", "nan")))
        assert float(pt.get("ce", "nan")) == pytest.approx(R95 * ref[hid][3], abs=0.01)
        on_tak[hid] = ev.find("detail/holescan").get("tier")  # type: ignore[union-attr]
    assert on_tak == {i: t for i, t in tiers.items() if t == "announced"}

    class Table(html.parser.HTMLParser):
        def __init__(self) -> None:
            super().__init__()
            self.rows: list[list[str]] = []
            self.stats: list[str] = []
            self._cell: list[str] | None = None
            self._in_table = False

        def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
            if tag == "table" and ("class", "holes") in attrs:
                self._in_table = True
            elif self._in_table and tag == "tr":
                self.rows.append([])
            elif self._in_table and tag == "td":
                self._cell = []

        def handle_endtag(self, tag: str) -> None:
            if tag == "td" and self._cell is not None:
                self.rows[-1].append(" ".join(self._cell))
                self._cell = None
            elif tag == "table":
                self._in_table = False

        def handle_data(self, data: str) -> None:
            if self._cell is not None and data.strip():
                self._cell.append(data.strip())
            self.stats.append(data.strip())

    page = Table()
    page.feed((out / "flight_report.html").read_text(encoding="utf-8"))
    rows = [r for r in page.rows if r]
    assert {int(r[0]): r[1] for r in rows} == tiers
    for r in rows:
        lat, lon = (float(v) for v in r[3].split()[:2])
        same_place(int(r[0]), lat, lon, tol_m=0.02)
    i = page.stats.index("holes found")
    assert page.stats[i - 1] == str(doc["holes_found"])
    station = json.loads((out / "ground" / "station.json").read_text())
    at_ground = {h["id"]: h for h in station["holes"]}
    props = {f["properties"]["hole_id"]: f["properties"] for f in gj["features"]}
    for hid, t in tiers.items():  # the station knows every found hole by the same id
        g = at_ground.get(hid)
        assert g is not None and g["tier"] == t, (hid, g)
        # ... with the vehicle's last numbers: every hole whose facts changed since it was
        # told is told once more when the flight ends, and the demo waits for those cards.
        # What is allowed is only the card's rounding: 7 decimals of a degree (<= 1 cm),
        # sigma to 0.01 m, p_hole to 0.001 (plus the files' own rounding, 0.001 m / 0.001).
        same_place(hid, g["lat_deg"], g["lon_deg"], tol_m=0.02)
        assert g["sigma_h_m"] == pytest.approx(ref[hid][3], abs=0.005 + 0.0005), hid
        assert g["p_hole"] == pytest.approx(props[hid]["p_hole"], abs=0.0005 + 0.0005), hid
        assert g["sightings"] == props[hid]["sightings"], hid
