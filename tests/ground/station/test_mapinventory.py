"""After a link drop the station says which tiles it holds: only the others come again.

Real parts: the vehicle's HoleMissionServer and the station's VehicleLink over loopback
UDP through a relay that is cut, the station's MapStore on disk."""

from __future__ import annotations

import time
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from test_station import Relay, wait_for

from holescan.ground.station import StationState
from holescan.ground.station.link import VehicleLink
from holescan.ground.station.mapstore import MapStore
from holescan.missions import (
    TYPE_COVERAGE,
    HoleMissionServer,
    TileFacts,
    TileInventory,
    encode_coverage_tile,
    encode_inventory,
    held_by,
    read_inventory,
)
from tests._support import free_udp_port

N = 16


def tile(map_id: int, tx: int, v: int) -> bytes:
    cov = np.zeros((N, N))
    cov[: tx + 1, :] = 0.5
    return encode_coverage_tile(cov, TileFacts(map_id, "cov", tx, 0, N, 0.1, 43.65, -79.38, v))


class Outbox:
    """The live map's sending side as :class:`capture.LiveMap` does it: the newest bytes of
    each tile, sent once; ``resend_all(held)`` marks again those the station lacks."""

    def __init__(self, map_id: int, n: int) -> None:
        self.map_id = map_id
        self.data = {tx: tile(map_id, tx, 1) for tx in range(n)}
        self.sent = dict.fromkeys(range(n), False)
        self.sends: list[int] = []

    def change(self, tx: int, v: int) -> None:
        self.data[tx], self.sent[tx] = tile(self.map_id, tx, v), False

    def next_tile(self) -> tuple[int, bytes] | None:
        for tx, done in self.sent.items():
            if not done:
                self.sent[tx] = True
                self.sends.append(tx)
                return TYPE_COVERAGE, self.data[tx]
        return None

    def resend_all(self, held: Callable[[bytes], bool] | None = None) -> None:
        for tx, done in self.sent.items():
            if not (done and held is not None and held(self.data[tx])):
                self.sent[tx] = False


def test_inventory_bytes_round_trip_and_hostile_ones_refused() -> None:
    inv = TileInventory(
        7, {("cov", tx, -tx): tx + 1 for tx in range(300)} | {("ortho", 1, 2): 9, ("cov", 5, 0): 6}
    )
    data = encode_inventory(inv)
    assert len(data) < 9 * 302  # compressed
    back = read_inventory(data)
    assert back is not None and back.map_id == 7 and dict(back.have) == dict(inv.have)
    bomb = b"HSINV1" + zlib.compress(b"\0" * 10_000_000)
    for bad in (
        b"",
        b"HSINV1",
        b"HSINV1garbage",
        bomb,
        data[:-3],
        b"HSINV1" + zlib.compress(b"\0" * 4 + b"\x07" + b"\0" * 8),
    ):
        assert read_inventory(bad) is None
    held = held_by(back)
    assert held(tile(7, 5, 6)) and not held(tile(7, 5, 7)) and not held(tile(8, 5, 6))
    assert not held(b"\xff\xd8\xff\xd9")


@pytest.mark.timeout(120)
def test_link_up_resends_only_what_the_station_lacks(tmp_path: Path) -> None:
    ground = free_udp_port()
    relay = Relay(ground)
    state = StationState.open(tmp_path / "st")
    store = MapStore.open(tmp_path / "st" / "map")
    box = Outbox(map_id=42, n=12)
    try:
        with (
            VehicleLink(f"udpin:127.0.0.1:{ground}", state, map_store=store, silence_s=1.5) as link,
            HoleMissionServer(f"udpout:127.0.0.1:{relay.port}", 1, card_bytes_per_s=20_000) as srv,
        ):
            srv.set_tiles(box)
            wait_for(lambda: store.summary()["cov"] == 12, 30.0, "every tile at the station")
            time.sleep(1.0)  # the start-up request (empty store) may still be answered
            wait_for(lambda: all(box.sent.values()), 10.0, "the outbox sent")
            before = len(box.sends)
            requests = link.resync_requests
            # the radio drops; meanwhile two tiles change (the first sent into the void)
            relay.cut = True
            time.sleep(0.5)
            box.change(3, 2)
            wait_for(lambda: box.sent[3], 5.0, "tile 3 sent into the cut")
            box.change(7, 2)
            wait_for(lambda: not link.link_up or link.resync_requests > requests, 10.0, "silence")
            relay.cut = False
            wait_for(lambda: link.resync_requests > requests, 20.0, "the station's request")
            wait_for(
                lambda: (
                    all(store.get(f"v1-m42-cov-{tx}_0.png") is not None for tx in (3, 7))
                    and all(
                        store.get(f"v1-m42-cov-{tx}_0.png").facts.version == 2  # type: ignore[union-attr]
                        for tx in (3, 7)
                    )
                ),
                30.0,
                "the changed tiles",
            )
            time.sleep(1.0)
            again = box.sends[before:]
            # tile 3 (lost in the cut) and 7 (changed, due anyway); none of the ten it held
            assert sorted(set(again)) == [3, 7], again
            assert link.tiles_received >= 12 + 2
    finally:
        relay.close()
