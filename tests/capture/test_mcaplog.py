"""The MCAP flight log: write -> read round trips, rotation, drops, truncation and recovery,
a writer killed with SIGKILL, garbage input, the ``holescan log`` verbs, and the writer's
speed at 30 fps."""

from __future__ import annotations

import json
import logging
import math
import os
import signal
import subprocess
import sys
import textwrap
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from mcap.reader import make_reader
from mcap.records import Message
from mcap.stream_reader import StreamReader
from mcap_protobuf.decoder import DecoderFactory

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import common as mavlink2  # noqa: E402

from capture import (  # noqa: E402
    FlightLogError,
    FlightLogWriter,
    Frame,
    LoggedCalibration,
    LoggedDetections,
    LoggedFrame,
    LoggedHealth,
    LoggedHoles,
    LoggedMavlink,
    LoggedPose,
    LogOptions,
    McapSource,
    TruncatedLogError,
    log_info,
    read_flight_log,
    recover_log,
)
from capture._mcaplog import log_file_path  # noqa: E402
from detect import CameraIntrinsics, Detection, FeatureScores  # noqa: E402
from geotag import CameraMount, Hole, VehiclePose  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
SMALL = CameraIntrinsics(80, 60, 71.3, 71.3, 39.5, 29.5)
VGA = CameraIntrinsics.xtion()
T0_UNIX_NS = 1_750_000_000_123_456_789
FRAME_TOPICS = ("/camera/frame_info", "/camera/color/image_raw", "/camera/depth/image_raw")
_log = logging.getLogger(__name__)


def make_frame(i: int, cam: CameraIntrinsics = SMALL) -> Frame:
    """Frame ``i`` of a deterministic synthetic sequence (content depends on ``i``)."""
    rng = np.random.default_rng(1000 + i)
    h, w = cam.height, cam.width
    yy, xx = np.mgrid[0:h, 0:w]
    depth = 1500 + 400 * np.sin((xx + 3 * i) / 9.0) + rng.integers(0, 20, (h, w))
    depth[rng.random((h, w)) < 0.05] = 0  # no reading
    rgb = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    return Frame(i, rgb, depth.astype(np.uint16), 9_000_000_000 + i * 33_333_333, i * 33_366_000)


def make_pose(i: int) -> VehiclePose:
    return VehiclePose(
        t_boot_ns=60_000_000_000 + i * 20_000_000,
        lat_deg=43.6532 + i * 1e-6,
        lon_deg=-79.3832 - i * 2e-6,
        alt_m=112.5 + 0.01 * i,
        rel_alt_m=3.0 + 0.01 * i,
        roll=0.05 * math.sin(i),
        pitch=-0.03 * math.cos(i),
        yaw=3.1 + 0.01 * i,  # wraps past pi
        vn=1.0,
        ve=-0.5,
        vd=0.01,
        eph_m=float("nan") if i % 3 == 0 else 0.8,
        age_ns=i * 1000,
    )


def make_detection(i: int) -> Detection:
    return Detection(
        box=(10 + i, 12, 30, 20),
        score=0.1 + 0.01 * i,
        features=FeatureScores(0.9, 0.8, 0.7, 0.6, 1.0 / 3.0),
        depth_rel_m=1.25 + i,
        major_m=0.71,
        minor_m=0.43,
        rim_depth_m=2.9,
        beyond_range=i % 2 == 1,
    )


def make_hole(k: int) -> Hole:
    return Hole(
        k, 43.65 + k * 1e-5, -79.38, 110.0, 0.4, 0.8, 3 + k, 1, 2 + k, 7, (1, 2, 3, 4), 0.7, 0.4
    )


def mavlink_packets(n: int) -> list[bytes]:
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    out = []
    for i in range(n):
        msg = mav.global_position_int_encode(i * 20, 436532000 + i, -793832000, 112500, 3000, 100, -50, 1, 31000)
        out.append(bytes(msg.pack(mav)))
    return out


