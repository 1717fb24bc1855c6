"""The pure-Python .oni writer and scanner: layout, round trip of metadata, bad input."""

from __future__ import annotations

import math
import struct
import subprocess
import sys
import textwrap
from dataclasses import replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from holescan.capture import OniWriter, scan_oni, write_oni
from holescan.detect import CameraIntrinsics, Frame
from holescan.errors import InputError

CAM = CameraIntrinsics(64, 48, 57.3, 58.1, 31.0, 24.5)
REPO = Path(__file__).resolve().parents[3]


def make_frames(n: int, cam: CameraIntrinsics = CAM, seed: int = 0, t0_ns: int = 5_000_000_000):
    rng = np.random.default_rng(seed)
    h, w = cam.height, cam.width
    return [
        Frame(
            index=i,
            rgb=rng.integers(0, 256, (h, w, 3), dtype=np.uint8),
            depth=rng.integers(0, 65536, (h, w), dtype=np.uint16),
            t_mono_ns=0,
            t_sensor_ns=t0_ns + i * 33_333_000,
        )
        for i in range(n)
    ]


def read_record(data: bytes, pos: int) -> tuple[int, int, int, int, int, int]:
    """(type, node id, fields size, payload size, undo position, magic) of the record at pos."""
    magic, rtype, node, fields, payload, undo = struct.unpack_from("<IIIIIQ", data, pos)
    return rtype, node, fields, payload, undo, magic


def test_write_then_scan_reports_streams_frames_and_camera(tmp_path: Path) -> None:
    frames = make_frames(7)
    path = tmp_path / "a.oni"
    assert write_oni(path, frames, CAM, fps=15) == 7
    assert path.is_file()
    assert not (tmp_path / ".a.part.oni").exists()
    info = scan_oni(path)
    assert info.size_bytes == path.stat().st_size
    assert info.max_timestamp_us == frames[-1].t_sensor_ns // 1000
    assert [s.kind for s in info.streams] == ["depth", "image"]
    for s in info.streams:
        assert (s.width, s.height, s.fps, s.codec) == (64, 48, 15, "NONE")
        assert s.frame_count == s.frames_found == 7
        assert s.min_timestamp_us == 5_000_000
        assert s.max_timestamp_us == 5_000_000 + 6 * 33_333
        assert s.camera == CAM
        assert s.hfov == pytest.approx(2 * math.atan(64 / (2 * 57.3)))
        assert s.vfov == pytest.approx(2 * math.atan(48 / (2 * 58.1)))
    assert info.stream("depth").oni_pixel_format == 100
    assert info.stream("image").oni_pixel_format == 200
    # Payload sizes: header + 7 x (depth + rgb) pixels dominate the file.
    assert info.size_bytes > 7 * 64 * 48 * (2 + 3)


