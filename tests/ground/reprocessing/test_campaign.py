"""``holescan campaign``: two simulated sorties over the same world (``conftest.flight`` and
``conftest.flight_b``: different paths, different vehicles' clocks) -> one campaign in
which every hole both saw is one hole with sightings per flight; a bad log in the set."""

from __future__ import annotations

import dataclasses
import json
import math
import zipfile
from collections.abc import Sequence
from pathlib import Path

import pymap3d
import pytest
import rasterio

from holescan import cli
from holescan.capture import FlightSummary
from holescan.errors import InputError
from holescan.geotag import Hole
from holescan.ground import ReprocessOptions, ReprocessResult, StationState, run_campaign
from holescan.link import hole_text
from holescan.sim import RubbleWorld, WorldAnchor

ANCHOR = WorldAnchor(43.6532, -79.3832, 120.0)  # as in conftest.py

Flown = tuple[list[Path], FlightSummary]


def opts(**kw: object) -> ReprocessOptions:
    kw.setdefault("workers", 0)
    kw.setdefault("partition_mib", 0.3)
    return ReprocessOptions(**kw)  # type: ignore[arg-type]


def true_holes(world: RubbleWorld) -> list[tuple[float, float]]:
    out = []
    for h in world.access_holes:
        e, n = h.centre_xy
        lat, lon, _ = pymap3d.enu2geodetic(e, n, 0.0, ANCHOR.lat_deg, ANCHOR.lon_deg, 0.0)
        out.append((float(lat), float(lon)))
    return out


def dist_m(a: tuple[float, float], b: tuple[float, float]) -> float:
    e, n, _ = pymap3d.geodetic2enu(a[0], a[1], 0.0, b[0], b[1], 0.0)
    return math.hypot(e, n)


@pytest.fixture(scope="module")
def campaign(
    flight: Flown, flight_b: Flown, tmp_path_factory: pytest.TempPathFactory
) -> ReprocessResult:
    return run_campaign(
        [*flight[0], *flight_b[0]], tmp_path_factory.mktemp("campaign"), opts(cache=False)
    )


@pytest.mark.slow
def test_a_hole_seen_on_both_sorties_is_one_hole(
    campaign: ReprocessResult, world: RubbleWorld
) -> None:
    by_name = {f.name: f for f in campaign.flights}
    assert set(by_name) == {"sortie", "second"}
    both = 0
    for truth in true_holes(world):
        seen_by = [
            name
            for name, f in by_name.items()
            if any(dist_m(truth, (h.lat_deg, h.lon_deg)) < 1.0 for h in f.for_crew)
        ]
        near = [
            h for h in campaign.campaign if dist_m(truth, (h.hole.lat_deg, h.hole.lon_deg)) < 1.0
        ]
        if not seen_by:
            continue
        assert len(near) == 1, (truth, near)  # one hole, however many flights saw it
        flights = {s.flight for s in near[0].flights}
        assert set(seen_by) <= flights
        both += len(seen_by) == 2
        per = {s.flight: s for s in near[0].flights}
        assert sum(s.sightings for s in per.values()) == near[0].hole.sightings
        for s in per.values():
            assert s.first_seen_unix_ns <= s.last_seen_unix_ns
    assert both >= 1  # the sorties overlap: at least one hole was seen by both
    ids = [h.id for h in campaign.campaign]
    assert ids == sorted(set(ids))


def test_campaign_files_and_summary(campaign: ReprocessResult) -> None:
    kinds = dict(campaign.files)
    holes = {"gpx", "kml", "geojson", "plan", "datapackage", "report"}
    maps = {"ortho", "dsm", "coverage", "map", "gaps"}
    assert holes | maps <= set(kinds) <= holes | maps | {"refly.plan", "refly.waypoints"}
    out = campaign.summary_path.parent

    # The campaign's map is both flights' together: it saw at least what each saw.
    def seen_m2(path: Path) -> float:
        with rasterio.open(path) as ds:
            return float((ds.read(1) > 0).sum()) * abs(ds.transform.a * ds.transform.e)

    both = seen_m2(kinds["coverage"])
    each = [seen_m2(out / n / f"{n}_coverage.tif") for n in ("sortie", "second")]
    assert both >= max(each) and both <= sum(each) + 1.0, (both, each)
    with zipfile.ZipFile(kinds["datapackage"]) as z:
        assert any(n.endswith("campaign_map.kmz") for n in z.namelist())
    assert kinds["datapackage"] == out / "campaign_holes_datapackage.zip"
    assert kinds["gpx"] == out / "campaign_holes.gpx"
    geo = json.loads(kinds["geojson"].read_text())
    assert len(geo["features"]) == len(campaign.campaign)
    doc = json.loads(campaign.summary_path.read_text())
    holes = doc["campaign"]["holes"]
    assert [h["id"] for h in holes] == [h.id for h in campaign.campaign]
    for h in holes:
        assert h["flights"] and {f["flight"] for f in h["flights"]} <= {"sortie", "second"}
    assert doc["campaign"]["holes_seen_by_several_flights"] >= 1
    for name in ("sortie", "second"):
        assert (out / name / f"{name}_reprocess.mcap").is_file()
        assert (out / name / f"{name}_report.html").is_file()
    page = kinds["report"].read_text()
    assert "sortie" in page and "second" in page
    assert page.count(">start</text>") >= 2  # each flight's track drawn on its own


