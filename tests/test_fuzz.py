"""Property-based fuzzing of every parser of outside data, each bounded (examples, deadline,
address space): the MCAP flight-log reader, the ``.oni`` scanner, MAVLink byte streams into
the telemetry decoder, area GeoJSON, dataset JSON, camera.json and the fly TOML config.

Property: a result or the project's own error (:class:`holescan.errors.HolescanError`),
never another exception, a hang or unbounded memory.
"""

from __future__ import annotations

import contextlib
import json
import os
import resource
import struct
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from holescan.capture import parse_fly_config, scan_oni, write_oni
from holescan.detect import CameraIntrinsics, Frame
from holescan.errors import HolescanError
from holescan.flightlog import FlightLogWriter, LoggedFrame, log_info, read_flight_log, recover_log
from holescan.ground import load_dataset, read_camera
from holescan.link import (
    MavlinkStream,
    attitude_from_attitude,
    attitude_from_quaternion,
    gps_from_gps_raw_int,
    mavlink,
    parser,
    position_from_global_position_int,
)
from holescan.missions import read_area

CAM = CameraIntrinsics(32, 24, 30.0, 30.0, 15.5, 11.5)
#: Extra address space a parser may take while fuzzed (a corrupt length once asked 5 GB).
_AS_BUDGET = 1536 << 20

FUZZ = settings(
    max_examples=int(os.environ.get("HOLESCAN_FUZZ_EXAMPLES", "60")),
    deadline=3000,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
    derandomize="HOLESCAN_FUZZ_EXAMPLES" not in os.environ,  # CI: the same examples each run
)


@contextlib.contextmanager
def bounded_memory() -> Iterator[None]:
    """Cap the address space at what the process has now plus a budget."""
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    vm = 0
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmSize:"):
            vm = int(line.split()[1]) * 1024
    limit = vm + _AS_BUDGET
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def result_or_own_error(fn: Callable[[], Any]) -> Any:
    with bounded_memory():
        try:
            return fn()
        except HolescanError:
            return None


# ------------------------------------------------------------------------------ MCAP


