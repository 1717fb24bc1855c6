"""A log's chunk index (from its summary, or walked when it was cut off), one chunk read by
its byte range, the flight-log decoder on those chunks, and the one MAVLink decoder shared
by the live link and log replay."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from mcap.records import Channel, Message

from holescan.detect import CameraIntrinsics, Frame
from holescan.flightlog import (
    FlightLogWriter,
    LoggedFrame,
    LogOptions,
    decode_messages,
    errors_from_metadata,
    mount_from_metadata,
    read_chunk,
    read_flight_log,
    read_log_layout,
)
from holescan.flightlog.errors import ChunkDamagedError, FlightLogError
from holescan.flightlog.format import read_summary
from holescan.flightlog.scan import ScanState, scan_records
from holescan.geotag import CameraMount, ErrorModel
from holescan.link import (
    AttitudeSample,
    GpsFix,
    PositionSample,
    TelemetryReplay,
    is_autopilot_heartbeat,
    telemetry_sample,
)
from holescan.link import mavlink as mavlink2

CAM = CameraIntrinsics(80, 60, 71.3, 71.3, 39.5, 29.5)
T0 = 1_750_000_000_000_000_000


def frame(i: int) -> Frame:
    rng = np.random.default_rng(i)
    rgb = rng.integers(0, 255, (60, 80, 3), dtype=np.uint8)
    depth = rng.integers(500, 4000, (60, 80), dtype=np.uint16)
    return Frame(index=i, rgb=rgb, depth=depth, t_mono_ns=i * 10**8, t_sensor_ns=i * 10**8)


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    prefix = tmp_path_factory.mktemp("chunks") / "c"
    mount = CameraMount.from_euler_deg(0.0, -80.0, 0.0, offset_m=(0.1, 0.0, 0.05))
    with FlightLogWriter(prefix, CAM, mount=mount, options=LogOptions(chunk_size=20_000)) as w:
        for i in range(20):
            w.write_frame(frame(i), T0 + i * 10**8, t_boot_ns=5 * 10**9 + i * 10**8)
    (path,) = w.paths
    return path


def frames_in(path: Path, chunks: object = None) -> list[int]:
    layout = read_log_layout(path)
    pending: dict[int, dict[str, object]] = {}
    out = []
    with open(path, "rb") as f:
        for span in layout.chunks:
            msgs = []
            for rec in read_chunk(f, span):
                if isinstance(rec, Message):
                    msgs.append((layout.channels[rec.channel_id], rec))
            for r in decode_messages(msgs, layout, pending):  # type: ignore[arg-type]
                if isinstance(r, LoggedFrame):
                    out.append(r.frame.index)
    return out


def test_layout_from_the_summary_reads_back_every_frame(log: Path) -> None:
    layout = read_log_layout(log)
    assert layout.complete and layout.stop_reason is None and len(layout.chunks) >= 5
    assert [c.offset for c in layout.chunks] == sorted(c.offset for c in layout.chunks)
    assert "/camera/color/image_raw" in layout.topics()
    assert mount_from_metadata(layout.metadata) == CameraMount.from_euler_deg(
        0.0, -80.0, 0.0, offset_m=(0.1, 0.0, 0.05)
    )
    expected = [r.frame.index for r in read_flight_log(log, kinds={LoggedFrame})]  # type: ignore[union-attr]
    assert frames_in(log) == expected == list(range(20))


def test_a_cut_off_file_is_walked_to_its_last_complete_chunk(log: Path, tmp_path: Path) -> None:
    full = read_log_layout(log)
    data = log.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: full.chunks[-2].offset + 10])  # inside the last-but-one chunk
    walked = read_log_layout(cut, topics=("/camera/color/image_raw", "/camera/frame_info"))
    assert not walked.complete and "at byte" in (walked.stop_reason or "")
    assert walked.chunks == full.chunks[:-2]
    assert {"/camera/color/image_raw", "/camera/frame_info"} <= set(walked.topics())
    assert walked.content_hash != full.content_hash
    assert walked.metadata["holescan.mount"] == full.metadata["holescan.mount"]
    only_header = tmp_path / "head.mcap"
    only_header.write_bytes(data[:40])
    assert read_log_layout(only_header).chunks == ()


def test_a_file_without_its_summary_is_walked_whole(log: Path, tmp_path: Path) -> None:
    """The layout's walk and the reader's scan are the one record walker: a file cut right
    after its data section (summary and footer lost) gives the summary's chunks, complete,
    and the scan counts the same chunks."""
    full = read_log_layout(log)
    data = log.read_bytes()
    with open(log, "rb") as f:
        summary = read_summary(f, len(data))
    assert summary is not None
    cut = tmp_path / "no-summary.mcap"
    cut.write_bytes(data[: summary.start])
    walked = read_log_layout(cut, topics=full.topics())  # their channels are in the chunks
    assert walked.complete and walked.stop_reason is None
    assert walked.chunks == full.chunks
    assert walked.topics() == full.topics()
    state = ScanState(cut)
    records = list(scan_records(cut, state))
    assert state.chunks == len(walked.chunks) and not state.damaged
    assert sum(isinstance(r, Message) for r in records) > 0


def test_a_damaged_chunk_raises_and_bad_files_are_named(log: Path, tmp_path: Path) -> None:
    layout = read_log_layout(log)
    span = layout.chunks[1]
    data = bytearray(log.read_bytes())
    data[span.offset + span.length - 5] ^= 0xFF
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    with open(bad, "rb") as f:
        read_chunk(f, layout.chunks[0])
        with pytest.raises(ChunkDamagedError, match="damaged chunk at byte"):
            read_chunk(f, span)
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"x" * 100)
    with pytest.raises(FlightLogError, match="not an MCAP"):
        read_log_layout(junk)
    with pytest.raises(FlightLogError, match="no such file"):
        read_log_layout(tmp_path / "missing.mcap")
    with pytest.raises(FlightLogError, match=r"holescan\.mount"):
        mount_from_metadata({"holescan.mount": {"rotation_frd_from_camera": "[1]"}})


def test_one_decoder_for_the_live_link_and_replay() -> None:
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    hb = mav.heartbeat_encode(2, mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 4)
    gcs = mav.heartbeat_encode(6, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 4)
    assert is_autopilot_heartbeat(hb) and not is_autopilot_heartbeat(gcs)
    pos = mav.global_position_int_encode(
        1000, 436532000, -793832000, 122500, 2500, 80, -40, 5, 9000
    )
    att = mav.attitude_encode(1000, 0.1, -0.2, 1.5, 0.0, 0.0, 0.0)
    gps = mav.gps_raw_int_encode(0, 3, 436532000, -793832000, 122500, 120, 65535, 0, 0, 12)
    p = telemetry_sample(pos, 0)
    assert isinstance(p, PositionSample) and p.t_boot_ns == 10**9 and p.rel_alt_m == 2.5
    assert isinstance(telemetry_sample(att, 0), AttitudeSample)
    g = telemetry_sample(gps, 7)
    assert isinstance(g, GpsFix) and g.t_boot_ns == 7 and g.hdop == pytest.approx(1.2)
    assert telemetry_sample(hb, 0) is None
    replay = TelemetryReplay()
    later = [
        mav.global_position_int_encode(1100, 436532010, -793832000, 122500, 2500, 80, -40, 5, 9000),
        mav.attitude_encode(1100, 0.1, -0.2, 1.5, 0.0, 0.0, 0.0),
    ]
    packets = [bytes(m.pack(mav)) for m in (pos, hb, pos, att, *later)]
    added = [replay.feed(pk) for pk in packets]
    assert added == [False, False, True, True, True, True]  # none before the heartbeat
    assert replay.target == (1, 1) and replay.poses.newest_t_boot_ns == 1_100_000_000
    pose = replay.pose_at(1_050_000_000)
    assert pose is not None and pose.lat_deg == pytest.approx(43.6532005)
    assert replay.pose_at(None) is None
    assert dataclasses.is_dataclass(p)


def test_channels_in_a_chunk_are_read(log: Path) -> None:
    layout = read_log_layout(log)
    with open(log, "rb") as f:
        records = read_chunk(f, layout.chunks[0])
    assert any(isinstance(r, Channel) for r in records)


def test_the_attitude_sigma_is_logged_and_read_back(tmp_path: Path) -> None:
    """Reprocessing places holes with the error model the flight had."""
    errors = ErrorModel(attitude_sigma_rad=math.radians(0.3))
    with FlightLogWriter(tmp_path / "e", CAM, errors=errors) as w:
        w.write_frame(frame(0), T0, t_boot_ns=5 * 10**9)
    (path,) = w.paths
    got = errors_from_metadata(read_log_layout(path).metadata)
    assert math.degrees(got.attitude_sigma_rad) == pytest.approx(0.3)
    assert errors_from_metadata({}) == ErrorModel()  # logs from before: the default
    for bad, match in (("x", "unreadable"), ("45", "0-10")):
        with pytest.raises(FlightLogError, match=match):
            errors_from_metadata({"holescan.mount": {"attitude_sigma_deg": bad}})
