"""Map tiles: self-describing PNG/JPEG, sent after the cards under their budget, read back
from real MAVLink bytes."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

import cv2
import numpy as np
import pytest
from test_holecards import HOLE, Wire, jpeg

from holescan.errors import InputError
from holescan.link import parser
from holescan.missions import (
    TYPE_COVERAGE,
    TYPE_ORTHO,
    CardAssembler,
    CardSender,
    TileFacts,
    card_facts,
    coverage_from_levels,
    coverage_levels,
    encode_coverage_tile,
    encode_ortho_tile,
    is_map_tile,
    make_card,
    read_card,
    read_tile,
    tile_facts_of,
)

N = 64


def facts(layer: str = "cov", tx: int = -2, ty: int = 3, v: int = 5) -> TileFacts:
    return TileFacts(77, layer, tx, ty, N, 0.1, 43.6532, -79.3832, v)  # type: ignore[arg-type]


def coverage() -> np.ndarray:
    c = np.zeros((N, N))
    c[10:40, 5:60] = 0.7
    c[40:50] = 1.0
    c[50:52, :3] = 0.004  # seen, barely: must stay "seen"
    return c


def ortho() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(1)
    rgb = cv2.GaussianBlur((rng.random((N, N, 3)) * 200 + 30).astype(np.uint8), (5, 5), 1.5)
    return rgb, coverage() > 0


def test_tiles_round_trip_and_open_in_any_viewer() -> None:
    cov_png = encode_coverage_tile(coverage(), facts())
    got = read_tile(cov_png)
    assert got is not None and got[0] == facts()
    assert np.array_equal(got[1], coverage_levels(coverage()))
    back = coverage_from_levels(got[1])
    assert ((back > 0) == (coverage() > 0)).all()  # seen stays seen, unseen stays unseen
    assert np.abs(back - coverage()).max() <= 1 / 15 + 1e-9
    # an ordinary decoder opens it (the facts ride in a tEXt chunk)
    img = cv2.imdecode(np.frombuffer(cov_png, np.uint8), cv2.IMREAD_UNCHANGED)
    assert img.shape == (N, N)
    rgb, seen = ortho()
    jpg = encode_ortho_tile(rgb, seen, facts("ortho"))
    got = read_tile(jpg)
    assert got is not None and got[0] == facts("ortho") and got[1].shape == (N, N, 3)
    err = np.abs(got[1].astype(int) - rgb.astype(int))[seen].mean()
    assert err < 20, err  # lossy, but the picture
    assert len(jpg) <= 1200
    assert is_map_tile(jpg) and is_map_tile(cov_png)


def test_cards_and_garbage_are_not_tiles() -> None:
    card = make_card(jpeg(), card_facts(HOLE, "why", 1))
    assert not is_map_tile(card) and read_tile(card) is None
    assert read_tile(b"\x89PNG\r\n\x1a\n" + b"\x00" * 40) is None
    assert read_tile(b"garbage") is None
    # facts that lie about the size or layer are refused
    png = encode_coverage_tile(coverage(), facts())
    lie = png.replace(b'"n":64', b'"n":32')
    assert read_tile(lie) is None
    assert tile_facts_of({"map": 1, "layer": "dsm", "tx": 0}) is None
    assert tile_facts_of({**facts().to_json(), "lat0": 123.0}) is None
    with pytest.raises(InputError):
        encode_coverage_tile(np.zeros((8, 8)), facts())


class Tiles:
    """A tile source that counts what it was asked for."""

    def __init__(self, tiles: list[tuple[int, bytes]]) -> None:
        self.q = deque(tiles)
        self.all = list(tiles)
        self.resent = 0

    def next_tile(self) -> tuple[int, bytes] | None:
        return self.q.popleft() if self.q else None

    def resend_all(self, held: Callable[[bytes], bool] | None = None) -> None:
        self.resent += 1
        self.q = deque(self.all)


def test_cards_go_first_tiles_share_the_budget_and_arrive_whole() -> None:
    now = [0.0]
    rgb, seen = ortho()
    tiles = []
    for i in range(6):
        tiles.append((TYPE_COVERAGE, encode_coverage_tile(coverage(), facts(tx=i))))
        tiles.append((TYPE_ORTHO, encode_ortho_tile(rgb, seen, facts("ortho", tx=i))))
    src = Tiles(tiles)
    sender = CardSender(bytes_per_s=1000.0, clock=lambda: now[0], repeat_s=None, tiles=src)
    cards = [make_card(jpeg(i), card_facts(HOLE, "x" * i, 1)) for i in range(2)]
    wire = Wire()
    p, asm = parser(), CardAssembler()
    order: list[str] = []
    sent_at: list[tuple[float, int]] = []
    done_before_put = 0
    for step in range(600):  # 60 s
        if step == 50:  # a hole is announced while tiles are flowing
            done_before_put = len(order)
            for i, c in enumerate(cards):
                sender.put(i, c)
        n0 = len(wire.bytes)
        sender.pump(wire.send)
        for b in wire.bytes[n0:]:
            sent_at.append((now[0], len(b)))
            for msg in p.parse_buffer(b) or []:
                pic = asm.add(msg)
                if pic is None:
                    continue
                order.append("tile" if is_map_tile(pic) else "card")
                assert read_tile(pic) is not None if is_map_tile(pic) else pic in cards
        now[0] += 0.1
    assert order.count("card") == 2 and order.count("tile") == 12 and asm.dropped == 0
    # the cards were put while a tile was under way: at most that one tile went before them
    first_card = order.index("card")
    assert done_before_put >= 1
    assert first_card - done_before_put <= 1, order
    assert order[first_card : first_card + 2] == ["card", "card"]
    assert sender.cards_sent == 2 and sender.tiles_sent == 12 and sender.pending == 0
    # the tiles' bytes are counted apart from the cards', the budget covers both
    on_wire = sum(n for _, n in sent_at)
    assert on_wire <= sender.bytes_sent + sender.tile_bytes_sent
    for t0 in np.arange(0.0, 50.0, 1.0):
        in_5s = sum(n for t, n in sent_at if t0 <= t < t0 + 5.0)
        assert in_5s <= 1000.0 * 5.0 + sender.burst_bytes
    # a ground station's "send everything" request reaches the tile source too
    sender.resend_all()
    assert src.resent == 1


def test_handshake_type_says_png_or_jpeg() -> None:
    now = [0.0]
    png = encode_coverage_tile(coverage(), facts())
    src = Tiles([(TYPE_COVERAGE, png)])
    sender = CardSender(bytes_per_s=10_000.0, clock=lambda: now[0], repeat_s=None, tiles=src)
    wire = Wire()
    for _ in range(5):
        sender.pump(wire.send)
        now[0] += 0.1
    p = parser()
    msgs = [m for b in wire.bytes for m in p.parse_buffer(b) or []]
    hs = [m for m in msgs if m.get_type() == "DATA_TRANSMISSION_HANDSHAKE"]
    assert [m.type for m in hs] == [TYPE_COVERAGE] and hs[0].size == len(png)
    assert read_card(png) is None  # never mistaken for a card
