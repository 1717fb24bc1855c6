"""The orthophoto with the holes on it as a KMZ (Google Earth, CalTopo, ATAK).

A KML ``GroundOverlay`` of the orthophoto warped to WGS84 longitude/latitude (a PNG with
transparency where nothing was seen, inside the KMZ) and one ``Placemark`` per hole (the
project's hole descriptions, :func:`missions.hole_points`), written with the standard
library (zipfile, ElementTree): nothing the ground crew's tools need beyond KML 2.2.
"""

from __future__ import annotations

import io
import math
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Mapping, Sequence
from pathlib import Path

import cv2
import numpy as np
from affine import Affine
from rasterio.crs import CRS
from rasterio.enums import Resampling
from rasterio.warp import calculate_default_transform, reproject

from holescan.geotag import AnnounceGate, Hole, LocalFrame
from holescan.ground.searchmap.geotiff import local_crs
from holescan.link import xml_safe_tree
from holescan.mapping import MapLayers
from holescan.missions import hole_points
from holescan.outputs import atomic_output

__all__ = ["KML_NS", "write_map_kmz"]

KML_NS = "http://www.opengis.net/kml/2.2"
_MAX_PX = 4096  # Google Earth draws overlays up to its texture size; keep within


def _sub(parent: ET.Element, tag: str, text: str | None = None) -> ET.Element:
    el = ET.SubElement(parent, tag)
    if text is not None:
        el.text = text
    return el


def _lonlat_png(
    layers: MapLayers, frame: LocalFrame
) -> tuple[bytes, tuple[float, float, float, float]]:
    """The orthophoto on a lon/lat grid as PNG bytes, and its (west, south, east, north)."""
    g = layers.grid
    src_t = Affine(g.cell_m, 0.0, g.west_m, 0.0, -g.cell_m, g.north_m)
    dst_crs = CRS.from_epsg(4326)
    deg = g.cell_m / 111_320.0
    scale = max(1.0, max(g.nx, g.ny) / _MAX_PX)
    dst_t, w, h = calculate_default_transform(
        local_crs(frame),
        dst_crs,
        g.nx,
        g.ny,
        g.west_m,
        g.south_m,
        g.east_m,
        g.north_m,
        resolution=(deg * scale / max(math.cos(math.radians(frame.lat0_deg)), 0.01), deg * scale),
    )
    alpha = np.where(np.isfinite(layers.height_m), 255, 0).astype(np.uint8)
    src = np.concatenate([np.moveaxis(layers.rgb, -1, 0), alpha[None]], axis=0)
    out = np.zeros((4, h, w), np.uint8)
    for b in range(4):
        reproject(
            src[b],
            out[b],
            src_transform=src_t,
            src_crs=local_crs(frame),
            dst_transform=dst_t,
            dst_crs=dst_crs,
            resampling=Resampling.nearest,
        )
    bgra = np.ascontiguousarray(np.moveaxis(out[[2, 1, 0, 3]], 0, -1))
    ok, png = cv2.imencode(".png", bgra)
    if not ok:
        raise ValueError("PNG encoding failed")
    west, north = dst_t.c, dst_t.f
    east, south = west + w * dst_t.a, north + h * dst_t.e
    return png.tobytes(), (west, south, east, north)


def write_map_kmz(
    path: Path,
    name: str,
    layers: MapLayers,
    frame: LocalFrame,
    holes: Sequence[Hole],
    *,
    boot_to_unix_ns: int | None = None,
    force: bool = True,
    tiers: Mapping[int, str] | None = None,
) -> Path:
    """``NAME_map.kmz``: the orthophoto as a GroundOverlay and the holes as placemarks.

    tiers : hole id -> tier (None: :meth:`geotag.AnnounceGate.tier` with the default
        gate); each placemark is named and described by its tier, candidates are left out
        (the KMZ goes to the crews, inside the TAK data package too).
    """
    if tiers is None:
        gate = AnnounceGate()
        tiers = {h.id: gate.tier(h) for h in holes}
    holes = [h for h in holes if tiers.get(h.id, "candidate") != "candidate"]
    png, (west, south, east, north) = _lonlat_png(layers, frame)
    ET.register_namespace("", KML_NS)
    kml = ET.Element(f"{{{KML_NS}}}kml")
    doc = _sub(kml, "Document")
    _sub(doc, "name", f"holescan map: {name}")
    _sub(
        doc,
        "description",
        "Orthophoto fused from the flight's own RGB-D frames. The map and the holes carry the "
        "same pose errors: a hole sits on its picture even when GNSS is off by metres.",
    )
    ov = _sub(doc, "GroundOverlay")
    _sub(ov, "name", "orthophoto")
    icon = _sub(ov, "Icon")
    _sub(icon, "href", "files/ortho.png")
    box = _sub(ov, "LatLonBox")
    for tag, v in (("north", north), ("south", south), ("east", east), ("west", west)):
        _sub(box, tag, f"{v:.9f}")
    folder = _sub(doc, "Folder")
    _sub(folder, "name", "holes")
    for w in hole_points(holes, boot_to_unix_ns=boot_to_unix_ns, on_ground=True, tiers=tiers):
        pm = _sub(folder, "Placemark")
        _sub(pm, "name", w.name)
        _sub(pm, "description", w.description)
        pt = _sub(pm, "Point")
        _sub(pt, "altitudeMode", "clampToGround")
        _sub(pt, "coordinates", f"{w.lon_deg:.8f},{w.lat_deg:.8f},0")
    buf = io.BytesIO()
    ET.ElementTree(xml_safe_tree(kml)).write(buf, encoding="utf-8", xml_declaration=True)
    with atomic_output(path, force=force) as f, zipfile.ZipFile(f, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("doc.kml", buf.getvalue())
        z.writestr("files/ortho.png", png)
    return path
