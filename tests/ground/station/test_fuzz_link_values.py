"""Fuzzing of what arrives over MAVLink, into the station's state and files and into the
vehicle's hole server: NaN, Infinity, huge and negative numbers, control characters,
wrong types, cut payloads.

Property: nothing invalid is kept (every kept number finite and in range, every kept text
XML-safe), every file parses strictly (``json`` refusing NaN, ``xml.etree``), nothing
raises out of the intake, the process goes on.
"""

from __future__ import annotations

import json
import math
import os
import struct
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_station import hole, picture

from holescan.ground import StationState
from holescan.ground.station.cot import hole_cot
from holescan.ground.station.files import write_station_files
from holescan.ground.station.mapstore import MapStore
from holescan.link import HOLE_ID_MAX, mavlink
from holescan.missions import TYPE_INVENTORY, HoleMissionServer, card_facts, read_card

FUZZ = settings(
    max_examples=int(os.environ.get("HOLESCAN_FUZZ_EXAMPLES", "60")),
    deadline=5000,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
    derandomize="HOLESCAN_FUZZ_EXAMPLES" not in os.environ,
)
JPEG = picture(3)
NASTY_FLOATS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([1e308, -1e308, 2**63, -(2**63), 1e-320, -0.0]),
)
NASTY = st.one_of(
    NASTY_FLOATS,
    st.integers(min_value=-(2**70), max_value=2**70),
    st.text(alphabet=st.characters(codec="utf-8"), max_size=30),
    st.none(),
    st.booleans(),
    st.lists(st.integers(), max_size=2),
)
KEYS = [
    "id",
    "rev",
    "lat",
    "lon",
    "alt",
    "sigma",
    "score",
    "p",
    "tier",
    "n",
    "major",
    "minor",
    "why",
]


TILE_KEYS = ["map", "layer", "tx", "ty", "n", "cell", "lat0", "lon0", "v"]


def strict_json(text: str) -> Any:
    def refuse(token: str) -> Any:
        raise ValueError(f"{token} in strict JSON")

    return json.loads(text, parse_constant=refuse)


def assert_kept_valid(state: StationState, folder: Path) -> None:
    _, holes, track = state.snapshot()
    for h in holes:
        assert 0 <= h.id <= HOLE_ID_MAX
        assert (
            -90 <= h.lat_deg <= 90
            and -180 <= h.lon_deg <= 180
            and (h.score is None or 0 <= h.score <= 1)
        )
        for v in (h.alt_m, h.sigma_h_m, h.major_m, h.minor_m, h.p_hole):
            assert v is None or math.isfinite(v)
        assert ET.fromstring(f"<w>{h.why}</w>") is not None
        ET.fromstring(hole_cot(h))
    for p in track:
        assert all(math.isfinite(v) for v in (p.lat_deg, p.lon_deg, p.rel_alt_m, p.yaw))
    state.flush()
    if state.path.exists():  # written once anything was kept
        strict_json(state.path.read_text())
    write_station_files(folder, holes)
    strict_json((folder / "holes.geojson").read_text())
    ET.parse(folder / "holes.kml")
    ET.parse(folder / "holes.gpx")


@FUZZ
@given(
    over=st.dictionaries(st.sampled_from(KEYS), NASTY, max_size=5),
    drop=st.lists(st.sampled_from(KEYS), max_size=3),
    cut=st.integers(min_value=0, max_value=400),
)
def test_fuzz_card_facts_into_the_station(over: dict[str, Any], drop: list[str], cut: int) -> None:
    facts = card_facts(hole(3), "dark opening", 1)
    facts.update(over)
    for k in drop:
        facts.pop(k, None)
    text = json.dumps(facts, default=str).encode()  # NaN/Infinity as a forger writes them
    card = JPEG[:2] + b"\xff\xfe" + struct.pack(">H", len(text) + 2) + text + JPEG[2:]
    if cut:
        card = card[: max(4, len(card) - cut)]  # a payload cut short
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        state = StationState.open(folder)
        parsed = read_card(card)
        if parsed is not None:
            state.on_card(parsed, card)
        assert_kept_valid(state, folder)
        StationState.open(folder)  # and it reads back


