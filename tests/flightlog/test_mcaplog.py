"""The MCAP flight log: write -> read round trips, rotation, drops, truncation and recovery,
a writer killed with SIGKILL, garbage input, the ``holescan log`` verbs, and the writer's
speed at 30 fps."""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pymap3d
import pytest
import zstandard
from mcap.reader import make_reader
from mcap.records import Footer, Message
from mcap.stream_reader import StreamReader
from mcap_protobuf.decoder import DecoderFactory

from holescan.detect import CameraIntrinsics, Detection, FeatureScores, Frame
from holescan.errors import HolescanError, InputError
from holescan.flightlog import (
    FlightLogWriter,
    LoggedCalibration,
    LoggedDetections,
    LoggedFrame,
    LoggedHealth,
    LoggedHoles,
    LoggedMavlink,
    LoggedPose,
    LogOptions,
    McapSource,
    decode_detection,
    detection_json,
    log_file_path,
    log_info,
    read_flight_log,
    recover_log,
)
from holescan.flightlog.errors import FlightLogError, TruncatedLogError
from holescan.geotag import CameraMount, Hole, VehiclePose
from holescan.link import mavlink as mavlink2

REPO = Path(__file__).resolve().parents[2]
SMALL = CameraIntrinsics(80, 60, 71.3, 71.3, 39.5, 29.5)
VGA = CameraIntrinsics.xtion()
T0_UNIX_NS = 1_750_000_000_123_456_789
FRAME_TOPICS = ("/camera/frame_info", "/camera/color/image_raw", "/camera/depth/image_raw")
_log = logging.getLogger(__name__)

#: The layout of older logs (raw images): what these container tests were sized for.
RAW: dict[str, Any] = {"color": "raw", "depth": "raw"}


def make_frame(i: int, cam: CameraIntrinsics = SMALL) -> Frame:
    """Frame ``i`` of a deterministic synthetic sequence (content depends on ``i``)."""
    rng = np.random.default_rng(1000 + i)
    h, w = cam.height, cam.width
    _yy, xx = np.mgrid[0:h, 0:w]
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
        relative_brightness=0.23 + 0.01 * i if i % 2 == 1 else None,
        p_hole=None if i % 3 == 2 else 0.5 + 0.01 * i,  # None: a paper-mode detection
    )


def make_hole(k: int) -> Hole:
    return Hole(
        k, 43.65 + k * 1e-5, -79.38, 110.0, 0.4, 0.8, 3 + k, 1, 2 + k, 7, (1, 2, 3, 4), 0.7, 0.4
    )


def mavlink_packets(n: int) -> list[bytes]:
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    out = []
    for i in range(n):
        msg = mav.global_position_int_encode(
            i * 20, 436532000 + i, -793832000, 112500, 3000, 100, -50, 1, 31000
        )
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


def write_full_log(
    prefix: Path, n_frames: int = 12, options: LogOptions | None = None
) -> dict[str, object]:
    """A short flight with every kind of record; returns what was written."""
    packets = mavlink_packets(25)
    poses = [make_pose(i) for i in range(20)]
    frames = [make_frame(i) for i in range(n_frames)]
    dets = {i: [make_detection(i), make_detection(i + 1)] for i in range(0, n_frames, 3)}
    holes = [make_hole(1), make_hole(2)]
    config = {"detector": {"mode": "default", "superpixels": 9}, "fps": 30}
    mount = CameraMount.from_euler_deg(0.0, -80.0, 0.0, offset_m=(0.1, 0.0, 0.05))
    with FlightLogWriter(prefix, SMALL, config=config, mount=mount, options=options) as w:
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


def jpeg_round_trip(rgb: np.ndarray, quality: int) -> np.ndarray:
    """What OpenCV's JPEG codec gives back for ``rgb`` at ``quality`` (RGB in, RGB out)."""
    bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, quality])
    assert ok
    return np.asarray(cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB))


