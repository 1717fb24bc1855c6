"""The holes as a TAK data package (``holes_datapackage.zip``): the offline way to get
markers *with their pictures* onto ATAK, WinTAK and iTAK (attachments sent over CoT often
never arrive).

A data package is a zip with ``MANIFEST/manifest.xml`` (``MissionPackageManifest``
version 2): ``Configuration`` (the package's ``uid`` and ``name``; imported on receipt,
kept), ``Contents`` with one ``Content zipEntry=...`` per file. Here:

* ``<uid>/<uid>.cot``: each hole TAK shows (tiers announced and confirmed,
  :func:`~ground.station.cot.on_tak`) as the CoT event of :func:`~ground.station.cot.hole_cot`,
  stale ``stale_s`` after writing (default 7 days: the package is imported once, the
  marker must outlive the flight) and ``<archive/>`` so ATAK keeps it;
* ``<uid>/hole-<id>.jpg``: its picture, a ``Content`` whose ``uid`` parameter is the
  hole's CoT uid. That is how ATAK attaches a file to a map item (its importer,
  ``MissionPackageFileAttachmentHandler``, unzips a file whose ``uid`` names a map item of
  the package into ``attachments/<uid>/``); the event also lists the picture's SHA-256 in
  ``attachment_list``, as ATAK's own QuickPic markers do;
* ``overlay/<name>.kmz``: the map overlay when there is one (``contentType`` KML).

The package uid is fixed per station (``holescan-<station>-holes``), so importing a newer
package replaces the older one on the device. Written through the output-path rule
(``.holes_datapackage.part.zip``, fsynced, renamed): a reader never sees half a zip.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Mapping, Sequence
from pathlib import Path

from holescan.errors import InputError
from holescan.geotag import Hole
from holescan.ground.station.cot import cot_uid, hole_cot, hole_tier, on_tak
from holescan.ground.station.records import GroundHole
from holescan.link import xml_safe_tree
from holescan.outputs import atomic_output

__all__ = [
    "DATAPACKAGE_NAME",
    "PACKAGE_STALE_S",
    "ground_hole_of",
    "package_holes",
    "write_datapackage",
]

DATAPACKAGE_NAME = "holes_datapackage.zip"
PACKAGE_STALE_S = 7 * 86400.0
"""Stale time of the package's markers after writing, s (an operation lasts days)."""
_OVERLAY_SUFFIXES = {".kmz", ".kml"}


def package_holes(holes: Sequence[GroundHole]) -> list[GroundHole]:
    """The holes a data package carries: those TAK shows (announced and confirmed)."""
    return [h for h in holes if on_tak(hole_tier(h))]


def ground_hole_of(h: Hole, boot_to_unix_ns: int | None = None, why: str = "") -> GroundHole:
    """A flight's fused hole (:class:`geotag.Hole`) as the ground's record (mark ``new``:
    announced), its times on the Unix clock when the boot->Unix offset is known."""
    first = last = 0
    if boot_to_unix_ns is not None:
        first, last = h.t_first_boot_ns + boot_to_unix_ns, h.t_last_boot_ns + boot_to_unix_ns
    return GroundHole(
        h.id,
        h.lat_deg,
        h.lon_deg,
        h.score,
        alt_m=h.alt_m,
        sigma_h_m=h.sigma_h_m,
        sightings=h.sightings,
        major_m=h.major_m,
        minor_m=h.minor_m,
        why=why,
        t_first_unix_ns=first,
        t_updated_unix_ns=last,
    )


def _content(contents: ET.Element, entry: str, **params: str) -> None:
    c = ET.SubElement(contents, "Content", {"ignore": "false", "zipEntry": entry})
    for name, value in params.items():
        ET.SubElement(c, "Parameter", {"name": name, "value": value})


def write_datapackage(
    path: Path,
    holes: Sequence[GroundHole],
    pictures: Mapping[int, bytes],
    *,
    station: str = "ground",
    name: str | None = None,
    overlay: Path | None = None,
    now: dt.datetime | None = None,
    stale_s: float = PACKAGE_STALE_S,
) -> Path:
    """Write the data package of ``holes`` (see the module docstring); return its path.

    holes : every hole known (those TAK does not show are left out). pictures : hole id
    -> JPEG bytes. station : the CoT uids' station name (the same as the live CoT's, so
    a device that has the live marker gets the same one). overlay : a ``.kmz``/``.kml``
    map overlay to include. The file is replaced when it exists (it is the station's
    own, rewritten as holes change).

    Raises
    ------
    InputError : the overlay is not a KML/KMZ file or cannot be read.
    """
    now = now or dt.datetime.now(dt.UTC)
    overlay_bytes = None
    if overlay is not None:
        if overlay.suffix.lower() not in _OVERLAY_SUFFIXES:
            raise InputError(f"map overlay {overlay}: a .kmz or .kml file is needed")
        try:
            overlay_bytes = overlay.read_bytes()
        except OSError as err:
            raise InputError(f"map overlay {overlay}: {err.strerror or err}") from err
    root = ET.Element("MissionPackageManifest", {"version": "2"})
    config = ET.SubElement(root, "Configuration")
    settings = {
        "uid": f"holescan-{station}-holes",
        "name": name or f"holescan holes ({station})",
        "onReceiveImport": "true",
        "onReceiveDelete": "false",
    }
    for key, value in settings.items():
        ET.SubElement(config, "Parameter", {"name": key, "value": value})
    contents = ET.SubElement(root, "Contents")
    files: list[tuple[str, bytes]] = []
    for h in package_holes(holes):
        uid = cot_uid(station, h.id)
        jpeg = pictures.get(h.id)
        digest = hashlib.sha256(jpeg).hexdigest() if jpeg is not None else None
        event = hole_cot(
            h, station=station, now=now, stale_s=stale_s, attachment_sha256=digest, archive=True
        )
        files.append((f"{uid}/{uid}.cot", event))
        _content(contents, f"{uid}/{uid}.cot", uid=uid, name=f"HOLE {h.id}")
        if jpeg is not None:
            entry = f"{uid}/hole-{h.id}.jpg"
            files.append((entry, jpeg))
            _content(contents, entry, uid=uid, name=f"hole-{h.id}.jpg")
    if overlay is not None and overlay_bytes is not None:
        entry = f"overlay/{overlay.name}"
        files.append((entry, overlay_bytes))
        _content(
            contents,
            entry,
            uid=f"holescan-{station}-overlay",
            name=overlay.name,
            contentType="KML",
            visible="true",
        )
    manifest = ET.tostring(xml_safe_tree(root), encoding="utf-8", xml_declaration=True)
    stamp = now.timetuple()[:6]
    with atomic_output(path, force=True) as f, zipfile.ZipFile(f, "w") as z:
        for entry, data in [("MANIFEST/manifest.xml", manifest), *files]:
            info = zipfile.ZipInfo(entry, date_time=stamp)
            jpeg_or_zip = entry.endswith((".jpg", ".kmz"))  # already compressed
            info.compress_type = zipfile.ZIP_STORED if jpeg_or_zip else zipfile.ZIP_DEFLATED
            z.writestr(info, data)
    return path