@FUZZ
@given(
    word=st.sampled_from(["HOLE", "REVIEW", "HOLE  ", "hole"]),
    fields=st.lists(
        st.one_of(NASTY_FLOATS.map(str), st.integers().map(str), st.text(max_size=12)),
        min_size=0,
        max_size=5,
    ),
    yaw=NASTY_FLOATS,
    lat=NASTY_FLOATS,
)
def test_fuzz_statustext_and_track_into_the_station(
    word: str, fields: list[str], yaw: float, lat: float
) -> None:
    from holescan.ground.station.records import TrackPoint

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        state = StationState.open(folder)
        state.on_statustext(" ".join([word, *fields])[:50])
        state.on_position(TrackPoint(10**18, lat, -79.38, 3.0, yaw))
        state.on_position(TrackPoint(2 * 10**18, 43.6, -79.38, 3.0, yaw))
        assert_kept_valid(state, folder)


@FUZZ
@given(facts=st.dictionaries(st.sampled_from(TILE_KEYS), NASTY, max_size=4))
def test_fuzz_map_tile_facts_into_the_store(facts: dict[str, Any]) -> None:
    import numpy as np

    from holescan.missions import TileFacts, encode_ortho_tile, make_card

    good = TileFacts(5, "ortho", 0, 0, 8, 0.1, 43.6532, -79.3832, 1)
    tile = encode_ortho_tile(np.zeros((8, 8, 3), np.uint8), np.ones((8, 8), bool), good)
    body = tile[6 + struct.unpack(">H", tile[4:6])[0] - 2 :]
    forged = make_card(b"\xff\xd8" + body, {**good.to_json(), **_jsonable(facts)})
    with tempfile.TemporaryDirectory() as tmp:
        store = MapStore.open(Path(tmp) / "map")
        store.put(forged)
        from holescan.ground.station.maplayers import map_document

        doc = map_document(store, None)
        assert len(doc["tiles"]) <= 2  # type: ignore[arg-type]
        strict_json(json.dumps(doc))


def _jsonable(d: dict[str, Any]) -> dict[str, Any]:
    """Facts make_card can write (it is strict): NaN/Infinity as huge values instead."""
    return {
        k: (1e308 if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()
    }


@FUZZ
@given(
    chunks=st.lists(st.binary(max_size=253), max_size=6),
    size=st.integers(min_value=0, max_value=2**32 - 1),
    packets=st.integers(min_value=0, max_value=255),
)
def test_fuzz_the_vehicles_hole_server_takes_any_inventory(
    chunks: list[bytes], size: int, packets: int
) -> None:
    """The hole server (vehicle side) fed an inventory handshake of any size and any
    packets: it answers nothing wrong and goes on (its next tick works)."""
    sent: list[Any] = []
    server = HoleMissionServer(None, 1, sender=sent.append)
    mav = mavlink.MAVLink(None, srcSystem=254, srcComponent=190)
    msgs = [mavlink.MAVLink_data_transmission_handshake_message(
        TYPE_INVENTORY, size, 0, 0, packets, 253, 0)]  # fmt: skip
    msgs += [mavlink.MAVLink_encapsulated_data_message(i, c.ljust(253, b"\0"))
             for i, c in enumerate(chunks)]  # fmt: skip
    msgs.append(mavlink.MAVLink_data_transmission_handshake_message(0, 0, 0, 0, 0, 0, 0))
    for m in msgs:
        m.pack(mav)  # as received: source system/component set
        decoded = mav.decode(bytearray(m.get_msgbuf()))
        server.on_message(decoded)
    server.tick()