#: Every chunk compression with every image codec pair worth telling apart: the layout of
#: older logs (raw), the default (JPEG + zstd), and the lossless ones.
IMAGE_MODES = [("raw", "raw"), ("jpeg", "zstd"), ("png", "zstd"), ("jpeg", "png"), ("png", "raw")]


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
@pytest.mark.parametrize(("color", "depth"), IMAGE_MODES)
def test_round_trip_every_record(tmp_path: Path, compression: str, color: str, depth: str) -> None:
    options = LogOptions(compression=compression, color=color, depth=depth, jpeg_quality=85)  # type: ignore[arg-type]
    wrote = write_full_log(tmp_path / "flight", options=options)
    paths = wrote["paths"]
    assert paths == (tmp_path / "flight_0000.mcap",)
    stats = wrote["stats"]
    assert stats.dropped == {}
    assert stats.error is None
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
    assert info.frames == 12
    assert info.dropped_frames == ()
    assert info.frame_index_gaps == ()
    assert {t: ti.count for t, ti in info.topics.items()} == counts
    assert all(ti.missing_sequences == () for ti in info.topics.values())
    schema = {"raw": "foxglove.RawImage"}
    assert info.topics["/camera/color/image_raw"].schema == schema.get(
        color, "foxglove.CompressedImage"
    )
    assert info.topics["/camera/depth/image_raw"].schema == schema.get(
        depth, "foxglove.CompressedImage"
    )
    assert info.topics["/detections"].message_encoding == "json"
    assert json.loads(info.metadata["holescan.config"]["detector"]) == wrote["config"]["detector"]
    assert info.metadata["holescan"]["version"] == "0.1.0"
    assert float(info.metadata["holescan.camera"]["fx"]) == SMALL.fx
    assert float(info.metadata["holescan.world_origin"]["lat_deg"]) == wrote["poses"][0].lat_deg
    with open(paths[0], "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    assert summary.statistics is not None
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
        if color == "jpeg":  # lossy: exactly what the JPEG codec gives back
            f = dataclasses.replace(f, rgb=jpeg_round_trip(f.rgb, 85))
        assert frames_equal(r.frame, f)
        assert r.frame.rgb.flags.writeable
        assert r.frame.depth.dtype == np.uint16
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
    assert cals
    assert all(c.camera == SMALL for c in cals)


def test_detection_p_hole_and_brightness_round_trip(tmp_path: Path) -> None:
    """A detection's calibrated p_hole and relative brightness come back from the log."""
    det = dataclasses.replace(make_detection(1), p_hole=0.973, relative_brightness=0.21)
    paper = dataclasses.replace(make_detection(2), p_hole=None, relative_brightness=None)
    with FlightLogWriter(tmp_path / "f", SMALL) as w:
        assert w.write_detections(4, [det, paper], T0_UNIX_NS)
    (got,) = [r for r in read_flight_log(w.paths[0]) if isinstance(r, LoggedDetections)]
    assert list(got.detections) == [det, paper]
    assert got.detections[0].p_hole == 0.973 and got.detections[0].relative_brightness == 0.21
    # a log written before the fields existed reads back with None
    old = {
        k: v for k, v in detection_json(det).items() if k not in ("p_hole", "relative_brightness")
    }
    assert decode_detection(old) == dataclasses.replace(det, p_hole=None, relative_brightness=None)


def test_foxglove_messages_decode_with_generic_reader(tmp_path: Path) -> None:
    wrote = write_full_log(
        tmp_path / "fox", n_frames=4, options=LogOptions(color="raw", depth="raw")
    )
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
    assert len(ann.points) == 2
    assert ann.points[0].type == 2
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


@pytest.mark.parametrize(("color", "depth"), [("jpeg", "zstd"), ("png", "png")])
def test_compressed_images_describe_themselves(tmp_path: Path, color: str, depth: str) -> None:
    """A generic protobuf reader gets ``foxglove.CompressedImage`` messages whose format
    says how to decode them without holescan: OpenCV for jpeg/png, zstd for the depth."""
    options = LogOptions(color=color, depth=depth)  # type: ignore[arg-type]
    wrote = write_full_log(tmp_path / "fox", n_frames=2, options=options)
    topics = ["/camera/color/image_raw", "/camera/depth/image_raw"]
    seen: dict[str, list[object]] = {}
    with open(wrote["paths"][0], "rb") as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages(topics=topics):
            seen.setdefault(channel.topic, []).append(msg)
    c, d = seen["/camera/color/image_raw"][0], seen["/camera/depth/image_raw"][0]
    assert type(c).__name__ == type(d).__name__ == "CompressedImage"
    assert c.frame_id == d.frame_id == "camera"
    assert c.timestamp.seconds * 10**9 + c.timestamp.nanos == T0_UNIX_NS
    frame = wrote["frames"][0]
    assert c.format == color
    bgr = cv2.imdecode(np.frombuffer(c.data, np.uint8), cv2.IMREAD_COLOR)
    want = jpeg_round_trip(frame.rgb, 90) if color == "jpeg" else frame.rgb
    assert np.array_equal(bgr[..., ::-1], want)
    if depth == "zstd":
        assert d.format == "16UC1; zstd; 80x60"
        raw = zstandard.ZstdDecompressor().decompress(d.data)
        got = np.frombuffer(raw, "<u2").reshape(60, 80)
    else:
        assert d.format == "png"
        got = cv2.imdecode(np.frombuffer(d.data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert got.dtype == np.uint16
    assert np.array_equal(got, frame.depth)


# ------------------------------------------------------------------------------- rotation


def test_rotation_by_size_keeps_sequences_across_files(tmp_path: Path) -> None:
    opts = LogOptions(chunk_size=8 * 1024, max_file_bytes=60 * 1024, **RAW)
    frames = [make_frame(i) for i in range(40)]
    with FlightLogWriter(tmp_path / "rot.mcap", SMALL, options=opts) as w:
        for i, f in enumerate(frames):
            assert w.write_frame(f, T0_UNIX_NS + i)
            assert w.write_pose(make_pose(i), T0_UNIX_NS + i)
    paths = w.paths
    assert len(paths) >= 3
    assert [p.name for p in paths] == [f"rot_{k:04d}.mcap" for k in range(len(paths))]
    assert paths == tuple(log_file_path(tmp_path / "rot", k) for k in range(len(paths)))
    per_file = []
    for p in paths:
        info = log_info(p)  # each file is complete on its own: summary, CRCs
        assert info.truncated == ()
        assert "holescan.camera" in info.metadata
        assert info.topics["/camera/color/camera_info"].count >= 1  # each file has calibration
        assert info.topics["/tf"].count >= 1  # and the static mount
        assert os.path.getsize(p) < opts.max_file_bytes + 2 * 15_000  # one item past the limit
        per_file.append(info.frames)
    assert sum(per_file) == 40
    assert all(n > 0 for n in per_file)
    info = log_info(paths)
    assert info.frames == 40
    assert info.dropped_frames == ()
    assert info.metadata["holescan.world_origin"]["lat_deg"] == repr(make_pose(0).lat_deg)
    for ti in info.topics.values():
        assert ti.first_sequence == 0
        assert ti.missing_sequences == ()
        assert ti.last_sequence == ti.count - 1
    got = [r.frame for r in read_flight_log(paths, kinds={LoggedFrame})]
    assert len(got) == 40
    assert all(frames_equal(a, b) for a, b in zip(got, frames, strict=True))
    with McapSource(paths) as src:
        assert src.camera == SMALL
        assert [f.index for f in src] == list(range(40))


def test_rotation_by_age(tmp_path: Path) -> None:
    opts = LogOptions(max_file_s=0.25, sync_interval_s=0.1)
    with FlightLogWriter(tmp_path / "age", SMALL, options=opts) as w:
        for i in range(30):
            w.write_frame(make_frame(i), T0_UNIX_NS + i)
            time.sleep(0.03)
    assert len(w.paths) >= 3
    assert log_info(w.paths).frames == 30


def test_existing_file_is_never_overwritten(tmp_path: Path) -> None:
    (tmp_path / "x_0000.mcap").write_bytes(b"precious")
    with pytest.raises(FlightLogError, match="exists"):
        FlightLogWriter(tmp_path / "x", SMALL)
    assert (tmp_path / "x_0000.mcap").read_bytes() == b"precious"
    with pytest.raises(FlightLogError, match="cannot create"):
        FlightLogWriter(tmp_path / "no" / "such" / "dir", SMALL)


def test_bad_frames_and_holes_are_refused(tmp_path: Path) -> None:
    with FlightLogWriter(tmp_path / "bad", SMALL) as w:
        good = make_frame(0)
        with pytest.raises(ValueError, match="uint16"):
            w.write_frame(Frame(0, good.rgb, good.depth.astype(np.float32), 0, 0), 0)  # type: ignore[arg-type]
        with pytest.raises(ValueError, match=r"\(60, 80, 3\)"):
            w.write_frame(Frame(0, good.rgb[:10], good.depth, 0, 0), 0)
        with pytest.raises(ValueError, match="lat_deg"):
            w.write_holes([{"id": 1}], 0)


# ---------------------------------------------------------------------------------- drops


def test_full_queue_drops_and_leaves_sequence_gaps(tmp_path: Path) -> None:
    opts = LogOptions(max_queued_frames=2)
    frames = [make_frame(i, VGA) for i in range(3)]
    accepted = []
    with FlightLogWriter(tmp_path / "drop", VGA, options=opts) as w:
        for i in range(39):  # a burst far faster than the writer (~15 ms per VGA frame)
            accepted.append(w.write_frame(frames[i % 3], T0_UNIX_NS + i))
        deadline = time.monotonic() + 10
        while w.stats().queue_depth and time.monotonic() < deadline:
            time.sleep(0.01)
        accepted.append(w.write_frame(frames[0], T0_UNIX_NS + 39))  # drops become a gap
        assert accepted[-1]
    stats = w.stats()
    dropped = [i for i, ok in enumerate(accepted) if not ok]
    assert dropped, "the burst should overflow a 2-frame queue"
    assert stats.dropped["frames"] == len(dropped)
    assert stats.written["frames"] == 40 - len(dropped)
    assert stats.frames_queued_max == 2
    info = log_info(w.paths)
    assert info.frames == 40 - len(dropped)
    assert list(info.dropped_frames) == dropped
    assert list(info.topics["/camera/color/image_raw"].missing_sequences) == dropped
    seqs = [r.sequence for r in read_flight_log(w.paths, kinds={LoggedFrame})]
    assert seqs == [i for i, ok in enumerate(accepted) if ok]
    logger = [r.values for r in read_flight_log(w.paths, kinds={LoggedHealth})]
    assert logger[-1]["source"] == "logger"  # the final record, written at close
    assert logger[-1]["dropped"] == {"frames": len(dropped)}
    assert info.logger_dropped == {"frames": len(dropped)}


# ------------------------------------------------------------------ truncation, recovery


@pytest.fixture(scope="module")
def chunked_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Frame]]:
    """A complete log of 30 small frames in many small chunks."""
    prefix = tmp_path_factory.mktemp("chunked") / "c"
    frames = [make_frame(i) for i in range(30)]
    with FlightLogWriter(prefix, SMALL, options=LogOptions(chunk_size=20_000, **RAW)) as w:
        for i, f in enumerate(frames):
            w.write_frame(f, T0_UNIX_NS + i * 33_333_333)
            w.write_mavlink(mavlink_packets(1)[0], T0_UNIX_NS + i * 33_333_333)
    (path,) = w.paths
    return path, frames


def test_truncated_files_read_up_to_the_last_chunk_and_recover(
    chunked_log: tuple[Path, list[Frame]], tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path, frames = chunked_log
    data = path.read_bytes()
    full = log_info(path)
    previous = -1
    for cut in (12, 200, len(data) // 4, len(data) // 2, len(data) - 5000, len(data) - 40):
        cut_path = tmp_path / f"cut{cut}.mcap"
        cut_path.write_bytes(data[:cut])
        with caplog.at_level(logging.WARNING):
            got = [r.frame for r in read_flight_log(cut_path, kinds={LoggedFrame})]
        assert "recover" in caplog.text
        caplog.clear()
        # A prefix of the flight, exactly: nothing invented, nothing reordered.
        assert all(frames_equal(a, b) for a, b in zip(got, frames, strict=False))
        assert len(got) >= previous
        previous = len(got)
        with pytest.raises(TruncatedLogError, match="recover"):
            list(read_flight_log(cut_path, strict=True))
        with pytest.raises(TruncatedLogError, match=f"of {cut}"):
            log_info(cut_path)
        partial = log_info(cut_path, allow_truncated=True)
        assert partial.truncated
        assert partial.frames == len(got)
        if cut <= 200:  # cut inside the header/metadata: nothing to recover yet
            continue
        out = tmp_path / f"rec{cut}.mcap"
        report = recover_log(cut_path, out)
        assert not report.source_complete
        assert report.frames == len(got)
        assert report.bytes_total == cut
        assert report.bytes_used <= cut
        info = log_info(out)  # a valid, indexed file: summary and CRCs check out
        assert info.frames == len(got)
        assert info.message_count == report.messages == sum(report.topics.values())
        assert all(ti.missing_sequences == () for ti in info.topics.values())
        assert info.metadata["holescan.camera"] == full.metadata["holescan.camera"]
        again = [r.frame for r in read_flight_log(out, kinds={LoggedFrame}, strict=True)]
        assert len(again) == len(got)
        assert all(frames_equal(a, b) for a, b in zip(again, got, strict=True))
        with open(out, "rb") as f:
            stats = make_reader(f).get_summary().statistics
        assert stats.message_count == report.messages
    assert previous >= 25  # cutting off the summary loses at most the last chunk


def test_recovering_a_complete_file_keeps_everything(
    chunked_log: tuple[Path, list[Frame]], tmp_path: Path
) -> None:
    path, _ = chunked_log
    report = recover_log(path, tmp_path / "same.mcap")
    assert report.source_complete
    assert report.stop_reason is None
    assert report.bytes_used == report.bytes_total
    a, b = log_info(path), log_info(tmp_path / "same.mcap")
    assert {t: x.count for t, x in a.topics.items()} == {t: x.count for t, x in b.topics.items()}
    with pytest.raises(HolescanError, match="exists"):
        recover_log(path, tmp_path / "same.mcap")


def test_damaged_chunk_costs_that_chunk_only(
    chunked_log: tuple[Path, list[Frame]], tmp_path: Path
) -> None:
    path, frames = chunked_log
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF  # one flipped bit pattern in the middle of the data
    bad = tmp_path / "flipped.mcap"
    bad.write_bytes(bytes(data))
    got = [r.frame for r in read_flight_log(bad, kinds={LoggedFrame})]
    assert len(frames) - 2 <= len(got) < len(frames)  # a 20 kB chunk holds 1-2 frames
    assert got[-1].index == frames[-1].index  # reading went on after the damage
    assert all(frames_equal(g, frames[g.index]) for g in got)
    with pytest.raises(TruncatedLogError, match=r"chunk CRC mismatch.*messages lost"):
        log_info(bad)
    report = recover_log(bad, tmp_path / "fixed.mcap")
    assert report.frames == len(got)
    assert report.source_complete
    assert len(report.damaged) == 1
    assert report.messages_lost == report.damaged[0].messages > 0
    assert log_info(tmp_path / "fixed.mcap").frames == len(got)


def test_summary_and_data_section_crcs_are_checked(
    chunked_log: tuple[Path, list[Frame]], tmp_path: Path
) -> None:
    path, _ = chunked_log
    data = path.read_bytes()
    footer = next(r for r in StreamReader(str(path)).records if isinstance(r, Footer))
    # A byte of the summary offsets (parsed by no one): only the summary CRC notices.
    bad = bytearray(data)
    bad[footer.summary_offset_start + 1 + 8 + 1 + 7] ^= 0x01
    (tmp_path / "summary.mcap").write_bytes(bytes(bad))
    with pytest.raises(FlightLogError, match="summary section CRC"):
        log_info(tmp_path / "summary.mcap")
    # A byte of the config metadata (outside any chunk): only the data section CRC notices.
    bad = bytearray(data)
    at = data.index(b"holescan.mount")
    bad[at + 1] ^= 0x20  # "holescan.mount" -> "hOlescan.mount"
    (tmp_path / "meta.mcap").write_bytes(bytes(bad))
    with pytest.raises(TruncatedLogError, match="CRC"):
        log_info(tmp_path / "meta.mcap")


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"", "empty file"),
        (b"GIF89a" + bytes(range(256)) * 40, "not an MCAP file"),
        (np.random.default_rng(3).bytes(50_000), "not an MCAP file"),
    ],
)
def test_garbage_files_give_a_clear_error(tmp_path: Path, content: bytes, message: str) -> None:
    bad = tmp_path / "garbage.mcap"
    bad.write_bytes(content)
    with pytest.raises(FlightLogError, match=message):
        list(read_flight_log(bad))
    with pytest.raises(FlightLogError, match=message):
        log_info(bad)
    with pytest.raises(FlightLogError, match=message):
        recover_log(bad, tmp_path / "out.mcap")
    assert not (tmp_path / "out.mcap").exists()
    assert not list(tmp_path.glob(".*part"))
    with pytest.raises(FlightLogError, match="no such file"):
        log_info(tmp_path / "missing.mcap")


