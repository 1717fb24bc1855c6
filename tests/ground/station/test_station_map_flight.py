"""A simulated flight's live map reaches the ground station and says what the sensor saw.

The one flight path (:func:`capture.fly` over :class:`sim.SimSortie`: the simulated
autopilot over MAVLink, the simulated Xtion, the daemon, the hole server) sends its map
tiles to a real :class:`ground.GroundStation` over loopback UDP. Checked:

* every tile the flight held at its end is in the station's folder, byte for byte, so the
  coverage there is what the flight's own map held;
* against truth the code under test did not produce: the simulator's exact view
  (:func:`sim.render_exact`, noise-free depth of its world) from the true poses of the
  frames the live map fused (its CPU budget passes frames over, more of them on a loaded
  machine: :attr:`capture.LiveMapStats.fused_t_mono_ns` says which it took) marks the
  cells the sensor saw; at 0.5 m cells the station's seen / not seen agrees with it;
* the live page draws the layers (headless Chromium); its screenshot goes to
  ``HOLESCAN_ARTEFACTS`` (else the test's folder).
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Collection
from pathlib import Path

import numpy as np
import pytest
from test_station import wait_for

from holescan.capture import SensorSetup, fly, parse_fly_config
from holescan.detect import CameraIntrinsics
from holescan.geotag import LocalFrame
from holescan.ground import GroundOptions, GroundStation
from holescan.ground.station.mapstore import tile_file_name
from holescan.missions import read_tile
from holescan.sim import SimSortie, camera_pose_in_world, render_exact, sortie_params
from tests._support import free_udp_port

COARSE_M = 0.5


def truth_seen(
    sortie: SimSortie,
    frame: LocalFrame,
    grid: tuple[float, float, int, int],
    fused_t_mono_ns: Collection[int],
) -> tuple[np.ndarray, int]:
    """Cells of ``COARSE_M`` the simulator's exact view reaches within the Xtion's range
    outside the flight's unread registration bands (the sensor reads nothing there), from the
    true pose of every rendered frame the live map fused (by capture time); and how many
    frames that is. grid: (west, north, nx, ny) in ``frame``."""
    world, anchor, ap = sortie.world, sortie.params.anchor, sortie.autopilot
    assert world is not None and ap is not None
    # the autopilot's boot time of each fused frame: the key of its true pose
    fused = {ap.boot_ns_at_mono(t) for t in fused_t_mono_ns}
    used = 0
    cam = CameraIntrinsics.xtion()
    v, u = np.mgrid[0 : cam.height : 4, 0 : cam.width : 4]
    rays = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones(u.shape)], -1)
    west, north, nx, ny = grid
    # the map's frame in the world's (ENU at the anchor): a shift (tangent planes metres apart)
    dx, dy, _ = anchor.to_world(frame.lat0_deg, frame.lon0_deg, anchor.alt_m)
    seen = np.zeros((ny, nx), bool)
    for src in sortie.sources:
        b = src.bands  # the flight's: one draw per flight
        read = (
            (u >= b.left) & (u < cam.width - b.right) & (v >= b.top) & (v < cam.height - b.bottom)
        )
        for pose, _ in src.truth.values():
            if pose.t_boot_ns not in fused:
                continue
            used += 1
            cp = camera_pose_in_world(pose, sortie.mount, anchor)
            z, _ = render_exact(world, cp, cam)
            z = z[::4, ::4]
            ok = read & (z > 0) & (z < 4.0)  # the Xtion reads to ~3.5-4 m
            hit = cp.position + (rays[ok] * z[ok, None]) @ cp.rotation.T
            col = np.floor((hit[:, 0] - dx - west) / COARSE_M).astype(int)
            row = np.floor((north - (hit[:, 1] - dy)) / COARSE_M).astype(int)
            inside = (col >= 0) & (col < nx) & (row >= 0) & (row < ny)
            seen[row[inside], col[inside]] = True
    return seen, used


@pytest.mark.slow
def test_flight_map_reaches_the_station_and_matches_the_simulators_view(tmp_path: Path) -> None:
    port = free_udp_port()
    station_dir = tmp_path / "station"
    opts = GroundOptions(
        mavlink=f"udpin:127.0.0.1:{port}", out=station_dir, http_port=0, cot_url=None
    )
    doc = {
        "sensor": "sim",
        "capture": {"startup_sync_s": 5.0},
        "sim": {"size_m": [4.0, 4.0], "world_seed": 15, "n_access_holes": 2, "fps": 10.0},
    }
    cfg = parse_fly_config(
        doc,
        {"log_dir": str(tmp_path / "logs"), "gcs": f"udpout:127.0.0.1:{port}", "duration_s": 40.0},
    )
    params, record = sortie_params(cfg.sim_table)
    cfg = dataclasses.replace(cfg, record={**cfg.record, **record})
    with GroundStation(opts) as station:
        with SimSortie(params, mount=cfg.flight.mount, mavlink=cfg.mavlink) as sortie:
            t0 = time.monotonic()
            report = fly(cfg, SensorSetup(sortie.source, sortie.camera, sortie.mavlink))
            took_s = time.monotonic() - t0  # the flight and the last pictures and tiles
        ms = report.map_stats
        # How many frames the map fuses is its CPU budget's call (fewer on a loaded machine;
        # tests/capture/test_livemap.py checks the budget): here every offered frame is
        # accounted for, and the truth below is made of the frames it did fuse.
        assert ms is not None and ms.fused >= 1, ms
        assert ms.offered == ms.fused + ms.unposed + ms.skipped_budget + ms.dropped, ms
        tiles = report.map_tiles
        assert len(tiles) >= 8  # coverage and orthophoto of >= 4 places
        store = station.map_store

        def all_there() -> bool:
            if len(store.vehicles()) != 1:  # kept under the one vehicle's system id
                return False
            (sysid,) = store.vehicles()
            for data in tiles.values():
                got = read_tile(data)
                assert got is not None
                if store.read(tile_file_name(got[0], sysid)) != data:
                    return False
            return True

        wait_for(all_there, 60.0, "every tile of the flight at the station")
        assert station.link is not None
        assert all(p.cards.dropped == 0 for p in station.link.peers.values())
        assert station.link.tiles_received == report.tiles_sent
        # the page draws them
        art = Path(os.environ.get("HOLESCAN_ARTEFACTS", tmp_path))
        art.mkdir(parents=True, exist_ok=True)
        if Path("/usr/bin/chromium").exists():
            from test_station_flight import Chromium

            assert station.web is not None
            browser = Chromium(station.web.url, tmp_path / "profile")
            try:
                n = len(tiles) // 2
                q = "document.querySelectorAll('g.maplayer[data-layer=\"%s\"] image').length"
                wait_for(lambda: browser.js(q % "cov") == n, 60.0, "coverage drawn")
                assert browser.js(q % "ortho") == n
                time.sleep(1.0)  # the images decode
                browser.screenshot(art / "live-map.png")
            finally:
                browser.close()
    print(
        f"live map: {ms.fused} of {ms.offered} frames fused, "
        f"{ms.cpu_ms / ms.offered:.2f} ms CPU per frame; {report.tiles_sent} tiles sent, "
        f"{report.tile_bytes} B; pictures {report.card_bytes} B; "
        f"over {took_s:.0f} s: {(report.tile_bytes + report.card_bytes) / took_s:.0f} B/s"
    )
    # one budget for pictures and tiles (the bucket's burst on top)
    assert report.tile_bytes + report.card_bytes <= 1000.0 * took_s + 600
    # the station's coverage after a restart, on coarse cells, against the ray caster's
    again = GroundStation(opts).map_store
    (map_id,) = {t.facts.map_id for t in again.tiles()}
    mosaic = again.coverage(map_id)
    assert mosaic is not None
    cov, sw = mosaic
    n, cell = sw.n, sw.cell_m
    k = round(COARSE_M / cell)
    west = sw.tx * n * cell
    north = (sw.ty * n + cov.shape[0]) * cell
    ny, nx = cov.shape[0] // k, cov.shape[1] // k
    ours = (cov[: ny * k, : nx * k] > 0).reshape(ny, k, nx, k).any(axis=(1, 3))
    truth, used = truth_seen(
        sortie, LocalFrame(sw.lat0_deg, sw.lon0_deg), (west, north, nx, ny), ms.fused_t_mono_ns
    )
    assert used == ms.fused, (used, ms)  # every fused frame is a rendered one, found by time
    both = (ours & truth).sum()
    recall = both / truth.sum()
    precision = both / ours.sum()
    print(
        f"seen at {COARSE_M} m from {used} fused frames: truth {truth.sum()} cells, "
        f"station {ours.sum()}, recall {recall:.3f}, precision {precision:.3f}"
    )
    assert truth.sum() > 50
    assert recall >= 0.9 and precision >= 0.9
