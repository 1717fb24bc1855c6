"""The map as GeoTIFFs (rasterio, GDAL): orthophoto, surface heights, coverage.

The map is fused on a north-up grid of a :class:`geotag.LocalFrame`'s tangent-plane metres.
That plane is the ellipsoidal orthographic projection at the frame's origin
(``+proj=ortho``; over a field of 100 m it agrees with east/north to well under a
millimetre), so GDAL knows exactly where every cell is; each raster is then warped
(``rasterio.warp.reproject``) to the UTM zone of the origin (WGS84, EPSG 326xx / 327xx),
which QGIS, ATAK and CalTopo all open, written tiled (256 px), deflate-compressed, with
overviews (2x, 4x ... while over 64 px).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import rasterio
from affine import Affine
from rasterio.crs import CRS
from rasterio.enums import Resampling
from rasterio.warp import calculate_default_transform, reproject

from holescan.geotag import LocalFrame
from holescan.mapping import MapLayers
from holescan.outputs import output_via_part

__all__ = [
    "DSM_NODATA",
    "GeoRaster",
    "local_crs",
    "to_utm",
    "utm_crs",
    "write_geotiff",
    "write_map_geotiffs",
]

DSM_NODATA = -9999.0
_TILE = 256


def local_crs(frame: LocalFrame) -> CRS:
    """The CRS of a local frame's east/north metres (ellipsoidal orthographic at its origin)."""
    return CRS.from_proj4(
        f"+proj=ortho +lat_0={frame.lat0_deg!r} +lon_0={frame.lon0_deg!r} +x_0=0 +y_0=0 "
        "+ellps=WGS84 +units=m +no_defs"
    )


def utm_crs(lat_deg: float, lon_deg: float) -> CRS:
    """WGS84 / UTM of the zone holding a point (EPSG 326zz north, 327zz south)."""
    zone = min(60, max(1, math.floor((lon_deg + 180.0) / 6.0) + 1))
    return CRS.from_epsg((32600 if lat_deg >= 0 else 32700) + zone)


@dataclass(frozen=True)
class GeoRaster:
    """Bands ready to write: (bands, rows, cols), their transform and CRS, nodata."""

    data: npt.NDArray[np.generic]
    transform: Affine
    crs: CRS
    nodata: float | None


def to_utm(
    bands: npt.NDArray[np.generic],
    layers: MapLayers,
    frame: LocalFrame,
    resampling: Resampling,
    nodata: float | None,
) -> GeoRaster:
    """Warp (bands, ny, nx) of the map's grid to the UTM zone of the frame's origin."""
    g = layers.grid
    src_t = Affine(g.cell_m, 0.0, g.west_m, 0.0, -g.cell_m, g.north_m)
    src_crs = local_crs(frame)
    dst_crs = utm_crs(frame.lat0_deg, frame.lon0_deg)
    dst_t, w, h = calculate_default_transform(
        src_crs,
        dst_crs,
        g.nx,
        g.ny,
        g.west_m,
        g.south_m,
        g.east_m,
        g.north_m,
        resolution=g.cell_m,
    )
    out = np.empty((bands.shape[0], h, w), dtype=bands.dtype)
    fill = nodata if nodata is not None else 0
    out[...] = fill
    for b in range(bands.shape[0]):
        reproject(
            bands[b],
            out[b],
            src_transform=src_t,
            src_crs=src_crs,
            src_nodata=nodata,
            dst_transform=dst_t,
            dst_crs=dst_crs,
            dst_nodata=nodata,
            resampling=resampling,
        )
    return GeoRaster(out, dst_t, dst_crs, nodata)


def write_geotiff(path: Path, raster: GeoRaster, *, rgb: bool = False, force: bool = True) -> Path:
    """One GeoTIFF: tiled, deflate, with overviews; through ``.part`` and a rename."""
    bands, h, w = raster.data.shape
    profile = {
        "driver": "GTiff",
        "width": w,
        "height": h,
        "count": bands,
        "dtype": raster.data.dtype.name,
        "crs": raster.crs,
        "transform": raster.transform,
        "tiled": True,
        "blockxsize": _TILE,
        "blockysize": _TILE,
        "compress": "deflate",
        "nodata": raster.nodata,
    }
    if rgb:
        profile["photometric"] = "RGB"
        profile.pop("nodata")
        profile["alpha"] = "YES" if bands == 4 else "NO"
    factors = []
    f = 2
    while max(h, w) / f >= _TILE / 4 and f <= 512:
        factors.append(f)
        f *= 2
    with output_via_part(path, force=force) as tmp, rasterio.open(tmp, "w", **profile) as dst:
        dst.write(raster.data)
        if rgb and bands == 4:
            dst.colorinterp = [
                rasterio.enums.ColorInterp.red,
                rasterio.enums.ColorInterp.green,
                rasterio.enums.ColorInterp.blue,
                rasterio.enums.ColorInterp.alpha,
            ]
        if factors:
            dst.build_overviews(factors, Resampling.average)
            dst.update_tags(ns="rio_overview", resampling="average")
    return path


def write_map_geotiffs(
    folder: Path, name: str, layers: MapLayers, frame: LocalFrame, *, force: bool = True
) -> list[tuple[str, Path]]:
    """``NAME_ortho.tif`` (RGB + alpha), ``NAME_dsm.tif`` (metres, the flight's altitude
    datum), ``NAME_coverage.tif`` (0..1, 0 where unseen) in UTM. Returns (kind, path)."""
    seen = layers.looks > 0
    alpha = np.where(np.isfinite(layers.height_m), 255, 0).astype(np.uint8)
    rgba = np.concatenate([np.moveaxis(layers.rgb, -1, 0), alpha[None]], axis=0)
    ortho = to_utm(rgba, layers, frame, Resampling.nearest, None)
    dsm_m = np.where(np.isfinite(layers.height_m), layers.height_m + frame.alt0_m, DSM_NODATA)
    dsm = to_utm(dsm_m[None].astype(np.float32), layers, frame, Resampling.nearest, DSM_NODATA)
    cov = np.where(seen, layers.coverage, 0.0).astype(np.float32)
    coverage = to_utm(cov[None], layers, frame, Resampling.nearest, None)
    out = []
    for kind, raster, rgb in (
        ("ortho", ortho, True),
        ("dsm", dsm, False),
        ("coverage", coverage, False),
    ):
        path = folder / f"{name}_{kind}.tif"
        write_geotiff(path, raster, rgb=rgb, force=force)
        out.append((kind, path))
    return out