@pytest.fixture(scope="module")
def mcap_bytes(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    d = tmp_path_factory.mktemp("fuzzlog")
    rng = np.random.default_rng(0)
    opts_kw: dict[str, Any] = {}
    from holescan.flightlog import LogOptions

    with FlightLogWriter(d / "f", CAM, options=LogOptions(chunk_size=4000, **opts_kw)) as w:
        for i in range(12):
            rgb = rng.integers(0, 255, (24, 32, 3), dtype=np.uint8)
            depth = rng.integers(500, 3000, (24, 32)).astype(np.uint16)
            w.write_frame(Frame(i, rgb, depth, i * 1000, i * 1000), 1_750_000_000_000_000_000 + i)
            w.write_holes([{"lat_deg": 43.0, "lon_deg": -79.0, "id": i}], 1_750_000_000_0 + i)
    return w.paths[0].read_bytes()


def _mutate(data: bytes, draw: st.DrawFn) -> bytes:
    buf = bytearray(data)
    kind = draw(st.sampled_from(["truncate", "flip", "length", "splice"]))
    if kind == "truncate":
        return bytes(buf[: draw(st.integers(0, len(buf)))])
    if kind == "flip":
        for _ in range(draw(st.integers(1, 8))):
            i = draw(st.integers(0, len(buf) - 1))
            buf[i] ^= draw(st.integers(1, 255))
        return bytes(buf)
    if kind == "length":  # an 8-byte little-endian field anywhere set to something wild
        i = draw(st.integers(0, len(buf) - 8))
        value = draw(st.sampled_from([0, 1, 2**31, 2**32 + 7, 2**62, 2**64 - 1, len(buf)]))
        struct.pack_into("<Q", buf, i, value)
        return bytes(buf)
    i = draw(st.integers(0, len(buf)))
    return bytes(buf[:i]) + draw(st.binary(max_size=64)) + bytes(buf[i:])


@st.composite
def mutated(draw: st.DrawFn, data: bytes) -> bytes:
    return _mutate(data, draw)


@FUZZ
@given(data=st.data())
def test_fuzz_mcap_reader(mcap_bytes: bytes, data: st.DataObject) -> None:
    blob = data.draw(mutated(mcap_bytes))
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "f.mcap"
        p.write_bytes(blob)
        frames = result_or_own_error(lambda: list(read_flight_log(p, kinds={LoggedFrame})))
        if frames is not None:
            assert all(r.frame.depth.shape == (24, 32) for r in frames)
        result_or_own_error(lambda: log_info(p, allow_truncated=True))
        result_or_own_error(lambda: recover_log(p, Path(d) / "r.mcap"))
        assert not list(Path(d).glob(".*part*"))


# ------------------------------------------------------------------------------- .oni


@pytest.fixture(scope="module")
def oni_bytes(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    d = tmp_path_factory.mktemp("fuzzoni")
    frames = [
        Frame(
            i,
            np.full((24, 32, 3), i, np.uint8),
            np.full((24, 32), 1000 + i, np.uint16),
            0,
            i * 33_000_000,
        )
        for i in range(4)
    ]
    write_oni(d / "a.oni", frames, CAM)
    return (d / "a.oni").read_bytes()


@FUZZ
@given(data=st.data())
def test_fuzz_oni_scanner(oni_bytes: bytes, data: st.DataObject) -> None:
    blob = data.draw(mutated(oni_bytes))
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "a.oni"
        p.write_bytes(blob)
        info = result_or_own_error(lambda: scan_oni(p))
        if info is not None:
            assert info.streams


# ----------------------------------------------------------------------------- MAVLink


def _real_packets() -> list[bytes]:
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    msgs = [
        mav.global_position_int_encode(10, 436532000, -793832000, 112500, 3000, 1, 2, 3, 4),
        mav.attitude_encode(11, 0.1, -0.2, 3.0, 0.0, 0.0, 0.0),
        mav.attitude_quaternion_encode(12, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        mav.gps_raw_int_encode(13, 3, 436532000, -793832000, 112500, 120, 65535, 0, 0, 9),
        mav.system_time_encode(1_750_000_000_000_000, 14),
    ]
    return [bytes(m.pack(mav)) for m in msgs]


PACKETS = _real_packets()


@FUZZ
@given(
    pieces=st.lists(
        st.one_of(st.sampled_from(PACKETS), st.binary(max_size=120)), min_size=1, max_size=30
    ),
    flips=st.lists(st.tuples(st.integers(0, 10_000), st.integers(1, 255)), max_size=5),
    datagrams=st.booleans(),
)
def test_fuzz_mavlink_into_the_telemetry_decoder(
    pieces: list[bytes], flips: list[tuple[int, int]], datagrams: bool
) -> None:
    stream = b"".join(pieces)
    buf = bytearray(stream)
    for i, x in flips:
        if buf:
            buf[i % len(buf)] ^= x
    s = MavlinkStream(parser(), datagrams=datagrams)
    adapters = {
        "GLOBAL_POSITION_INT": position_from_global_position_int,
        "ATTITUDE": attitude_from_attitude,
        "ATTITUDE_QUATERNION": attitude_from_quaternion,
    }
    with bounded_memory():
        feed = (
            [bytes(buf)] if datagrams else [bytes(buf[i : i + 17]) for i in range(0, len(buf), 17)]
        )
        for chunk in feed:
            for msg in s.feed(chunk):
                fn = adapters.get(msg.get_type())
                try:
                    if fn is not None:
                        fn(msg)
                    elif msg.get_type() == "GPS_RAW_INT":
                        gps_from_gps_raw_int(msg, 0)
                except ValueError:  # the adapter's own refusal (a zero quaternion)
                    pass
    assert len(s._buf) < 300  # never more than one unfinished packet kept


# ------------------------------------------------------------------ files people write

json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**70), 2**70) | st.floats() | st.text(max_size=8),
    lambda children: (
        st.lists(children, max_size=5) | st.dictionaries(st.text(max_size=8), children, max_size=5)
    ),
    max_leaves=30,
)