def test_layout_header_seek_tables_and_data_records(tmp_path: Path) -> None:
    frames = make_frames(5, t0_ns=1_234_567_891)
    path = tmp_path / "b.oni"
    write_oni(path, frames, CAM)
    data = path.read_bytes()
    magic, major, minor, maint, build, max_ts, max_node = struct.unpack_from("<4sBBHIQI", data)
    assert (magic, major, minor, maint, build) == (b"NI10", 1, 0, 1, 0)
    assert max_ts == frames[-1].t_sensor_ns // 1000
    assert max_node == 2
    # The file ends with an END record.
    assert read_record(data, len(data) - 28)[0] == 0x0B
    # Walk the records: every NEW_DATA payload holds the frame's pixels as written.
    pos, seen, seek_tables = 24, {1: [], 2: []}, {}
    while True:
        rtype, node, fields, payload, undo, rmagic = read_record(data, pos)
        assert rmagic == 0x0052494E
        if rtype == 0x0B:
            break
        if rtype == 0x0A:
            ts, frame_id = struct.unpack_from("<QI", data, pos + 28)
            body = data[pos + fields : pos + fields + payload]
            f = frames[frame_id - 1]
            expected = f.depth.astype("<u2").tobytes() if node == 1 else f.rgb.tobytes()
            assert body == expected
            assert ts == f.t_sensor_ns // 1000
            # undo = previous data record of the same node (0 for the first)
            assert undo == (seen[node][-1] if seen[node] else 0)
            seen[node].append(pos)
        if rtype == 0x0E:
            entries = [
                struct.unpack_from("<QIQ", data, pos + fields + 20 * i)
                for i in range(payload // 20)
            ]
            seek_tables[node] = entries
        pos += fields + payload
    assert len(seen[1]) == len(seen[2]) == 5
    for node in (1, 2):
        entries = seek_tables[node]
        assert entries[0] == (0, 0, 0)  # entry 0 is empty: frame ids start at 1
        assert [e[2] for e in entries[1:]] == seen[node]
        assert [e[0] for e in entries[1:]] == [f.t_sensor_ns // 1000 for f in frames]


def test_timestamps_are_floored_to_microseconds(tmp_path: Path) -> None:
    frames = make_frames(3, t0_ns=999)
    path = tmp_path / "us.oni"
    write_oni(path, frames, CAM)
    info = scan_oni(path)
    assert info.stream("depth").min_timestamp_us == 0
    assert info.stream("depth").max_timestamp_us == (999 + 2 * 33_333_000) // 1000


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"rgb": np.zeros((48, 64, 3), np.uint16)}, "rgb must be"),
        ({"rgb": np.zeros((48, 63, 3), np.uint8)}, "rgb must be"),
        ({"depth": np.zeros((48, 64), np.float32)}, "depth must be"),
        ({"depth": np.zeros((47, 64), np.uint16)}, "depth must be"),
        ({"t_sensor_ns": -1}, "t_sensor_ns must be >= 0"),
    ],
)
def test_writer_rejects_bad_frames(tmp_path: Path, change: dict, message: str) -> None:
    good = make_frames(1)[0]
    fields = {k: getattr(good, k) for k in ("index", "rgb", "depth", "t_mono_ns", "t_sensor_ns")}
    bad = Frame(**{**fields, **change})
    with OniWriter(tmp_path / "c.oni", CAM) as w:
        w.write(good)
        with pytest.raises(InputError, match=message):
            w.write(bad)
        assert w.frame_count == 1
    # The frames before the bad one are kept and the file is whole.
    assert scan_oni(tmp_path / "c.oni").stream("image").frames_found == 1


def test_writer_rejects_time_going_back(tmp_path: Path) -> None:
    a, b = make_frames(2)
    with OniWriter(tmp_path / "d.oni", CAM) as w:
        w.write(b)
        with pytest.raises(InputError, match="back in time"):
            w.write(a)


def test_no_frames_is_an_error_and_leaves_no_file(tmp_path: Path) -> None:
    path = tmp_path / "empty.oni"
    with pytest.raises(InputError, match="no frames"):
        write_oni(path, [], CAM)
    assert list(tmp_path.iterdir()) == []


def test_exception_in_with_block_keeps_frames_written(tmp_path: Path) -> None:
    path = tmp_path / "e.oni"
    w = OniWriter(path, CAM)

    def record_then_fail() -> None:
        with w:
            for f in make_frames(3):
                w.write(f)
            raise RuntimeError("flight aborted")

    with pytest.raises(RuntimeError, match="flight aborted"):
        record_then_fail()
    assert w.closed
    assert scan_oni(path).stream("depth").frames_found == 3


def test_writer_arguments_checked(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="fps"):
        OniWriter(tmp_path / "f.oni", CAM, fps=0)
    with pytest.raises(InputError, match="too large"):
        OniWriter(tmp_path / "f.oni", CameraIntrinsics(2000, 1500, 1000, 1000, 1000, 750))
    with pytest.raises(InputError, match="missing-dir does not exist"):
        OniWriter(tmp_path / "missing-dir" / "f.oni", CAM)
    w = OniWriter(tmp_path / "g.oni", CAM)
    w.write(make_frames(1)[0])
    w.close()
    w.close()  # closing twice is harmless
    with pytest.raises(InputError, match="closed"):
        w.write(make_frames(1)[0])


