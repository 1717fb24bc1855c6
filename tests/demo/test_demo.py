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
from holescan.demo._run import DEMO_SORTIE
from holescan.flightlog import log_info
from holescan.geotag import AnnounceGate, Hole
from holescan.ground import read_flight_holes
from holescan.sim import TrueHole, make_sortie_world, true_holes

CHROMIUM = Path("/usr/bin/chromium")
SIZE = (6.0, 6.0)


def distance_m(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    e, n, _ = pymap3d.geodetic2enu(lat1, lon1, 0.0, lat2, lon2, 0.0)
    return math.hypot(float(e), float(n))


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    out = tmp_path_factory.mktemp("demo") / "run"
    argv = ["demo", "--out", str(out), "--duration", "12", "--size", str(SIZE[0]), str(SIZE[1])]
    proc = subprocess.run(
        ["python", "-m", "holescan.cli", *argv],
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
        cwd=Path(__file__).resolve().parents[2],
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "flying 12 s" in proc.stderr  # the progress display
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
            m = re.search(r"as hole (\d+) \(p_hole [\d.]+, score [\d.]+\), (\d+) cm off", rest)
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
    m = re.search(r"=> found (\d+) of (\d+) in view, missed (\d+), false (\d+)", text)
    assert m is not None
    found, in_view, missed, false = (int(v) for v in m.groups())
    assert (found, missed, false) == (len(found_ids), in_view - found, len(false_ids))
    assert found >= 1  # the demo's short run over the small field finds holes
    doc = json.loads((out / "demo.json").read_text())
    assert (doc["found"], doc["missed"], doc["false"]) == (found, missed, false)
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
    assert info.frames == doc["frames_captured"] > 50
    assert "/mavlink/raw" in info.topics and "/holes" in info.topics
    confirmed = doc["found"] + doc["false"]
    # Each confirmed hole was announced to the ground station and served as a waypoint;
    # each hole for review was sent too (REVIEW), never a waypoint.
    texts = [t for t in doc["announcements"] if t.startswith("HOLE ")]
    told = [t for t in doc["announcements"] if not t.startswith("HOLE ")]
    assert len({t.split()[1] for t in texts}) == confirmed
    assert all(re.fullmatch(r"HOLE \d+ [\d.]+ -?[\d.]+ -?[\d.]+", t) for t in texts)
    assert all(re.fullmatch(r"REVIEW \d+ [\d.]+ -?[\d.]+ -?[\d.]+", t) for t in told)
    review = doc["review"]
    assert {int(t.split()[1]) for t in told} >= set(review)
    assert doc["mission_items"] == confirmed
    assert f"downloaded a mission of {confirmed} hole waypoints" in text
    # the live map flew too: its tiles reached the ground station's store, on disk
    tiles = doc["map_tiles_at_ground"]
    assert tiles >= 2 and f"{tiles} live-map tiles" in text
    assert len(list((out / "ground" / "map").glob("m*-cov-*.png"))) * 2 >= tiles
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
    assert "expected at the default gate: about 70 per hectare (benchmarks/bench_tiers" in text
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
    (tmp_path / "flight_0000.mcap").write_bytes(b"x")
    assert cli.main(["demo", "--out", str(tmp_path), "--duration", "5"]) == 2
    assert "already holds a demo flight" in capsys.readouterr().err
