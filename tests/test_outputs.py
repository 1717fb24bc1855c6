"""The output-path rule (holescan.outputs): refuse existing, never an input, a crash leaves
no final file, fsync before the rename; the same through every door (atomic_output,
output_via_part, PartFile, folder_via_part)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from holescan.outputs import (
    OutputPathError,
    PartFile,
    atomic_output,
    folder_via_part,
    output_via_part,
    part_path,
)


def _write_atomic(path: Path, data: bytes, **kw: object) -> None:
    with atomic_output(path, **kw) as f:  # type: ignore[arg-type]
        f.write(data)


def _write_via_part(path: Path, data: bytes, **kw: object) -> None:
    with output_via_part(path, **kw) as tmp:  # type: ignore[arg-type]
        tmp.write_bytes(data)


def _write_partfile(path: Path, data: bytes, **kw: object) -> None:
    out = PartFile(path, **kw)  # type: ignore[arg-type]
    out.file.write(data)
    out.commit()


WRITERS = [_write_atomic, _write_via_part, _write_partfile]


@pytest.mark.parametrize("write", WRITERS)
def test_writes_and_leaves_no_part(tmp_path: Path, write) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "holes.json"
    write(out, b"[]")
    assert out.read_bytes() == b"[]"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["holes.json"]


@pytest.mark.parametrize("write", WRITERS)
def test_existing_output_refused_unless_forced(tmp_path: Path, write) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "holes.json"
    out.write_bytes(b"kept")
    with pytest.raises(OutputPathError, match="exists"):
        write(out, b"new")
    assert out.read_bytes() == b"kept"
    write(out, b"new", force=True)
    assert out.read_bytes() == b"new"


@pytest.mark.parametrize("write", WRITERS)
def test_flight_log_never_replaced_even_forced(tmp_path: Path, write) -> None:  # type: ignore[no-untyped-def]
    log = tmp_path / "flight_0001.mcap"
    log.write_bytes(b"log")
    with pytest.raises(OutputPathError, match="flight log"):
        write(log, b"x", force=True)
    assert log.read_bytes() == b"log"


@pytest.mark.parametrize("write", WRITERS)
def test_an_input_is_never_an_output(tmp_path: Path, write) -> None:  # type: ignore[no-untyped-def]
    src = tmp_path / "area.geojson"
    src.write_bytes(b"input")
    for given in (src, tmp_path / "." / "area.geojson"):
        with pytest.raises(OutputPathError, match="also an input"):
            write(given, b"x", inputs=[src], force=True)
    link = tmp_path / "link.geojson"
    link.symlink_to(src)
    with pytest.raises(OutputPathError, match="also an input"):
        write(link, b"x", inputs=[src], force=True)
    with pytest.raises(OutputPathError, match="also an input"):
        write(tmp_path / "area.geojson", b"x", inputs=[link], force=True, replace=True)
    assert src.read_bytes() == b"input"


@pytest.mark.parametrize("write", WRITERS)
def test_replace_own_output_even_a_log(tmp_path: Path, write) -> None:  # type: ignore[no-untyped-def]
    own = tmp_path / "flight_reprocess.mcap"
    own.write_bytes(b"first run")
    write(own, b"second run", replace=True)
    assert own.read_bytes() == b"second run"


def _fail_atomic(out: Path) -> None:
    with atomic_output(out) as f:
        f.write(b"half")
        raise RuntimeError("writer failed")


def _fail_via_part(out: Path) -> None:
    with output_via_part(out) as tmp:
        tmp.write_bytes(b"half")
        raise RuntimeError("writer failed")


def _fail_partfile(out: Path) -> None:
    with PartFile(out) as pf:
        pf.file.write(b"half")
        raise RuntimeError("writer failed")


def _fail_folder(out: Path) -> None:
    with folder_via_part(out) as part:
        (part / "half.png").write_bytes(b"x")
        raise RuntimeError("writer failed")


@pytest.mark.parametrize("fail", [_fail_atomic, _fail_via_part, _fail_partfile, _fail_folder])
def test_error_inside_the_block_leaves_neither_file(tmp_path: Path, fail) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(RuntimeError, match="writer failed"):
        fail(tmp_path / "map.tif")
    assert list(tmp_path.iterdir()) == []


def test_discarded_partfile_leaves_nothing(tmp_path: Path) -> None:
    pf = PartFile(tmp_path / "flight.oni")
    pf.file.write(b"half")
    pf.discard()
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(OutputPathError, match="already committed or discarded"):
        pf.file  # noqa: B018


def _overtaken(out: Path) -> None:
    with atomic_output(out) as f:
        f.write(b"ours")
        out.write_bytes(b"someone else's")


def test_output_that_appears_while_writing_is_kept(tmp_path: Path) -> None:
    out = tmp_path / "report.html"
    with pytest.raises(OutputPathError, match="appeared while writing"):
        _overtaken(out)
    assert out.read_bytes() == b"someone else's"
    assert not part_path(out).exists()


CRASHER = """
import os, sys
from holescan.outputs import {door}
out = sys.argv[1]
{body}
"""


@pytest.mark.parametrize(
    ("door", "body"),
    [
        ("atomic_output", "with atomic_output(out) as f:\n    f.write(DATA); f.flush()\n    KILL"),
        ("PartFile", "pf = PartFile(out)\npf.file.write(DATA); pf.file.flush()\nKILL"),
        (
            "output_via_part",
            "with output_via_part(out) as tmp:\n    tmp.write_bytes(DATA)\n    KILL",
        ),
    ],
)
def test_a_killed_writer_leaves_no_final_file(tmp_path: Path, door: str, body: str) -> None:
    """A process killed mid-write (power cut, OOM killer) leaves at most the ``.part``, never
    a half file under the real name; the next run replaces the leftover ``.part``."""
    out = tmp_path / "holes.kmz"
    body = body.replace("DATA", "b'x' * 99999").replace("KILL", "os.kill(os.getpid(), 9)")
    script = textwrap.dedent(CRASHER).format(door=door, body=body)
    proc = subprocess.run([sys.executable, "-c", script, str(out)], check=False, timeout=60)
    assert proc.returncode == -signal.SIGKILL
    assert not out.exists()
    assert part_path(out).exists()  # what the crash left, under its temporary name
    _write_atomic(out, b"complete")
    assert out.read_bytes() == b"complete"
    assert not part_path(out).exists()


def test_fsync_before_rename(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The data reaches the disk before the name does: every door fsyncs the ``.part``, then
    renames it, then fsyncs the folder (the real calls, recorded in order)."""
    events: list[tuple[str, str]] = []
    real_fsync, real_link, real_replace = os.fsync, os.link, os.replace

    def fsync(fd: int) -> None:
        events.append(("fsync", os.readlink(f"/proc/self/fd/{fd}")))
        real_fsync(fd)

    def link(src: str, dst: str, **kw: object) -> None:
        events.append(("rename", str(dst)))
        real_link(src, dst, **kw)  # type: ignore[arg-type]

    def replace(src: str, dst: str, **kw: object) -> None:
        events.append(("rename", str(dst)))
        real_replace(src, dst, **kw)  # type: ignore[arg-type]

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "link", link)
    monkeypatch.setattr(os, "replace", replace)
    folder = str(tmp_path.resolve())
    for i, write in enumerate(WRITERS):
        out = tmp_path / f"out{i}.json"
        events.clear()
        write(out, b"{}")
        part = str(part_path(out.resolve()))
        assert events == [("fsync", part), ("rename", str(out)), ("fsync", folder)], write


def test_folder_via_part(tmp_path: Path) -> None:
    out = tmp_path / "dataset"
    with folder_via_part(out) as part:
        (part / "annotations.json").write_text("{}")
        assert not out.exists()
    assert (out / "annotations.json").read_text() == "{}"
    with pytest.raises(OutputPathError, match="already exists"), folder_via_part(out):
        pass
    with pytest.raises(OutputPathError, match="is an input inside"):
        folder_via_part(tmp_path / "wrap", inputs=[tmp_path / "wrap" / "a.csv"]).__enter__()


def test_bad_names_and_folders(tmp_path: Path) -> None:
    with pytest.raises(OutputPathError, match="is a folder"):
        _write_atomic(tmp_path, b"x")
    with pytest.raises(OutputPathError, match="does not exist"):
        _write_atomic(tmp_path / "missing" / "a.json", b"x")
    with pytest.raises(OutputPathError, match="unknown extension"):
        _write_atomic(tmp_path / "a.txt", b"x", suffixes={".json"})
    assert list(tmp_path.iterdir()) == []
