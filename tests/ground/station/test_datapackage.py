"""``holes_datapackage.zip``: the holes with their pictures (and the map overlay) for TAK.

The package written here is read by an independent reader, @tak-ps/node-cot's
``DataPackage`` under node (its CoT markers, the attachments it links to them through the
manifest, the other files), and by Python's zipfile / ElementTree for the manifest as
ATAK's importer reads it (every Content's zipEntry in the zip, each with a ``uid``). The
station keeps it current as holes come and go; its CoT details (stale from now, the
point's age, the tier) are checked on fixed clocks.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import json
import shutil
import socket
import subprocess
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest
from test_station import picture, wait_for

from holescan.ground import GroundHole, GroundOptions, GroundStation
from holescan.ground.station import (
    DATAPACKAGE_NAME,
    hole_cot,
    hole_tier,
    on_tak,
    write_datapackage,
)

NODE_COT = Path(__file__).parents[1] / "cot"
T0 = dt.datetime(2026, 12, 3, 9, 0, tzinfo=dt.UTC)
NS = 10**9


def t_ns(t: dt.datetime) -> int:
    return int(t.timestamp()) * NS


def ground_hole(hid: int, mark: str = "new", sigma: float | None = 0.3) -> GroundHole:
    return GroundHole(
        hid,
        43.6532 + hid * 2e-5,
        -79.3832 + hid * 1e-5,
        0.88,
        alt_m=121.0,
        sigma_h_m=sigma,
        sightings=4,
        major_m=1.1,
        minor_m=0.7,
        why="a dark opening",
        has_picture=True,
        mark=mark,  # type: ignore[arg-type]
        t_first_unix_ns=t_ns(T0),
        t_updated_unix_ns=t_ns(T0 + dt.timedelta(minutes=30)),
    )


def kmz(path: Path) -> Path:
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("doc.kml", '<kml xmlns="http://www.opengis.net/kml/2.2"><Document/></kml>')
    return path


def manifest(path: Path) -> tuple[ET.Element, dict[str, dict[str, str]], zipfile.ZipFile]:
    z = zipfile.ZipFile(path)
    root = ET.fromstring(z.read("MANIFEST/manifest.xml"))
    contents = {
        c.attrib["zipEntry"]: {p.attrib["name"]: p.attrib["value"] for p in c.iter("Parameter")}
        for c in root.iter("Content")
    }
    return root, contents, z


def node_read(path: Path) -> dict[str, object]:
    res = subprocess.run(
        ["node", str(NODE_COT / "datapackage.mjs"), str(path)],
        capture_output=True,
        timeout=60,
        check=False,
    )
    assert res.returncode == 0, res.stderr.decode()[-2000:]
    doc: dict[str, object] = json.loads(res.stdout)
    return doc


def test_datapackage_layout(tmp_path: Path) -> None:
    holes = [ground_hole(1), ground_hole(2, "confirmed"), ground_hole(3, "rejected")]
    holes.append(ground_hole(4, sigma=None))  # heard by STATUSTEXT only: no picture yet
    holes[3].has_picture = False
    pictures = {h.id: picture(h.id) for h in holes if h.has_picture}
    now = T0 + dt.timedelta(hours=2)
    path = write_datapackage(
        tmp_path / DATAPACKAGE_NAME, holes, pictures, overlay=kmz(tmp_path / "s_map.kmz"), now=now
    )
    root, contents, z = manifest(path)
    assert root.tag == "MissionPackageManifest" and root.get("version") == "2"
    config = {p.get("name"): p.get("value") for p in root.iterfind("Configuration/Parameter")}
    assert config["uid"] == "holescan-ground-holes" and config["name"]
    assert config["onReceiveImport"] == "true" and config["onReceiveDelete"] == "false"
    names = set(z.namelist())
    assert set(contents) | {"MANIFEST/manifest.xml"} == names  # every file listed, no other
    assert all("uid" in params for params in contents.values())
    uids = {f"holescan-ground-hole-{i}" for i in (1, 2, 4)}  # the rejected one left out
    cots = {e for e in names if e.endswith(".cot")}
    assert cots == {f"{u}/{u}.cot" for u in uids}
    for entry in cots:
        ev = ET.fromstring(z.read(entry))
        assert contents[entry]["uid"] == ev.get("uid") == entry.split("/")[0]
        assert ev.find("detail/archive") is not None  # ATAK keeps the marker
    for hid in (1, 2):
        uid = f"holescan-ground-hole-{hid}"
        entry = f"{uid}/hole-{hid}.jpg"
        assert z.read(entry) == pictures[hid]
        assert contents[entry]["uid"] == uid  # ATAK: an attachment of the marker uid
    overlay = contents["overlay/s_map.kmz"]
    assert overlay["contentType"] == "KML" and overlay["uid"] not in uids
    assert zipfile.ZipFile(z.open("overlay/s_map.kmz")).namelist() == ["doc.kml"]
    assert not list(tmp_path.glob(".*part*"))


@pytest.mark.skipif(shutil.which("node") is None, reason="needs node")
def test_datapackage_read_by_node_cot(tmp_path: Path) -> None:
    if not (NODE_COT / "node_modules" / "@tak-ps" / "node-cot").exists():
        pytest.skip(f"npm install --prefix {NODE_COT} (the independent CoT parser)")
    holes = [ground_hole(1), ground_hole(2, "visited"), ground_hole(3, "rejected")]
    pictures = {h.id: picture(h.id) for h in holes}
    now = T0 + dt.timedelta(hours=2)
    path = write_datapackage(
        tmp_path / DATAPACKAGE_NAME, holes, pictures, overlay=kmz(tmp_path / "m.kmz"), now=now
    )
    doc = node_read(path)
    assert path.is_file()  # the reader was told not to delete its input
    assert doc["version"] == "2"
    cots = {c["uid"]: c for c in doc["cots"]}  # type: ignore[attr-defined]
    assert set(cots) == {"holescan-ground-hole-1", "holescan-ground-hole-2"}
    attachments = doc["attachments"]
    hashes = doc["hashes"]
    for hid in (1, 2):
        uid = f"holescan-ground-hole-{hid}"
        c = cots[uid]
        assert c["type"] == "b-m-p-s-p-i" and c["callsign"] == f"HOLE {hid}" and c["archived"]
        assert attachments[uid] == [f"{uid}/hole-{hid}.jpg"]  # type: ignore[index]
        digest = hashlib.sha256(pictures[hid]).hexdigest()
        assert hashes[f"{uid}/hole-{hid}.jpg"] == digest  # type: ignore[index]
        # node-cot adds the hash of each linked attachment; ours was already the same one
        assert c["attachment_hashes"] == [digest]
        lon, lat = c["geojson"]["geometry"]["coordinates"][:2]
        assert (lat, lon) == pytest.approx((holes[hid - 1].lat_deg, holes[hid - 1].lon_deg))
        stale = dt.datetime.strptime(c["stale"], "%Y-%m-%dT%H:%M:%S.%fZ").replace(tzinfo=dt.UTC)
        assert stale == now + dt.timedelta(days=7)
    assert cots["holescan-ground-hole-2"]["remarks"].startswith("CONFIRMED: hole 2")
    assert doc["files"] == ["overlay/m.kmz"]  # the overlay: a file, not an attachment


def test_cot_details_stale_age_tier() -> None:
    h = ground_hole(1)
    late = T0 + dt.timedelta(hours=5)  # sent long after the first sighting
    ev = ET.fromstring(hole_cot(h, now=late, stale_s=300.0))
    assert ev.get("time") == ev.get("start") == "2026-12-03T14:00:00.000Z"
    assert ev.get("stale") == "2026-12-03T14:05:00.000Z"  # from now, not from T0
    text = ev.findtext("detail/remarks") or ""
    assert text.startswith("ANNOUNCED: hole 1, best frame's score 0.88")
    assert text.endswith("(first seen 5.0 h ago (09:00Z), updated 4.5 h ago)")
    facts = ev.find("detail/holescan")
    assert facts is not None and facts.attrib == {
        "tier": "announced",
        "mark": "new",
        "score": "0.880",
        "sightings": "4",
        "sigma_h_m": "0.300",
        "first_seen": "2026-12-03T09:00:00.000Z",
        "updated": "2026-12-03T09:30:00.000Z",
    }
    point = ev.find("point")
    assert point is not None and float(point.get("ce", "")) == pytest.approx(1.6215 * 0.3, 0.01)
    unknown = ET.fromstring(hole_cot(ground_hole(2, sigma=None), now=late)).find("point")
    assert unknown is not None and unknown.get("ce") == "9999999.0"
    assert [hole_tier(ground_hole(1, m)) for m in ("new", "confirmed", "visited", "rejected")] == [
        "announced",
        "confirmed",
        "confirmed",
        "rejected",
    ]
    assert [on_tak(t) for t in ("announced", "review", "confirmed", "rejected")] == [
        True,
        False,
        True,
        False,
    ]
    with pytest.raises(ValueError, match="stale_s"):
        hole_cot(h, stale_s=0)


def test_station_keeps_the_datapackage_current(tmp_path: Path) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "station"
    opts = GroundOptions(
        mavlink=f"udpin:127.0.0.1:{port}",
        out=out,
        http_port=None,
        cot_url=None,
        overlay=kmz(tmp_path / "area_map.kmz"),
    )
    path = out / DATAPACKAGE_NAME

    def holes_in_package() -> set[str]:
        if not path.exists():
            return set()
        _, contents, _ = manifest(path)  # always a whole zip: written atomically
        return {e.split("/")[0] for e in contents if e.endswith(".cot")}

    with GroundStation(opts) as station:
        for hid in (1, 2):
            facts = {"id": hid, "rev": 1, "lat": 43.6532 + hid * 2e-5, "lon": -79.3832}
            station.state.on_card(facts | {"score": 0.9, "sigma": 0.3}, picture(hid))
        both = {"holescan-ground-hole-1", "holescan-ground-hole-2"}
        wait_for(lambda: holes_in_package() == both, 10.0, "both holes in the package")
        station.mark(2, "rejected")  # the station's own thread writes the files after it
        wait_for(
            lambda: holes_in_package() == {"holescan-ground-hole-1"}, 10.0, "the rejected one out"
        )
    _, contents, z = manifest(path)
    assert z.read("holescan-ground-hole-1/hole-1.jpg") == picture(1)
    assert "overlay/area_map.kmz" in contents
    assert not list(out.glob(".*part*"))
