"""The flight log records each hole's tier and the gate's thresholds; ``holescan holes``
uses them (logs from before get the default gate, and say so)."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest

from holescan.detect import CameraIntrinsics
from holescan.flightlog import FlightLogWriter, LoggedHoles, read_flight_log
from holescan.geotag import AnnounceGate, Hole
from holescan.ground import export_flight_holes, read_flight_holes

CAM = CameraIntrinsics.xtion()
T0_UNIX_NS = 1_750_000_000_000_000_000
# Not the default: a hole at p_hole 0.6 is announced, one at 0.2 is a candidate.
GATE = AnnounceGate(min_p_hole=0.5, min_sightings=3, min_span_s=0.5, review_min_p_hole=0.3)


def hole(hid: int, p_hole: float) -> Hole:
    span_ns = 2_000_000_000
    return Hole(
        hid, 43.7123 + hid * 1e-5, 10.4012, 30.0, 0.8, 0.7, 6, 0, span_ns, None, (40, 30, 20, 16),
        0.7, 0.5, p_hole=p_hole, views=3,
    )  # fmt: skip


HOLES = [hole(1, 0.95), hole(2, 0.6), hole(3, 0.2)]


def write_log(prefix: Path, gate: AnnounceGate | None) -> Path:
    with FlightLogWriter(prefix, CAM) as w:
        tiers = None if gate is None else {h.id: gate.tier(h) for h in HOLES}
        assert w.write_holes(HOLES, T0_UNIX_NS, tiers, gate)
    (path,) = w.paths
    return path


def exported_tiers(log: Path, out: Path) -> dict[int, str]:
    report = export_flight_holes(log, ["geojson"], out=out)
    doc = json.loads(out.read_text())
    assert [f for _, f in report.files] == [out]
    return {f["properties"]["hole_id"]: f["properties"]["tier"] for f in doc["features"]}


def test_a_flight_with_its_own_gate_reads_back_with_it(tmp_path: Path) -> None:
    log = write_log(tmp_path / "flight", GATE)
    (rec,) = read_flight_log(log, kinds={LoggedHoles})
    assert isinstance(rec, LoggedHoles)
    assert rec.announce_gate() == GATE
    assert rec.tiers() == {1: "announced", 2: "announced", 3: "candidate"}
    assert rec.as_holes() == tuple(HOLES)  # the tier is not a Hole field
    assert [h["p_hole"] for h in rec.holes] == [0.95, 0.6, 0.2]
    flight = read_flight_holes(log, thumbnails=False)
    assert flight.gate == GATE and flight.gate_recorded
    assert flight.tiers == {1: "announced", 2: "announced", 3: "candidate"}
    # The default gate would make hole 2 a review item and hole 3 one too.
    assert {h.id: AnnounceGate().tier(h) for h in HOLES} == {
        1: "announced",
        2: "review",
        3: "review",
    }
    out = tmp_path / "holes.geojson"
    assert exported_tiers(log, out) == {1: "announced", 2: "announced"}
    report = export_flight_holes(log, ["geojson"], out=tmp_path / "again.geojson")
    assert "tiers: the flight's: announced p_hole >= 0.5, >= 3 sightings" in report.lines()[1]


def test_a_log_from_before_recorded_tiers_gets_the_default_gate(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    log = write_log(tmp_path / "old", None)
    (rec,) = read_flight_log(log, kinds={LoggedHoles})
    assert isinstance(rec, LoggedHoles)
    assert rec.announce_gate() is None and rec.tiers() is None
    with caplog.at_level(logging.INFO):
        flight = read_flight_holes(log, thumbnails=False)
    assert "predates recorded tiers" in caplog.text
    assert flight.gate == AnnounceGate() and not flight.gate_recorded
    assert flight.tiers == {1: "announced", 2: "review", 3: "review"}
    out = tmp_path / "holes.geojson"
    assert exported_tiers(log, out) == {1: "announced", 2: "review", 3: "review"}