def read_topics(path: Path) -> dict[str, list[Message]]:
    """Every message by topic, read with every CRC validated (chunks, data section)."""
    channels: dict[int, str] = {}
    out: dict[str, list[Message]] = {}
    for rec in StreamReader(str(path), validate_crcs=True).records:
        if type(rec).__name__ == "Channel":
            channels[rec.id] = rec.topic
        elif isinstance(rec, Message):
            out.setdefault(channels[rec.channel_id], []).append(rec)
    return out


def frames_equal(a: Frame, b: Frame) -> bool:
    return (
        a.index == b.index
        and a.t_mono_ns == b.t_mono_ns
        and a.t_sensor_ns == b.t_sensor_ns
        and a.rgb.dtype == b.rgb.dtype
        and a.depth.dtype == b.depth.dtype
        and np.array_equal(a.rgb, b.rgb)
        and np.array_equal(a.depth, b.depth)
    )


def poses_equal(a: VehiclePose | None, b: VehiclePose | None) -> bool:
    if a is None or b is None:
        return a is b
    return all(
        (x == y) or (isinstance(x, float) and math.isnan(x) and math.isnan(y))
        for x, y in zip(a.__dict__.values(), b.__dict__.values(), strict=True)
    )


# ----------------------------------------------------------------------------- round trip


def write_full_log(prefix: Path, n_frames: int = 12) -> dict[str, object]:
    """A short flight with every kind of record; returns what was written."""
    packets = mavlink_packets(25)
    poses = [make_pose(i) for i in range(20)]
    frames = [make_frame(i) for i in range(n_frames)]
    dets = {i: [make_detection(i), make_detection(i + 1)] for i in range(0, n_frames, 3)}
    holes = [make_hole(1), make_hole(2)]
    config = {"detector": {"mode": "default", "superpixels": 9}, "fps": 30}
    mount = CameraMount.from_euler_deg(0.0, -80.0, 0.0, offset_m=(0.1, 0.0, 0.05))
    with FlightLogWriter(prefix, SMALL, config=config, mount=mount) as w:
        for i, frame in enumerate(frames):
            t = T0_UNIX_NS + i * 33_333_333
            for p in packets[2 * i : 2 * i + 2]:
                assert w.write_mavlink(p, t, "GLOBAL_POSITION_INT")
            assert w.write_pose(poses[i], t - 1_000_000)
            pose = poses[i] if i % 2 == 0 else None
            t_boot = poses[i].t_boot_ns if i % 2 == 0 else None
            assert w.write_frame(frame, t, pose=pose, t_boot_ns=t_boot)
            if i in dets:
                assert w.write_detections(i, dets[i], t)
            if i == 2:
                assert w.write_holes(holes, t)
                assert w.write_health({"frames_dropped": 0, "clock_offset_ns": -12345}, t)
        stats_before_close = w.stats()
    return {
        "packets": packets[: 2 * n_frames],
        "poses": poses[:n_frames],
        "frames": frames,
        "dets": dets,
        "holes": holes,
        "config": config,
        "mount": mount,
        "stats": w.stats(),
        "stats_open": stats_before_close,
        "paths": w.paths,
    }