# ------------------------------------------------------------------------------------ CLI


def test_cli_log_info_and_recover(
    chunked_log: tuple[Path, list[Frame]],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    from holescan import cli

    main = cli.main
    path, _ = chunked_log
    assert main(["log", "info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "frames: 30, dropped by logger: 0" in out
    assert "/camera/color/image_raw: 30 x foxglove.RawImage" in out

    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: os.path.getsize(path) // 2])
    assert main(["log", "info", str(cut)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "file ends inside a record" in err[0]
    assert "recover" in err[0]

    assert main(["log", "recover", str(cut)]) == 0
    assert "frames recovered" in capsys.readouterr().out
    assert log_info(tmp_path / "cut-recovered.mcap").frames > 0
    assert main(["log", "recover", str(cut), "--out", str(tmp_path / "r2.mcap")]) == 0
    capsys.readouterr()

    garbage = tmp_path / "g.mcap"
    garbage.write_bytes(b"\x00" * 100)
    for argv in (["log", "info", str(garbage)], ["log", "recover", str(tmp_path / "none")]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1
        assert err[0].startswith("holescan log: error:")


# ------------------------------------------------------------- crash safety and speed

_CHILD = textwrap.dedent(
    """
    import sys, time
    from holescan.flightlog import FlightLogWriter
    from tests.flightlog.test_mcaplog import VGA, make_frame

    w = FlightLogWriter(sys.argv[1], VGA)
    t0 = time.monotonic()
    for i in range(100_000):
        delay = t0 + i / 30 - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        ok = w.write_frame(make_frame(i, VGA), time.time_ns())
        st = w.stats()
        print(i, int(ok), st.written.get("frames", 0), st.frames_synced, flush=True)
    """
)


def test_sigkilled_writer_loses_at_most_about_a_second(tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(
        [sys.executable, "-c", _CHILD, str(tmp_path / "killed")],
        stdout=subprocess.PIPE,
        text=True,
        cwd=REPO,
        env=env,
    )
    assert proc.stdout is not None
    reports: list[tuple[int, int, int, int]] = []
    t_first = None
    try:
        while True:
            line = proc.stdout.readline()
            assert line, f"writer process died: exit {proc.poll()}"
            reports.append(tuple(int(v) for v in line.split()))  # type: ignore[arg-type]
            t_first = t_first or time.monotonic()
            if time.monotonic() - t_first >= 3.0:
                break
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.kill()
        rest = proc.stdout.read()
        proc.wait(timeout=10)
    reports += [tuple(int(v) for v in ln.split()) for ln in rest.splitlines() if ln.strip()]
    assert proc.returncode == -signal.SIGKILL
    enqueued = sum(ok for _, ok, _, _ in reports)
    assert enqueued == len(reports) >= 30  # nothing dropped (a loaded machine writes fewer)
    _, _, written, synced = reports[-1]

    (path,) = tmp_path.glob("killed_*.mcap")
    with pytest.raises(TruncatedLogError):
        log_info(path)
    report = recover_log(path, tmp_path / "recovered.mcap")
    got = [r.frame for r in read_flight_log(report.dst, kinds={LoggedFrame}, strict=True)]
    assert [f.index for f in got] == list(range(len(got)))
    for k in (0, len(got) // 2, len(got) - 1):  # spot-check exact pixels (regenerating is slow)
        want = make_frame(k, VGA)  # as flights log it: colour through JPEG q90, depth exact
        assert frames_equal(got[k], dataclasses.replace(want, rgb=jpeg_round_trip(want.rgb, 90)))
    lost = enqueued - len(got)
    print(
        f"SIGKILL after {enqueued} frames: {len(got)} recovered, lost {lost} "
        f"({lost / 30:.2f} s); writer had reported {written} written, {synced} fsynced"
    )
    # every frame fsynced survived; frames written after the last fsync may sit in the chunk
    # still being built in the writer's memory (lost with it: at most the open chunk)
    assert written >= synced and len(got) >= synced
    assert lost <= 30  # at most ~1 s at 30 fps


def test_paced_vga_frames_are_all_written_and_enqueueing_never_stalls(tmp_path: Path) -> None:
    """3 s of VGA frames at 30 fps. How fast the writer is (ms per frame, queue depth) is
    measured by ``benchmarks/bench_log_writer.py``, not asserted here: a busy machine makes
    timings fail."""
    frames = [make_frame(i, VGA) for i in range(6)]
    calls = []
    with FlightLogWriter(tmp_path / "speed", VGA) as w:
        t0 = time.monotonic()
        for i in range(90):
            delay = t0 + i / 30 - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            c0 = time.perf_counter()
            w.write_frame(frames[i % 6], time.time_ns())
            calls.append(time.perf_counter() - c0)
    final = w.stats()
    assert final.dropped == {}
    assert final.written["frames"] == 90
    # write_frame only stamps and queues (~0.1 ms): 50 ms, hundreds of times that, is a
    # stall (waiting for the writer), not a slow machine.
    assert max(calls) < 0.05


_DISK_FULL_CHILD = textwrap.dedent(
    """
    import json, resource, signal, sys, time
    from holescan.flightlog import FlightLogError, FlightLogWriter, LogOptions
    from tests.flightlog.test_mcaplog import SMALL, make_frame

    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # writes past the limit fail with EFBIG
    resource.setrlimit(resource.RLIMIT_FSIZE, (300_000, 300_000))
    options = LogOptions(chunk_size=50_000, color="raw", depth="raw")
    w = FlightLogWriter(sys.argv[1], SMALL, options=options)
    accepted = []
    for i in range(200):
        accepted.append(w.write_frame(make_frame(i), i))
        time.sleep(0.002)
    error = None
    try:
        w.close()
    except FlightLogError as err:
        error = str(err)
    print(json.dumps({"accepted": accepted, "error": error, "stats_error": w.stats().error}))
    """
)


def test_write_failure_keeps_capture_running_and_is_reported(tmp_path: Path) -> None:
    """A file-size limit (as a full disk) stops the writer thread; write_frame keeps
    returning at once (False) and close() raises; what was written is recoverable."""
    out = subprocess.run(
        [sys.executable, "-c", _DISK_FULL_CHILD, str(tmp_path / "full")],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        timeout=120,
        check=True,
    )
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["error"] is not None
    assert "flight log writer failed" in result["error"]
    assert result["stats_error"] is not None
    accepted = result["accepted"]
    assert accepted[0]
    assert not accepted[-1]  # after the failure frames are refused, not queued forever
    (path,) = tmp_path.glob("full_*.mcap")
    report = recover_log(path, tmp_path / "saved.mcap")
    assert report.frames >= 8  # 300 kB of 24 kB frames, less the chunk cut by the limit
    got = [r.frame for r in read_flight_log(report.dst, kinds={LoggedFrame})]
    assert all(frames_equal(a, make_frame(a.index)) for a in got)


def test_detection_opening_centre_round_trips(tmp_path: Path) -> None:
    """The opening's centre, rim normal and rim seen come back; older logs give None."""
    det = dataclasses.replace(
        make_detection(1), opening_m=(0.41, -0.2, 2.93), rim_normal=(0.1, 0.0, -0.995), rim_seen=0.8
    )
    with FlightLogWriter(tmp_path / "f", SMALL) as w:
        assert w.write_detections(4, [det], T0_UNIX_NS)
    (got,) = [r for r in read_flight_log(w.paths[0]) if isinstance(r, LoggedDetections)]
    assert list(got.detections) == [det]
    old = {
        k: v
        for k, v in detection_json(det).items()
        if k not in ("opening_m", "rim_normal", "rim_seen")
    }
    assert decode_detection(old) == dataclasses.replace(
        det, opening_m=None, rim_normal=None, rim_seen=None
    )
    with pytest.raises(InputError, match="3 numbers"):
        decode_detection({**detection_json(det), "opening_m": [1.0, 2.0]})


def test_detection_plane_reading_and_hole_votes_round_trip(tmp_path: Path) -> None:
    """What a view read inside against the rim plane, and a hole's plane views, come back
    from the log; logs from before read with None and 0 (no vote)."""
    det = dataclasses.replace(make_detection(1), inside_on_plane=0.31, inside_behind=0.0)
    hole = Hole(
        7, 45.0, 7.0, 100.0, 0.3, 0.9, 9, 0, 2 * 10**9, 3, (0, 0, 9, 9), 0.7, 0.5,
        p_hole=0.97, views=5, plane_views=4, surface_views=3, behind_views=0,
    )  # fmt: skip
    with FlightLogWriter(tmp_path / "f", SMALL) as w:
        assert w.write_detections(4, [det], T0_UNIX_NS)
        assert w.write_holes([hole], T0_UNIX_NS)
    recs = list(read_flight_log(w.paths[0]))
    (got,) = [r for r in recs if isinstance(r, LoggedDetections)]
    assert list(got.detections) == [det]
    (holes,) = [r for r in recs if isinstance(r, LoggedHoles)]
    assert holes.as_holes() == (hole,)
    old = {
        k: v
        for k, v in detection_json(det).items()
        if k not in ("inside_on_plane", "inside_behind")
    }
    assert decode_detection(old) == dataclasses.replace(
        det, inside_on_plane=None, inside_behind=None
    )
    old_hole = {
        k: v
        for k, v in holes.holes[0].items()
        if k not in ("plane_views", "surface_views", "behind_views")
    }
    (back,) = LoggedHoles(0, 0, (old_hole,)).as_holes()
    assert back == dataclasses.replace(hole, plane_views=0, surface_views=0, behind_views=0)
    with pytest.raises(InputError, match="fraction"):
        decode_detection({**detection_json(det), "inside_on_plane": 1.5})