def test_a_cut_off_log_in_the_set_is_reported_the_others_processed(
    flight: Flown, flight_b: Flown, tmp_path: Path
) -> None:
    files_b = flight_b[0]
    cut = tmp_path / "cut.mcap"
    data = files_b[-1].read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    res = run_campaign([*flight[0], cut], tmp_path / "out", opts())
    by_name = {f.name: f for f in res.flights}
    assert by_name["cut"].truncated and "cut.mcap" in by_name["cut"].truncated[0]
    assert by_name["sortie"].frames_read == 40 and not by_name["sortie"].truncated
    with pytest.raises(InputError, match="no such file"):
        run_campaign([*flight[0], tmp_path / "gone.mcap"], tmp_path / "out2", opts())
    assert not (tmp_path / "out2").exists()


def test_cli(flight: Flown, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "c"
    argv = ["campaign", *map(str, flight[0]), "--out", str(out), "--workers", "0"]
    assert cli.main([*argv, "-f", "gpx"]) == 0
    text = capsys.readouterr().out
    assert "campaign:" in text and (out / "summary.json").is_file()
    assert cli.main(argv) == 0  # again: every partition from the cache
    assert "0 computed" in capsys.readouterr().out


def _station(folder: Path, holes: Sequence[Hole], mark: str) -> None:
    """A ground station folder: ``holes`` (as the vehicle's STATUSTEXTs told them) and
    ``mark`` on every one."""
    state = StationState.open(folder)
    for h in holes:
        p = h.p_hole if math.isfinite(h.p_hole) else 0.5
        assert state.on_statustext(hole_text(h.id, p, h.lat_deg, h.lon_deg)) is not None
        state.mark(h.id, mark)
    state.flush()


@pytest.mark.slow
def test_each_flights_station_marks_reach_the_campaign_through_that_flights_ids(
    flight: Flown, flight_b: Flown, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Both vehicles number their holes from 1: station A's mark of hole N must reach the
    campaign hole flight A calls N, never flight B's hole N elsewhere (only a hole N of
    both flights at the same place, within 1 m, takes both marks)."""
    a, b = flight[1].holes, flight_b[1].holes
    # A third station showed a hole N 20 m from each of flight B's holes N, confirmed:
    # another flight's hole N elsewhere, whose mark must reach neither flight.
    decoys = [dataclasses.replace(h, lat_deg=h.lat_deg + 20.0 / 111_132.0) for h in b]
    _station(tmp_path / "station_a", a, "confirmed")
    _station(tmp_path / "station_b", b, "rejected")
    _station(tmp_path / "station_c", decoys, "confirmed")
    out = tmp_path / "c"
    argv = ["campaign", *map(str, [*flight[0], *flight_b[0]]), "--out", str(out)]
    argv += ["--workers", "0", "--station", str(tmp_path / "station_a")]
    argv += ["--station", str(tmp_path / "station_b")]
    assert cli.main([*argv, "--station", str(tmp_path / "station_c")]) == 0
    capsys.readouterr()
    doc = json.loads((out / "summary.json").read_text())
    at = {
        "sortie": {h.id: (h.lat_deg, h.lon_deg) for h in a},
        "second": {h.id: (h.lat_deg, h.lon_deg) for h in b},
    }
    shown = [  # each station's holes: the mark, and where it showed them
        ("confirmed", at["sortie"]),
        ("rejected", at["second"]),
        ("confirmed", {h.id: (h.lat_deg, h.lon_deg) for h in decoys}),
    ]
    elsewhere = 0
    for h in doc["campaign"]["holes"]:
        marks = []
        for f in h["flights"]:
            own = at[f["flight"]].get(f["hole_id"])
            here = [
                m
                for m, holes in shown
                if own is not None
                and f["hole_id"] in holes
                and dist_m(holes[f["hole_id"]], own) <= 1.0
            ]
            elsewhere += sum(
                own is not None and f["hole_id"] in holes and dist_m(holes[f["hole_id"]], own) > 1
                for _, holes in shown
            )
            expected = "confirmed" if "confirmed" in here else ("rejected" if here else None)
            assert f["mark"] == expected, (h["id"], f)
            marks.append(expected)
        # one hole marked in both flights: the most affirmative mark (recall first)
        top = "confirmed" if "confirmed" in marks else ("rejected" if "rejected" in marks else None)
        assert h["mark"] == top, h
        if top is not None:
            assert h["tier"] == top
    assert elsewhere >= 1  # a mark of the same id at another place was not taken
    features = json.loads((out / "campaign_holes.geojson").read_text())["features"]
    tiers = {f["properties"]["hole_id"]: f["properties"]["tier"] for f in features}
    for h in doc["campaign"]["holes"]:
        if h["id"] in tiers:
            assert tiers[h["id"]] == h["tier"]