def test_round_trip_every_record(tmp_path: Path) -> None:
    wrote = write_full_log(tmp_path / "flight")
    paths = wrote["paths"]
    assert paths == (tmp_path / "flight_0000.mcap",)
    stats = wrote["stats"]
    assert stats.dropped == {} and stats.error is None
    assert stats.written["frames"] == 12

    # Counts, CRCs and sequences straight from the file.
    topics = read_topics(paths[0])
    counts = {t: len(m) for t, m in topics.items()}
    for t in FRAME_TOPICS:
        assert counts[t] == 12
    assert counts["/mavlink/raw"] == 24
    assert counts["/mavlink/pose"] == counts["/mavlink/location"] == 12
    assert counts["/tf"] == 1 + 12  # static mount + one world -> base_link per pose
    assert counts["/detections"] == counts["/detections/annotations"] == 4
    assert counts["/holes"] == counts["/holes/geojson"] == 1
    assert counts["/health"] == stats.written["/health"] >= 1  # daemon's + logger's
    assert counts["/camera/color/camera_info"] == stats.written["/camera/color/camera_info"]
    for topic, msgs in topics.items():
        assert [m.sequence for m in msgs] == list(range(len(msgs))), topic
        assert all(T0_UNIX_NS - 10**10 < m.log_time < time.time_ns() + 1 for m in msgs)
    assert [m.publish_time for m in topics["/camera/color/image_raw"]] == [
        T0_UNIX_NS + i * 33_333_333 for i in range(12)
    ]

    # Summary statistics agree with the content (log_info checks them and the CRC).
    info = log_info(paths[0])
    assert info.frames == 12 and info.dropped_frames == () and info.frame_index_gaps == ()
    assert {t: ti.count for t, ti in info.topics.items()} == counts
    assert all(ti.missing_sequences == () for ti in info.topics.values())
    assert info.topics["/camera/color/image_raw"].schema == "foxglove.RawImage"
    assert info.topics["/detections"].message_encoding == "json"
    assert json.loads(info.metadata["holescan.config"]["detector"]) == wrote["config"]["detector"]
    assert info.metadata["holescan"]["version"] == "0.1.0"
    assert float(info.metadata["holescan.camera"]["fx"]) == SMALL.fx
    assert float(info.metadata["holescan.world_origin"]["lat_deg"]) == wrote["poses"][0].lat_deg
    with open(paths[0], "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == sum(counts.values())
    assert {s.encoding for s in summary.schemas.values()} == {"protobuf", "jsonschema"}
    for s in summary.schemas.values():
        if s.encoding == "jsonschema":
            assert json.loads(s.data)["type"] == "object"

    # Typed records come back exactly.
    recs = list(read_flight_log(paths[0]))
    frames = [r for r in recs if isinstance(r, LoggedFrame)]
    assert [r.sequence for r in frames] == list(range(12))
    for r, f in zip(frames, wrote["frames"], strict=True):
        assert frames_equal(r.frame, f)
        assert r.frame.rgb.flags.writeable and r.frame.depth.dtype == np.uint16
    for i, r in enumerate(frames):
        assert r.t_unix_ns == T0_UNIX_NS + i * 33_333_333
        assert poses_equal(r.pose, wrote["poses"][i] if i % 2 == 0 else None)
        assert r.t_boot_ns == (wrote["poses"][i].t_boot_ns if i % 2 == 0 else None)
    poses = [r for r in recs if isinstance(r, LoggedPose)]
    assert all(poses_equal(r.pose, p) for r, p in zip(poses, wrote["poses"], strict=True))
    mav = [r for r in recs if isinstance(r, LoggedMavlink)]
    assert [r.packet for r in mav] == wrote["packets"]
    assert {(r.msgid, r.sysid, r.compid, r.name) for r in mav} == {
        (33, 1, 1, "GLOBAL_POSITION_INT")
    }
    dets = [r for r in recs if isinstance(r, LoggedDetections)]
    assert {r.frame_index: list(r.detections) for r in dets} == wrote["dets"]
    assert [r.t_unix_ns for r in dets] == [T0_UNIX_NS + i * 33_333_333 for i in (0, 3, 6, 9)]
    (holes,) = [r for r in recs if isinstance(r, LoggedHoles)]
    assert list(holes.as_holes()) == wrote["holes"]
    health = [r.values for r in recs if isinstance(r, LoggedHealth)]
    assert {"source": "daemon", "frames_dropped": 0, "clock_offset_ns": -12345} in health
    cals = [r for r in recs if isinstance(r, LoggedCalibration)]
    assert cals and all(c.camera == SMALL for c in cals)


def test_foxglove_messages_decode_with_generic_reader(tmp_path: Path) -> None:
    wrote = write_full_log(tmp_path / "fox", n_frames=4)
    protobuf_topics = [
        "/camera/color/image_raw",
        "/camera/depth/image_raw",
        "/camera/color/camera_info",
        "/tf",
        "/mavlink/location",
        "/detections/annotations",
        "/holes/geojson",
    ]
    seen: dict[str, list[object]] = {}
    with open(wrote["paths"][0], "rb") as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages(topics=protobuf_topics):
            seen.setdefault(channel.topic, []).append(msg)
    color, depth = seen["/camera/color/image_raw"][0], seen["/camera/depth/image_raw"][0]
    assert (color.encoding, color.step, color.width, color.height) == ("rgb8", 240, 80, 60)
    assert (depth.encoding, depth.step) == ("16UC1", 160)
    d = np.frombuffer(depth.data, "<u2").reshape(60, 80)
    assert np.array_equal(d, wrote["frames"][0].depth)
    assert color.frame_id == depth.frame_id == "camera"
    assert color.timestamp.seconds * 10**9 + color.timestamp.nanos == T0_UNIX_NS
    cal = seen["/camera/color/camera_info"][0]
    assert list(cal.K) == [SMALL.fx, 0, SMALL.cx, 0, SMALL.fy, SMALL.cy, 0, 0, 1]
    mount, *vehicle = seen["/tf"]
    assert (mount.parent_frame_id, mount.child_frame_id) == ("base_link", "camera")
    assert (mount.translation.x, mount.translation.y, mount.translation.z) == (0.1, 0.0, -0.05)
    # Camera z (optical axis) in base_link FLU: 80 deg down from the nose.
    q = mount.rotation
    z_axis = np.array(
        [2 * (q.x * q.z + q.w * q.y), 2 * (q.y * q.z - q.w * q.x), 1 - 2 * (q.x**2 + q.y**2)]
    )
    assert np.allclose(z_axis, [math.cos(math.radians(80)), 0, -math.sin(math.radians(80))])
    assert (vehicle[0].parent_frame_id, vehicle[0].child_frame_id) == ("world", "base_link")
    p0, p1 = wrote["poses"][0], wrote["poses"][1]
    enu = pymap3d.geodetic2enu(p1.lat_deg, p1.lon_deg, p1.alt_m, p0.lat_deg, p0.lon_deg, p0.alt_m)
    t1 = vehicle[1].translation
    assert (t1.x, t1.y, t1.z) == pytest.approx(tuple(float(v) for v in enu), abs=1e-9)
    assert t1.x < 0 < t1.y  # moved west and north
    # Body x (nose) in ENU: heading = yaw clockwise from north.
    q = vehicle[1].rotation
    x_axis = np.array(
        [1 - 2 * (q.y**2 + q.z**2), 2 * (q.x * q.y + q.w * q.z), 2 * (q.x * q.z - q.w * q.y)]
    )
    yaw, pitch = p1.yaw, p1.pitch
    nose_ned = [math.cos(yaw) * math.cos(pitch), math.sin(yaw) * math.cos(pitch), -math.sin(pitch)]
    assert np.allclose(x_axis, [nose_ned[1], nose_ned[0], -nose_ned[2]], atol=1e-9)
    fix = seen["/mavlink/location"][1]
    assert (fix.latitude, fix.longitude) == (43.6532 + 1e-6, -79.3832 - 2e-6)
    assert fix.position_covariance[0] == pytest.approx(0.64)
    ann = seen["/detections/annotations"][0]
    assert len(ann.points) == 2 and ann.points[0].type == 2  # LINE_LOOP
    assert [(p.x, p.y) for p in ann.points[0].points] == [
        (9.5, 11.5),
        (39.5, 11.5),
        (39.5, 31.5),
        (9.5, 31.5),
    ]
    assert ann.texts[0].text == "0.10"
    geo = json.loads(seen["/holes/geojson"][0].geojson)
    assert geo["features"][0]["geometry"]["coordinates"] == [-79.38, 43.65 + 1e-5]
    assert geo["features"][1]["properties"]["id"] == 2
