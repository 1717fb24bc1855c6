"""The station's state file: round trips, an older station's folder, mission matching."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from holescan.errors import InputError
from holescan.geotag import Hole, LocalFrame
from holescan.ground import GroundHole, StationFileError, StationState, TrackPoint

HOME = (43.6532, -79.3832)
T_NS = 1_700_000_000_250_000_000


def at(east_m: float, north_m: float) -> tuple[float, float]:
    lat, lon = LocalFrame(*HOME).to_geodetic(east_m, north_m)
    return float(lat), float(lon)


def test_round_trip_keeps_every_fact_and_the_track(tmp_path: Path) -> None:
    state = StationState.open(tmp_path / "st")
    state.clock = lambda: T_NS
    assert state.on_statustext("HOLE 3 0.88 43.6533100 -79.3831200") is not None
    state.on_position(TrackPoint(T_NS, *HOME, 3.0, 0.5))
    state.mark(3, "confirmed")
    doc = json.loads(state.path.read_text())
    assert doc["format"] == "holescan-ground-2"
    (h,) = doc["holes"]
    assert (h["lat_deg"], h["lon_deg"], h["t_first_unix_ns"]) == (43.65331, -79.38312, T_NS)
    assert "lat" not in h and "first_unix" not in h
    again = StationState.open(tmp_path / "st")
    assert again.holes == state.holes and again.track == state.track
    assert isinstance(again.track[0].t_unix_ns, int)


def test_an_older_station_folder_is_read(tmp_path: Path) -> None:
    """``holescan-ground-1``: lat/lon/alt/sigma_m and times in float seconds."""
    folder = tmp_path / "old"
    folder.mkdir()
    old_hole = json.loads(
        '{"id": 7, "lat": 43.65331, "lon": -79.38312, "score": 0.8, "alt": 121.5, '
        '"sigma_m": 0.4, "sightings": 5, "major_m": 1.1, "minor_m": 0.7, "why": "dark", '
        '"card_rev": 2, "has_picture": true, "mark": "visited", "seq": 1, '
        '"first_unix": 1700000000.25, "updated_unix": 1700000002.5}'
    )
    doc = {
        "format": "holescan-ground-1",
        "version": 12,
        "holes": [old_hole],
        "track": [[1_700_000_000.25, 43.6532, -79.3832, 3.0, 0.5]],
    }
    (folder / "station.json").write_text(json.dumps(doc))
    state = StationState.open(folder)
    assert state.holes == {
        7: GroundHole(
            7,
            43.65331,
            -79.38312,
            0.8,
            alt_m=121.5,
            sigma_h_m=0.4,
            sightings=5,
            major_m=1.1,
            minor_m=0.7,
            why="dark",
            card_rev=2,
            has_picture=True,
            mark="visited",
            seq=1,
            t_first_unix_ns=1_700_000_000_250_000_000,
            t_updated_unix_ns=1_700_000_002_500_000_000,
        )
    }
    assert state.track == [TrackPoint(1_700_000_000_250_000_000, 43.6532, -79.3832, 3.0, 0.5)]
    assert state.version == 12
    state.mark(7, "confirmed")  # the next change writes the current format
    assert json.loads(state.path.read_text())["format"] == "holescan-ground-2"
    assert StationState.open(folder).holes[7].t_first_unix_ns == 1_700_000_000_250_000_000


def test_a_foreign_state_file_is_named(tmp_path: Path) -> None:
    (tmp_path / "station.json").write_text('{"holes": [{"lat": 1}]}')
    with pytest.raises(StationFileError, match="not a holescan ground station file"):
        StationState.open(tmp_path)
    assert issubclass(StationFileError, InputError)  # the CLI's exit code 2


def test_mission_items_pair_with_holes_nearest_first(tmp_path: Path) -> None:
    state = StationState.open(tmp_path)
    for hid, (e, n) in {1: (0.0, 0.0), 2: (1.0, 0.0), 3: (20.0, 0.0)}.items():
        lat, lon = at(e, n)
        assert state.on_statustext(f"HOLE {hid} 0.80 {lat:.7f} {lon:.7f}") is not None
    # item 1 lies 0.3 m from hole 1 (0.7 m from hole 2), item 2 0.1 m from hole 1: the nearest
    # pair goes first, so item 2 is hole 1 and item 1 hole 2 (items taken in order would give
    # hole 1 to item 1)
    items = [(1, *at(0.3, 0.0)), (2, *at(0.1, 0.0)), (3, *at(50.0, 0.0))]
    assert state.on_mission(items) == 1  # item 3 matches no hole
    assert {h.id: h.seq for h in state.holes.values()} == {1: 2, 2: 1, 3: None}


def test_the_vehicles_tier_from_statustext_and_card_and_in_the_files(tmp_path: Path) -> None:
    from holescan.ground.station.files import hole_waypoint
    from holescan.missions import card_facts, make_card

    state = StationState.open(tmp_path / "st")
    state.clock = lambda: T_NS
    h = state.on_statustext("REVIEW 4 0.30 43.6533100 -79.3831200")
    assert h is not None and h.vehicle_tier == "review"
    jpeg = b"\xff\xd8\xff\xd9"
    hole = Hole(4, 43.65331, -79.38312, 120.0, 0.4, 0.3, 3, 0, 10**9, 1, (0, 0, 9, 9), 0.9, 0.5,
                p_hole=0.42)  # fmt: skip
    facts = card_facts(hole, "why", 1, "review")
    got = state.on_card(facts, make_card(jpeg, facts))
    assert got is not None and (got.vehicle_tier, got.p_hole) == ("review", 0.42)
    props = hole_waypoint(got).properties
    assert (props["tier"], props["p_hole"], props["hole_id"]) == ("review", 0.42, 4)
    # announced later (the vehicle saw it again): the card says so
    facts = card_facts(hole, "why", 2, "announced")
    assert state.on_card(facts, make_card(jpeg, facts)).vehicle_tier == "announced"  # type: ignore[union-attr]
    state.mark(4, "confirmed")
    assert state.holes[4].tier == "confirmed"
    again = StationState.open(tmp_path / "st")
    assert again.holes[4].vehicle_tier == "announced" and again.holes[4].p_hole == 0.42


def test_each_statustext_number_is_kept_as_what_it_is(tmp_path: Path) -> None:
    """``p0.68``: the hole-level p_hole; an old vehicle's bare ``0.99``: the best frame's
    score. One never becomes the other, on the state or in the files."""
    from holescan.ground.station.files import hole_summary, hole_waypoint

    state = StationState.open(tmp_path / "st")
    state.clock = lambda: T_NS
    new = state.on_statustext("REVIEW 7 p0.68 43.6533100 -79.3831200")
    assert new is not None and (new.vehicle_tier, new.p_hole, new.score) == ("review", 0.68, None)
    props = hole_waypoint(new).properties
    assert (props["p_hole"], props["score"]) == (0.68, None)
    assert "score" not in hole_summary(new)
    old = state.on_statustext("HOLE 8 0.99 43.6533400 -79.3831500")
    assert old is not None
    assert (old.vehicle_tier, old.p_hole, old.score) == ("announced", None, 0.99)
    assert "best frame's score 0.99" in hole_summary(old)
    # the next line of hole 7 changes p_hole only; what the card told of the score stays
    state.holes[7].vehicles[0].score = 0.42  # the hole shows its vehicles' facts
    again = state.on_statustext("REVIEW 7 p0.71 43.6533100 -79.3831200")
    assert again is not None and (again.p_hole, again.score) == (0.71, 0.42)
    back = StationState.open(tmp_path / "st").holes
    assert (back[7].p_hole, back[8].score, back[8].p_hole) == (0.71, 0.99, None)


def test_a_hole_told_again_goes_down_facts_only_and_the_station_keeps_its_picture(
    tmp_path: Path,
) -> None:
    """The vehicle's hole server sends the picture once; a smaller sigma later goes as a
    facts-only card (a few hundred bytes); repeats carry the picture again; the station
    shows the newest facts beside the picture it holds."""
    from dataclasses import replace

    import cv2
    import numpy as np

    from holescan.link import mavlink as dialect
    from holescan.link import parser
    from holescan.missions import (
        NO_PICTURE,
        CardAssembler,
        HoleMissionServer,
        card_picture,
        read_card,
    )

    img = (np.random.default_rng(3).random((72, 96, 3)) * 255).astype(np.uint8)
    pic = cv2.imencode(".jpg", cv2.GaussianBlur(img, (5, 5), 2))[1].tobytes()
    now = [0.0]
    wire: list[bytes] = []
    mav = dialect.MAVLink(None, srcSystem=1, srcComponent=191)

    class Capture:
        def __getattr__(self, name: str) -> object:
            encode = getattr(mav, name.removesuffix("_send") + "_encode")
            return lambda *a: wire.append(encode(*a).pack(mav))

    server = HoleMissionServer("udpout:127.0.0.1:9", 1)  # never started: cards pumped here
    server.cards.clock = lambda: now[0]
    p, asm = parser(), CardAssembler()

    def down(seconds: float) -> list[bytes]:
        n0 = len(wire)
        for _ in range(int(seconds * 10)):
            server.cards.pump(lambda fn: fn(Capture()))
            now[0] += 0.1
        got = [asm.add(m) for b in wire[n0:] for m in (p.parse_buffer(b) or [])]
        return [c for c in got if c is not None]

    state = StationState.open(tmp_path / "st")
    state.clock = lambda: T_NS
    h = Hole(5, 43.65331, -79.38312, 120.0, 1.2, 0.8, 4, 0, 10**9, 1, (0, 0, 9, 9), 0.9, 0.5,
             p_hole=0.95)  # fmt: skip
    full_size = server.send_card(h, pic, "why", "announced")
    (first,) = down(10.0)
    assert card_picture(first) == pic
    assert state.on_card(read_card(first) or {}, first) is not None
    later = replace(h, sigma_h_m=1.155, sightings=9)
    size = server.send_card(later, pic, "why", "announced")  # same picture: facts only
    assert size < 700 < full_size
    (second,) = down(10.0)
    assert card_picture(second) == NO_PICTURE
    got = state.on_card(read_card(second) or {}, second)
    assert got is not None and got.has_picture
    assert (got.sigma_h_m, got.sightings, got.card_rev) == (1.16, 9, 2)
    kept = state.card_path(5).read_bytes()  # the picture held, with the newest facts
    assert card_picture(kept) == pic and read_card(kept) == read_card(second)
    assert StationState.open(tmp_path / "st").holes[5].sigma_h_m == 1.16
    # the repeat (60 s after the newest card) carries the picture with the newest facts
    (repeat,) = down(61.0)
    assert card_picture(repeat) == pic and read_card(repeat) == read_card(second)
    # a new best view goes whole
    pic2 = cv2.imencode(".jpg", img)[1].tobytes()
    assert server.send_card(replace(later, sightings=10), pic2, "why", "announced") > 700
