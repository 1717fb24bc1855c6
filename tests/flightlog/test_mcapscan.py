"""Damaged flight logs cost the damaged bytes only: a flipped byte in a chunk, corrupt length
fields (with and without the summary), a damaged first chunk (channels from the summary);
and no verb ever writes over an input or an existing ``.mcap``."""

from __future__ import annotations

import hashlib
import struct
import tracemalloc
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader

from holescan.errors import HolescanError
from holescan.flightlog import (
    FlightLogWriter,
    LoggedFrame,
    LoggedHoles,
    LogOptions,
    ScanState,
    log_info,
    read_flight_log,
    recover_log,
    scan_records,
)
from holescan.flightlog.errors import TruncatedLogError
from tests.flightlog.test_mcaplog import (
    SMALL,
    T0_UNIX_NS,
    frames_equal,
    make_frame,
    make_hole,
    mavlink_packets,
)

N_FRAMES = 40

#: The layout of older logs (raw images): what these container tests were sized for.
RAW: dict[str, Any] = {"color": "raw", "depth": "raw"}


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """40 small frames in ~2-frame chunks, a /holes record every 5 frames."""
    prefix = tmp_path_factory.mktemp("scan") / "f"
    with FlightLogWriter(prefix, SMALL, options=LogOptions(chunk_size=20_000, **RAW)) as w:
        for i in range(N_FRAMES):
            t = T0_UNIX_NS + i * 33_333_333
            w.write_frame(make_frame(i), t)
            w.write_mavlink(mavlink_packets(1)[0], t)
            if i % 5 == 4:
                w.write_holes([make_hole(k) for k in range(1 + i // 5)], t)
    (path,) = w.paths
    return path


def chunks_of(path: Path) -> list[tuple[int, int]]:
    """(start offset, length) of every chunk, from the summary's chunk index."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return [(c.chunk_start_offset, c.chunk_length) for c in summary.chunk_indexes]


def data_end(path: Path) -> int:
    """Offset of the DataEnd record (cutting there removes the whole summary)."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    last = max(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    data = path.read_bytes()
    return data.index(b"\x0f\x04\0\0\0\0\0\0\0", last.chunk_start_offset + last.chunk_length)


def frames_read(path: Path) -> list[int]:
    return [r.frame.index for r in read_flight_log(path, kinds={LoggedFrame})]


def variant(src: Path, dst: Path, edit: object) -> Path:
    data = bytearray(src.read_bytes())
    edit(data)  # type: ignore[operator]
    dst.write_bytes(bytes(data))
    return dst


@pytest.mark.parametrize("which", [0, 5, -2])
def test_flipped_byte_costs_that_chunk_only(flight: Path, tmp_path: Path, which: int) -> None:
    chunks = chunks_of(flight)
    start, length = chunks[which]
    bad = variant(flight, tmp_path / "bad.mcap", lambda d: d.__setitem__(
        start + length // 2, d[start + length // 2] ^ 0x10))  # fmt: skip
    got = frames_read(bad)
    assert N_FRAMES - 3 <= len(got) < N_FRAMES  # a chunk holds at most ~2 frames' parts
    assert got[-1] >= N_FRAMES - 2  # reading went on after the damage
    state = ScanState(bad)
    n = sum(1 for _ in scan_records(bad, state))
    assert n > 0
    assert len(state.damaged) == 1
    region = state.damaged[0]
    assert region.offset == start
    assert region.length == length
    assert region.messages is not None and region.messages > 0
    assert region.t_start_ns is not None and region.t_start_ns >= T0_UNIX_NS
    assert "chunk CRC mismatch" in region.describe() or "zstd" in region.describe()
    # Every verb reads past the damage.
    holes = list(read_flight_log(bad, kinds={LoggedHoles}))
    assert len(holes) >= N_FRAMES // 5 - 1
    assert len(holes[-1].holes) == N_FRAMES // 5
    report = recover_log(bad, tmp_path / "fixed.mcap")
    assert report.frames == len(got)
    assert report.messages_lost == region.messages
    assert "messages lost" in report.line()
    assert log_info(tmp_path / "fixed.mcap").frames == len(got)
    again = [r.frame for r in read_flight_log(tmp_path / "fixed.mcap", kinds={LoggedFrame})]
    assert all(frames_equal(f, make_frame(f.index)) for f in again)
    with pytest.raises(TruncatedLogError, match="messages lost"):
        list(read_flight_log(bad, strict=True))


def test_damaged_first_chunk_keeps_later_channels_from_the_summary(
    flight: Path, tmp_path: Path
) -> None:
    start, length = chunks_of(flight)[0]  # holds the Schema and Channel records
    bad = variant(flight, tmp_path / "c0.mcap", lambda d: d.__setitem__(
        start + length - 40, d[start + length - 40] ^ 0xFF))  # fmt: skip
    got = frames_read(bad)
    assert len(got) >= N_FRAMES - 3
    info = log_info(bad, allow_truncated=True)
    assert info.frames == len(got)


@pytest.mark.parametrize("summary", [True, False])
@pytest.mark.parametrize(
    "field",
    ["record_length_huge", "record_length_short", "uncompressed_size", "data_length"],
)
def test_corrupt_length_fields_skip_one_chunk_without_allocating(
    flight: Path, tmp_path: Path, field: str, summary: bool
) -> None:
    start, length = chunks_of(flight)[3]
    end = len(flight.read_bytes()) if summary else data_end(flight)

    def edit(d: bytearray) -> None:
        if field == "record_length_huge":
            struct.pack_into("<Q", d, start + 1, 2**63 + 12345)
        elif field == "record_length_short":
            struct.pack_into("<Q", d, start + 1, length // 3)
        elif field == "uncompressed_size":
            struct.pack_into("<Q", d, start + 9 + 16, 2**50)
        else:  # the compressed data length, after the compression name "zstd"
            struct.pack_into("<Q", d, start + 9 + 28 + 4 + 4, 2**62)
        del d[end:]

    bad = variant(flight, tmp_path / f"{field}.mcap", edit)
    tracemalloc.start()
    try:
        got = frames_read(bad)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # A length field is never trusted for an allocation: reading the damaged file takes
    # about what reading the good one takes (a few chunks at a time), not 2**50 bytes.
    print(f"{field}: peak {peak / 1e6:.1f} MB traced, file {bad.stat().st_size / 1e6:.1f} MB")
    assert peak < 4 * flight.stat().st_size + 64 * 2**20
    if field == "data_length":  # the record length bounds the data: the chunk checks out
        assert len(got) == N_FRAMES
    else:
        assert N_FRAMES - 4 <= len(got) < N_FRAMES
    assert got[-1] == N_FRAMES - 1
    assert recover_log(bad, tmp_path / f"{field}-fixed.mcap").frames == len(got)
    info = log_info(bad, allow_truncated=True)
    assert info.frames == len(got)
    assert info.truncated


# ------------------------------------------------------------------ never write over data


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def cli_main(monkeypatch: pytest.MonkeyPatch):  # type: ignore[no-untyped-def]
    from holescan import cli

    return cli.main


def test_no_verb_writes_over_an_input_or_a_flight_log(
    flight: Path,
    tmp_path: Path,
    cli_main,
    capsys: pytest.CaptureFixture[str],  # type: ignore[no-untyped-def]
) -> None:
    a = tmp_path / "A.mcap"
    a.write_bytes(flight.read_bytes())
    opts = LogOptions(chunk_size=8 * 1024, max_file_bytes=60 * 1024, **RAW)
    with FlightLogWriter(tmp_path / "P", SMALL, options=opts) as w:
        for i in range(30):
            w.write_frame(make_frame(i), T0_UNIX_NS + i)
    p0, p1 = w.paths[:2]
    before = {p: sha(p) for p in (a, p0, p1)}
    cases = [
        (["export-oni", str(a), str(a)], "also an input"),
        (["export-oni", str(p0), str(p1)], "flight log"),
        (["export-oni", str(p0), str(tmp_path / "other.mcap")], "extension"),
        (["holes", str(a), "-o", str(a)], "also an input"),
        (["holes", str(a), "-o", str(p1)], "flight log"),
        (["log", "recover", str(a), "--out", str(a)], "also an input"),
        (["log", "recover", str(a), "--out", str(p0)], "flight log"),
        (["log", "info", str(a), str(a)], "given twice"),
        (["log", "info", str(a), str(tmp_path / "." / "A.mcap")], "given twice"),
    ]
    for argv, message in cases:
        assert cli_main(argv) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1, err
        assert message in err[0], (argv, err)
    assert {p: sha(p) for p in (a, p0, p1)} == before
    assert not list(tmp_path.glob(".*part*"))
    # An existing non-log output is refused unless --force; the input never.
    out = tmp_path / "o.oni"
    out.write_bytes(b"keep")
    assert cli_main(["export-oni", str(a), str(out)]) == 2
    assert "exists" in capsys.readouterr().err
    assert out.read_bytes() == b"keep"
    assert cli_main(["export-oni", str(a), str(out), "--force"]) == 0
    assert out.stat().st_size > 1000
    with pytest.raises(HolescanError, match="also an input"):
        recover_log(a, a)


def test_holes_and_export_oni_read_past_a_damaged_chunk(
    flight: Path,
    tmp_path: Path,
    cli_main,
    capsys: pytest.CaptureFixture[str],  # type: ignore[no-untyped-def]
) -> None:
    start, length = chunks_of(flight)[1]
    bad = variant(flight, tmp_path / "bad.mcap", lambda d: d.__setitem__(
        start + length // 2, d[start + length // 2] ^ 0x01))  # fmt: skip
    gpx = tmp_path / "holes.gpx"
    assert cli_main(["holes", str(bad), "-o", str(gpx), "--min-sightings", "1"]) == 0
    text = gpx.read_text()
    assert text.count("<wpt") == N_FRAMES // 5  # the last hole list, written after the damage
    oni = tmp_path / "bad.oni"
    assert cli_main(["export-oni", str(bad), str(oni)]) == 0
    out = capsys.readouterr().out
    n = int(out.split(":")[-1].split()[0])
    assert N_FRAMES - 3 <= n < N_FRAMES