def _geojson(draw: st.DrawFn) -> Any:
    coord = st.tuples(st.floats(), st.floats()).map(list)
    ring = st.lists(coord, min_size=0, max_size=8)
    shape = draw(
        st.sampled_from(["Polygon", "MultiPolygon", "Feature", "FeatureCollection", "junk"])
    )
    if shape == "junk":
        return draw(json_values)
    poly = {"type": "Polygon", "coordinates": draw(st.lists(ring, max_size=3))}
    if shape == "Polygon":
        return poly
    if shape == "MultiPolygon":
        return {"type": "MultiPolygon", "coordinates": [poly["coordinates"]]}
    feature = {"type": "Feature", "geometry": poly, "properties": draw(json_values)}
    if shape == "Feature":
        return feature
    return {"type": "FeatureCollection", "features": [feature, draw(json_values)]}


@FUZZ
@given(data=st.data())
def test_fuzz_area_geojson(data: st.DataObject) -> None:
    doc = data.draw(st.composite(_geojson)())
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "area.geojson"
        p.write_text(json.dumps(doc, allow_nan=True))
        result_or_own_error(lambda: read_area(p))


@FUZZ
@given(
    doc=st.fixed_dictionaries(
        {
            "images": st.lists(
                st.fixed_dictionaries(
                    {"id": json_values, "file_name": json_values},
                    optional={"depth_file": json_values, "width": json_values},
                ),
                max_size=3,
            ),
            "annotations": st.lists(
                st.fixed_dictionaries(
                    {"image_id": json_values, "bbox": json_values},
                    optional={"iscrowd": json_values, "category_id": json_values},
                ),
                max_size=3,
            ),
        },
        optional={"categories": json_values},
    )
    | json_values,
    camera=json_values,
)
def test_fuzz_dataset_json_and_camera_json(doc: Any, camera: Any) -> None:
    with tempfile.TemporaryDirectory() as d:
        root = Path(d)
        (root / "annotations.json").write_text(json.dumps(doc))
        (root / "camera.json").write_text(json.dumps(camera))
        ds = result_or_own_error(lambda: load_dataset(root))
        if ds is not None:
            for im in ds.images:
                assert im is not None
        result_or_own_error(lambda: read_camera(root / "camera.json"))


@FUZZ
@given(
    cam=st.fixed_dictionaries(
        {
            k: st.one_of(st.floats(), st.integers(-5, 5000), json_values)
            for k in ("width", "height", "fx", "fy", "cx", "cy")
        },
        optional={"depth_unit_m": st.one_of(st.floats(), json_values)},
    )
)
def test_fuzz_camera_json_fields(cam: dict[str, Any]) -> None:
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "camera.json"
        p.write_text(json.dumps(cam, allow_nan=True))
        got = result_or_own_error(lambda: read_camera(p))
        if got is not None:
            assert got.width > 0 and got.fx > 0 and 0 < got.depth_unit_m <= 1


toml_scalars = st.one_of(
    st.booleans(), st.integers(-(2**63), 2**63 - 1), st.floats(), st.text(max_size=12)
)
toml_tables = st.dictionaries(
    st.sampled_from(
        [
            "sensor",
            "mavlink",
            "log_dir",
            "gcs",
            "duration_s",
            "max_frames",
            "baud",
            "sysid",
            "fps",
            "mode",
            "x",
        ]
    ),
    toml_scalars | st.lists(toml_scalars, max_size=3),
    max_size=5,
)


@FUZZ
@given(
    doc=st.dictionaries(
        st.sampled_from(
            [
                "sensor",
                "log_dir",
                "duration_s",
                "capture",
                "detector",
                "holes",
                "mount",
                "log",
                "sim",
                "mavlink",
                "unknown",
            ]
        ),
        toml_scalars | toml_tables,
        max_size=6,
    )
)
def test_fuzz_fly_config(doc: dict[str, Any]) -> None:
    result_or_own_error(lambda: parse_fly_config(doc))
