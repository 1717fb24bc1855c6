"""Hole cards: JPEG + facts, paced under a byte budget, reassembled from real MAVLink bytes."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
import pytest

from holescan.errors import InputError
from holescan.geotag import Hole
from holescan.link import mavlink as mav_dialect
from holescan.link import parser
from holescan.missions import (
    CARD_PAYLOAD,
    CardAssembler,
    CardSender,
    card_facts,
    make_card,
    read_card,
)


def jpeg(seed: int = 0, size: tuple[int, int] = (72, 96)) -> bytes:
    rng = np.random.default_rng(seed)
    img = cv2.GaussianBlur((rng.random((*size, 3)) * 255).astype(np.uint8), (5, 5), 2)
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 60])
    assert ok
    return buf.tobytes()


HOLE = Hole(
    7, 43.6532123, -79.3832456, 121.5, 0.31, 0.876, 9, 10**9, 3 * 10**9, 4, (1, 2, 3, 4), 1.1, 0.7
)


def test_card_carries_facts_and_stays_a_jpeg() -> None:
    pic = jpeg()
    facts = card_facts(HOLE, "score 0.88: 1.10 x 0.70 m opening", 2)
    card = make_card(pic, facts)
    assert read_card(card) == facts
    assert facts["lat"] == 43.6532123 and facts["id"] == 7 and facts["rev"] == 2
    img = cv2.imdecode(np.frombuffer(card, np.uint8), cv2.IMREAD_COLOR)  # still opens
    assert img is not None and img.shape == (72, 96, 3)
    assert read_card(pic) is None
    with pytest.raises(InputError):
        make_card(b"not a jpeg", facts)


class Wire:
    """Encodes what the sender sends with the real dialect, as bytes on a link would be."""

    def __init__(self) -> None:
        self.mav = mav_dialect.MAVLink(None, srcSystem=1, srcComponent=191)
        self.bytes: list[bytes] = []

    def send(self, fn: Any) -> None:
        wire = self

        class Capture:
            def __getattr__(self, name: str) -> Any:
                encode = getattr(wire.mav, name.removesuffix("_send") + "_encode")
                return lambda *a: wire.bytes.append(encode(*a).pack(wire.mav))

        fn(Capture())


def test_budget_is_kept_and_cards_arrive_whole() -> None:
    now = [0.0]
    sender = CardSender(bytes_per_s=1000.0, clock=lambda: now[0], repeat_s=None)
    wire = Wire()
    cards = [make_card(jpeg(i), card_facts(HOLE, "x" * i, 1)) for i in range(3)]
    for i, c in enumerate(cards):
        sender.put(i, c)
    for _ in range(400):  # 40 s in 0.1 s steps
        sender.pump(wire.send)
        now[0] += 0.1
    total = sum(len(b) for b in wire.bytes)
    assert sender.cards_sent == 3 and sender.pending == 0
    # the budget counts whole frames: what went on the wire is within it
    assert total <= sender.bytes_sent
    first_send_window = sum(len(c) for c in cards) / CARD_PAYLOAD  # packets
    assert first_send_window > 10
    # rate: at most the budget (+ one burst) in any 5 s window
    sender2 = CardSender(bytes_per_s=1000.0, clock=lambda: now[0], repeat_s=None)
    wire2 = Wire()
    for i, c in enumerate(cards):
        sender2.put(i, c)
    sent_at = []
    for _ in range(200):
        n0 = len(wire2.bytes)
        sender2.pump(wire2.send)
        sent_at += [(now[0], len(b)) for b in wire2.bytes[n0:]]
        now[0] += 0.1
    t0 = sent_at[0][0]
    in_5s = sum(n for t, n in sent_at if t < t0 + 5.0)
    assert in_5s <= 1000.0 * 5.0 + sender2.burst_bytes
    # reassemble from the bytes with a real parser
    p = parser()
    asm = CardAssembler()
    got = []
    for b in wire.bytes:
        for msg in p.parse_buffer(b) or []:
            card = asm.add(msg)
            if card is not None:
                got.append(card)
    assert got == cards


def test_lost_packet_drops_the_card_and_a_request_resends_it() -> None:
    now = [0.0]
    sender = CardSender(bytes_per_s=5000.0, clock=lambda: now[0], repeat_s=None)
    wire = Wire()
    card = make_card(jpeg(1), card_facts(HOLE, "why", 1))
    sender.put(7, card)
    for _ in range(50):
        sender.pump(wire.send)
        now[0] += 0.1
    p, asm = parser(), CardAssembler()
    msgs = [m for b in wire.bytes for m in (p.parse_buffer(b) or [])]
    assert [asm.add(m) for m in msgs[:3] + msgs[4:]].count(None) == len(msgs) - 1  # one lost
    sender.resend_all()
    n0 = len(wire.bytes)
    for _ in range(50):
        sender.pump(wire.send)
        now[0] += 0.1
    out = [asm.add(m) for b in wire.bytes[n0:] for m in (p.parse_buffer(b) or [])]
    assert [c for c in out if c is not None] == [card]
    assert asm.dropped == 1


def test_newer_card_replaces_an_unsent_one_and_repeats_are_bounded() -> None:
    now = [0.0]
    sender = CardSender(bytes_per_s=100_000.0, clock=lambda: now[0], repeat_s=10.0, repeats=2)
    wire = Wire()
    sender.put(1, make_card(jpeg(1), {"id": 1, "rev": 1}))
    sender.put(1, make_card(jpeg(2), {"id": 1, "rev": 2}))
    assert sender.pending == 1
    for _ in range(600):  # 60 s
        sender.pump(wire.send)
        now[0] += 0.1
    assert sender.cards_sent == 3  # once + two repeats 10 s apart
    with pytest.raises(InputError):
        CardSender(bytes_per_s=1.0)


@pytest.mark.parametrize("tier", ["review", "rejected"])
def test_every_file_says_what_each_hole_is_and_only_announced_ones_are_waypoints(
    tmp_path: Any, tier: str
) -> None:
    import dataclasses
    import json as _json
    import xml.etree.ElementTree as ET

    from holescan.missions import read_gpx, write_hole_file

    strong = dataclasses.replace(HOLE, p_hole=0.97)
    weak = Hole(
        8,
        43.6533,
        -79.3833,
        121.0,
        0.5,
        0.21,
        4,
        10**9,
        2 * 10**9,
        3,
        (1, 2, 3, 4),
        0.3,
        0.2,
        p_hole=0.31,
    )
    holes, tiers = [strong, weak], {7: "announced", 8: tier}
    gj = write_hole_file(tmp_path / "h.geojson", holes, "geojson", tiers=tiers)
    feats = {
        f["properties"]["hole_id"]: f["properties"] for f in _json.loads(gj.read_text())["features"]
    }
    for hid, want_tier, p in ((7, "announced", 0.97), (8, tier, 0.31)):
        f = feats[hid]
        assert (f["tier"], f["p_hole"]) == (want_tier, p)
        assert {"sightings", "major_m", "minor_m", "sigma_h_m"} <= set(f)
    assert feats[8]["name"] == f"{tier} 8"
    for fmt in ("plan", "wpl"):  # a mission: announced (and confirmed) holes only
        path = write_hole_file(tmp_path / f"h.{fmt}", holes, fmt, tiers=tiers)  # type: ignore[arg-type]
        if fmt == "plan":
            items = _json.loads(path.read_text())["mission"]["items"]
            assert [it["holescan"]["properties"]["hole_id"] for it in items] == [7]
            assert items[0]["holescan"]["properties"]["tier"] == "announced"
        else:
            assert len(path.read_text().splitlines()) == 3  # header, home, hole 7
    gpx = read_gpx(write_hole_file(tmp_path / "h.gpx", holes, "gpx", tiers=tiers))
    descs = {w.name: w.description or "" for w in gpx}
    assert "(announced, rank 1): p_hole 0.97" in descs["hole 7"]
    assert f"({tier}, rank 2): p_hole 0.31" in descs[f"{tier} 8"]
    assert "within 0.81 m (95 %)" in descs[f"{tier} 8"]  # sigma 0.5 m
    assert "0.30 x 0.20 m" in descs[f"{tier} 8"]
    kml = write_hole_file(tmp_path / "h.kml", holes, "kml", tiers=tiers).read_text()
    root = ET.fromstring(kml)
    data = {
        d.get("name"): d.findtext("{http://www.opengis.net/kml/2.2}value")
        for d in root.iter("{http://www.opengis.net/kml/2.2}Data")
    }
    assert data["tier"] is not None and f"{tier} 8" in kml and "p_hole" in data
    with pytest.raises(InputError, match="tier"):
        write_hole_file(tmp_path / "x.gpx", holes, "gpx", tiers={8: "candidate"})


def test_announced_holes_cards_go_before_those_for_review() -> None:
    now = [0.0]
    sender = CardSender(bytes_per_s=1000.0, clock=lambda: now[0], repeat_s=None)
    wire = Wire()
    cards = {k: make_card(jpeg(k), {"id": k, "rev": 1}) for k in (1, 2, 3, 4)}
    sender.put(1, cards[1], priority=1)  # review, started first
    for _ in range(2):  # its handshake goes out: a card begun is never cut off
        sender.pump(wire.send)
        now[0] += 0.1
    assert wire.bytes
    sender.put(2, cards[2], priority=1)  # review
    sender.put(3, cards[3], priority=0)  # announced: before the waiting review card
    sender.put(4, cards[4], priority=0)
    p, asm, got = parser(), CardAssembler(), []
    for _ in range(400):
        sender.pump(wire.send)
        now[0] += 0.1
    for b in wire.bytes:
        for msg in p.parse_buffer(b) or []:
            if (card := asm.add(msg)) is not None:
                got.append(read_card(card)["id"])  # type: ignore[index]
    assert got == [1, 3, 4, 2]
    # a review hole that becomes announced jumps the queue too
    sender.put(5, make_card(jpeg(5), {"id": 5, "rev": 1}), priority=1)
    sender.put(6, make_card(jpeg(6), {"id": 6, "rev": 1}), priority=1)
    sender.put(6, make_card(jpeg(6), {"id": 6, "rev": 2}), priority=0)
    assert [item.key for item in sender._queue] == [6, 5]