def test_scan_missing_and_non_oni_files(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"no such \.oni file"):
        scan_oni(tmp_path / "nope.oni")
    junk = tmp_path / "junk.oni"
    junk.write_bytes(b"this is not a recording at all" * 10)
    with pytest.raises(InputError, match=r"not an OpenNI \.oni recording"):
        scan_oni(junk)
    empty = tmp_path / "empty.oni"
    empty.write_bytes(b"")
    with pytest.raises(InputError, match="not an OpenNI"):
        scan_oni(empty)
    with pytest.raises(InputError, match="cannot read"):
        scan_oni(tmp_path)  # a directory


def test_scan_truncated_files(tmp_path: Path) -> None:
    path = tmp_path / "t.oni"
    write_oni(path, make_frames(4), CAM)
    data = path.read_bytes()
    frame_bytes = 64 * 48 * 5 + 2 * 40
    for cut in (30, 500, len(data) // 2, len(data) - 2 * frame_bytes, len(data) - 1):
        short = tmp_path / f"cut{cut}.oni"
        short.write_bytes(data[:cut])
        with pytest.raises(InputError, match="truncated"):
            scan_oni(short)


def test_scan_corrupt_files(tmp_path: Path) -> None:
    path = tmp_path / "ok.oni"
    write_oni(path, make_frames(3), CAM)
    data = bytearray(path.read_bytes())

    def variant(name: str, mutate) -> Path:
        buf = bytearray(data)
        mutate(buf)
        out = tmp_path / name
        out.write_bytes(bytes(buf))
        return out

    first = 24  # the first record follows the file header
    bad_magic = variant("magic.oni", lambda b: b.__setitem__(slice(first, first + 4), b"XXXX"))
    with pytest.raises(InputError, match="corrupt record at byte 24"):
        scan_oni(bad_magic)
    bad_version = variant("version.oni", lambda b: b.__setitem__(4, 9))
    with pytest.raises(InputError, match="version 9"):
        scan_oni(bad_version)
    bad_type = variant(
        "type.oni", lambda b: b.__setitem__(slice(first + 4, first + 8), b"\x77\0\0\0")
    )
    with pytest.raises(InputError, match="unknown record type 0x77"):
        scan_oni(bad_type)
    # The header's maximum timestamp below the frames' timestamps.
    low_max = variant(
        "maxts.oni", lambda b: b.__setitem__(slice(12, 20), (1).to_bytes(8, "little"))
    )
    with pytest.raises(InputError, match="beyond the file's maximum"):
        scan_oni(low_max)
    # Frame count in NODE_ADDED lowered from 3 to 2: frame id 3 is out of range.
    name_end = first + 28 + 4 + len(b"Depth\0")
    count_at = name_end + 8
    assert struct.unpack_from("<I", data, count_at)[0] == 3
    low_count = variant("count.oni", lambda b: struct.pack_into("<I", b, count_at, 2))
    with pytest.raises(InputError, match=r"frame id 3 outside 1\.\.2"):
        scan_oni(low_count)


def test_killed_writer_leaves_only_a_partial_file(tmp_path: Path) -> None:
    """SIGKILL-like death mid-recording: no file under the final name, a .partial that
    scan_oni reports as truncated with the frames it holds."""
    path = tmp_path / "killed.oni"
    child = textwrap.dedent(
        f"""
        import os, numpy as np
        from holescan.capture import OniWriter
        from holescan.detect import Frame
        from holescan.detect import CameraIntrinsics
        cam = CameraIntrinsics(64, 48, 57.3, 58.1, 31.0, 24.5)
        w = OniWriter({str(path)!r}, cam)
        for i in range(5):
            z = np.zeros((48, 64), np.uint16)
            w.write(Frame(i, np.zeros((48, 64, 3), np.uint8), z, 0, i * 33_000_000))
        w._file.flush()
        os._exit(0)
        """
    )
    proc = subprocess.run(
        [sys.executable, "-c", child], cwd=REPO, capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 0, proc.stderr
    assert not path.exists()
    partial = tmp_path / ".killed.part.oni"
    assert partial.is_file()
    with pytest.raises(InputError, match="5 depth, 5 image frames before the cut"):
        scan_oni(partial)


def read_data_records(path: Path) -> dict[int, list[tuple[int, int, bytes]]]:
    """(timestamp us, frame id, payload) of every NEW_DATA record, per node id."""
    data = path.read_bytes()
    out: dict[int, list[tuple[int, int, bytes]]] = {1: [], 2: []}
    pos = 24
    while True:
        rtype, node, fields, payload, _undo, _magic = read_record(data, pos)
        if rtype == 0x0B:
            return out
        if rtype == 0x0A:
            ts, frame_id = struct.unpack_from("<QI", data, pos + 28)
            out[node].append((ts, frame_id, data[pos + fields : pos + fields + payload]))
        pos += fields + payload


def write_flight_log(prefix: Path, frames: list[Frame], **images: Any) -> Path:
    from holescan.flightlog import FlightLogWriter, LogOptions

    with FlightLogWriter(prefix, CAM, options=LogOptions(**images)) as log:
        for f in frames:
            assert log.write_frame(f, 1_700_000_000_000_000_000 + f.t_mono_ns)
    (path,) = log.paths
    return path


@pytest.mark.parametrize(
    ("color", "depth"), [("raw", "raw"), ("png", "zstd"), ("jpeg", "png"), ("jpeg", "zstd")]
)
def test_export_oni_from_a_flight_log(tmp_path: Path, color: str, depth: str) -> None:
    """Every way the log stores images exports: depth exactly, colour exactly or, from a
    JPEG log, as the JPEG codec gives it back."""
    from holescan.capture import export_oni

    frames = [replace(f, t_mono_ns=10_000 + i * 33_000_000) for i, f in enumerate(make_frames(6))]
    log = write_flight_log(tmp_path / "flight", frames, color=color, depth=depth)
    out = tmp_path / "flight.oni"
    assert export_oni(log, out, fps=30) == 6
    records = read_data_records(out)
    for i, f in enumerate(frames):
        ts, frame_id, depth = records[1][i]
        assert (ts, frame_id) == (f.t_sensor_ns // 1000, i + 1)
        assert depth == f.depth.astype("<u2").tobytes()
        rgb = f.rgb
        if color == "jpeg":
            ok, buf = cv2.imencode(".jpg", rgb[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 90])
            assert ok
            rgb = cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1]
        assert records[2][i][2] == np.ascontiguousarray(rgb).tobytes()
    assert scan_oni(out).stream("image").camera == CAM


def test_export_oni_continues_time_across_a_sensor_clock_reset(tmp_path: Path) -> None:
    from holescan.capture import export_oni

    frames = make_frames(5)
    mono = [i * 33_000_000 for i in range(5)]
    sensor = [9_000_000_000, 9_033_000_000, 1_000_000, 34_000_000, 67_000_000]  # USB reset
    frames = [
        replace(f, t_mono_ns=m, t_sensor_ns=s) for f, m, s in zip(frames, mono, sensor, strict=True)
    ]
    out = tmp_path / "reset.oni"
    assert export_oni(write_flight_log(tmp_path / "reset", frames), out) == 5
    ts_us = [ts for ts, _id, _px in read_data_records(out)[1]]
    assert ts_us == [9_000_000, 9_033_000, 9_066_000, 9_099_000, 9_132_000]


def test_export_oni_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from holescan.cli import build_parser

    parser = build_parser()
    log = write_flight_log(tmp_path / "cli", make_frames(3))
    out = tmp_path / "cli.oni"
    args = parser.parse_args(["export-oni", str(log), str(out), "--fps", "15"])
    assert args.func(args) == 0
    assert capsys.readouterr().out.strip() == f"{out}: 3 frames"
    assert scan_oni(out).stream("depth").fps == 15
    missing = parser.parse_args(["export-oni", str(tmp_path / "none.mcap"), str(out)])
    with pytest.raises(InputError):
        missing.func(missing)
