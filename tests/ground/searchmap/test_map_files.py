"""The search map's files read back by their readers: rasterio/GDAL, a KML parser, shapely."""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import cv2
import numpy as np
import pytest
import rasterio
from rasterio.warp import transform as warp_transform
from shapely.geometry import box, shape

from holescan.geotag import LocalFrame
from holescan.ground.searchmap import write_map_outputs
from holescan.mapping import MapGrid, MapLayers
from holescan.missions import SurveyParams, read_plan

FRAME = LocalFrame(47.0, 8.0, 400.0)
STRIP = (4.0, 5.5)  # east metres of the lane nobody looked at


def _layers() -> MapLayers:
    grid = MapGrid.covering(0.0, 0.0, 10.0, 8.0, 0.05)
    lay = MapLayers.empty(grid)
    e, n = grid.centres()
    ee, _ = np.meshgrid(e, n)
    gap = (ee >= STRIP[0]) & (ee < STRIP[1])
    lay.looks[~gap] = 3
    lay.log_miss[~gap] = math.log(1 - 0.9)
    lay.height_m[~gap] = (0.1 * ee[~gap]).astype(np.float32)
    lay.best_cost[~gap] = 3.0
    lay.rgb[~gap] = np.stack([ee * 20, 128 + 0 * ee, 255 - ee * 20], axis=-1)[~gap].astype(np.uint8)
    return lay


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Path]]:
    out = tmp_path_factory.mktemp("map")
    res = write_map_outputs(
        out,
        "f1",
        _layers(),
        FRAME,
        [],
        area=box(0.0, 0.0, 10.0, 8.0),
        survey=SurveyParams(altitude_m=2.5),
    )
    return out, dict(res.files)  # type: ignore[arg-type]


def _utm_of(ds: rasterio.io.DatasetReader, east: float, north: float) -> tuple[float, float]:
    lat, lon = FRAME.to_geodetic(east, north)
    xs, ys = warp_transform("EPSG:4326", ds.crs, [float(lon)], [float(lat)])
    return xs[0], ys[0]


def test_geotiffs_are_utm_tiled_with_overviews_and_hold_the_map(written) -> None:  # type: ignore[no-untyped-def]
    _, files = written
    with rasterio.open(files["coverage"]) as cov, rasterio.open(files["dsm"]) as dsm:
        assert cov.crs.to_epsg() == 32632  # 8 deg E: UTM zone 32 north
        assert cov.dtypes == ("float32",) and cov.block_shapes == [(256, 256)]
        assert cov.overviews(1) == [2]  # 10 x 8 m at 5 cm: 200 x 160 px, one level
        # Bounds: the field's corners, in UTM.
        for e, n in ((0.0, 0.0), (10.0, 8.0)):
            x, y = _utm_of(cov, e, n)
            assert cov.bounds.left - 0.1 <= x <= cov.bounds.right + 0.1
            assert cov.bounds.bottom - 0.1 <= y <= cov.bounds.top + 0.1
        c = cov.read(1)
        h = dsm.read(1)
        for e, n, want in ((2.0, 4.0, 0.9), (8.0, 2.0, 0.9), (4.7, 4.0, 0.0)):
            r, col = cov.index(*_utm_of(cov, e, n))
            assert c[r, col] == pytest.approx(want, abs=1e-5), (e, n)
            if want:
                assert h[r, col] == pytest.approx(400.0 + 0.1 * e, abs=0.02)
            else:
                assert h[r, col] == dsm.nodata
    with rasterio.open(files["ortho"]) as ortho:
        assert ortho.count == 4 and ortho.dtypes[0] == "uint8"
        rgba = ortho.read()
        r, col = ortho.index(*_utm_of(ortho, 2.0, 4.0))
        assert rgba[3, r, col] == 255 and rgba[0, r, col] == pytest.approx(40, abs=2)
        r, col = ortho.index(*_utm_of(ortho, 4.7, 4.0))
        assert rgba[3, r, col] == 0


def test_kmz_is_a_ground_overlay_on_the_field(written) -> None:  # type: ignore[no-untyped-def]
    _, files = written
    with zipfile.ZipFile(files["map"]) as z:
        root = ET.fromstring(z.read("doc.kml"))
        png = np.frombuffer(z.read("files/ortho.png"), np.uint8)
    ns = {"k": "http://www.opengis.net/kml/2.2"}
    ov = root.find("k:Document/k:GroundOverlay", ns)
    assert ov is not None
    assert ov.findtext("k:Icon/k:href", namespaces=ns) == "files/ortho.png"
    b = {
        t: float(ov.findtext(f"k:LatLonBox/k:{t}", namespaces=ns) or "nan")
        for t in ("north", "south", "east", "west")
    }
    lat0, lon0 = FRAME.to_geodetic(0.0, 0.0)
    lat1, lon1 = FRAME.to_geodetic(10.0, 8.0)
    assert b["south"] <= lat0 + 1e-6 and b["north"] >= lat1 - 1e-6
    assert b["west"] <= lon0 + 1e-6 and b["east"] >= lon1 - 1e-6
    assert b["north"] - b["south"] < 8.5 / 111_000
    img = cv2.imdecode(png, cv2.IMREAD_UNCHANGED)
    assert img.ndim == 3 and img.shape[2] == 4 and (img[..., 3] == 0).any()


def test_gaps_are_the_unlooked_lane_with_their_areas(written) -> None:  # type: ignore[no-untyped-def]
    _, files = written
    doc = json.loads(files["gaps"].read_text())
    gaps = [f for f in doc["features"] if f["properties"]["kind"] == "gap"]
    (area,) = [f for f in doc["features"] if f["properties"]["kind"] == "surveyed area"]
    assert len(gaps) == 1
    g = shape(gaps[0]["geometry"])  # lon/lat
    lon, lat = np.asarray(g.exterior.coords).T
    e, n = FRAME.to_en(lat, lon)
    assert e.min() == pytest.approx(STRIP[0], abs=0.06) and e.max() == pytest.approx(
        STRIP[1], abs=0.06
    )
    assert n.min() == pytest.approx(0.0, abs=0.06) and n.max() == pytest.approx(8.0, abs=0.06)
    assert gaps[0]["properties"]["area_m2"] == pytest.approx(1.5 * 8.0, rel=0.03)
    assert area["properties"]["searched_fraction"] == pytest.approx((80 - 12) / 80, abs=0.01)


def test_the_refly_flies_over_the_gap_only(written) -> None:  # type: ignore[no-untyped-def]
    _, files = written
    _home, items = read_plan(files["refly.plan"])
    nav = [w for w in items if w.command == 16]
    assert nav
    e, _n = FRAME.to_en([w.lat_deg for w in nav], [w.lon_deg for w in nav])
    # Lines along the 8 m lane (the planner's turn margin past each end), within it across.
    assert np.all((e > STRIP[0] - 0.8) & (e < STRIP[1] + 0.8))
    assert all(w.alt_m == pytest.approx(2.5) for w in nav)
    assert files["refly.waypoints"].read_text().startswith("QGC WPL 110")
