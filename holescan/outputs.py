"""Output files that never destroy data: one rule for every verb that writes.

* an output is never one of the inputs, and never an existing ``.mcap`` (a flight log);
* any other existing file is refused unless the caller says ``force``;
* the folder must exist and be writable, the name must not be a folder;
* the file is written as ``.STEM.part.EXT`` beside it and renamed when complete, so a crash or
  an error leaves no half-written output under the real name.

Problems are :class:`OutputPathError` (an :class:`holescan.errors.InputError`): the CLI
prints them as one line and exits 2.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
from collections.abc import Collection, Iterable, Iterator
from pathlib import Path
from typing import IO

from holescan.errors import InputError

__all__ = [
    "OutputPathError",
    "atomic_output",
    "check_folder",
    "check_output",
    "commit_part",
    "folder_via_part",
    "output_via_part",
    "part_path",
]

PathLike = str | os.PathLike[str]


class OutputPathError(InputError):
    """An output path that must not or cannot be written."""


def _same(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def check_output(
    path: PathLike,
    *,
    inputs: Iterable[PathLike] = (),
    suffixes: Collection[str] | None = None,
    force: bool = False,
) -> Path:
    """Check that ``path`` may be written; return it as a :class:`Path`.

    Parameters
    ----------
    inputs : the files the command reads (an output is never one of them).
    suffixes : allowed extensions, lower case with the dot (``{".png", ".jpg"}``).
    force : allow replacing an existing file that is not an input and not a ``.mcap``.

    Raises
    ------
    OutputPathError : with one line saying what to do.
    """
    p = Path(path)
    if str(path) == "" or p.name in ("", ".", ".."):
        raise OutputPathError(f"{str(path)!r} is not a file name")
    if p.is_dir():
        raise OutputPathError(f"{p} is a folder: give a file name")
    for i in inputs:
        q = Path(i)
        if _same(p, q) or p.resolve() == q.resolve():
            raise OutputPathError(f"{p} is also an input: choose another output file")
    if p.exists() or p.is_symlink():
        if p.suffix.lower() == ".mcap":
            raise OutputPathError(f"{p} exists and is a flight log: it is never overwritten")
        if not force:
            raise OutputPathError(f"{p} exists: choose another output file (or --force)")
    if suffixes is not None and p.suffix.lower() not in suffixes:
        allowed = ", ".join(sorted(suffixes))
        raise OutputPathError(f"{p}: unknown extension {p.suffix!r} (use one of {allowed})")
    check_folder(p.parent, for_file=p)
    return p


def check_folder(folder: PathLike, *, for_file: PathLike | None = None) -> Path:
    """A folder outputs can be written into (exists, is a folder, writable)."""
    d = Path(folder) if str(folder) else Path(".")
    what = f"cannot write {for_file}: " if for_file is not None else "cannot write in it: "
    if not d.exists():
        raise OutputPathError(f"{what}folder {d} does not exist (create it first)")
    if not d.is_dir():
        raise OutputPathError(f"{what}{d} is not a folder")
    try:
        read_only = bool(os.statvfs(d).f_flag & os.ST_RDONLY)
    except OSError:
        read_only = False
    if read_only:
        raise OutputPathError(f"{what}{d} is on a read-only file system")
    if not os.access(d, os.W_OK | os.X_OK):
        raise OutputPathError(f"{what}no permission to write in {d}")
    return d


def part_path(path: PathLike) -> Path:
    """The temporary name an output is written under: ``.STEM.part.EXT`` in its folder (the
    extension kept for writers that choose the format by it)."""
    p = Path(path)
    return p.with_name(f".{p.stem}.part{p.suffix}")


def _os_error(p: Path, err: OSError) -> OutputPathError:
    why = {
        errno.EROFS: "read-only file system",
        errno.EACCES: "permission denied",
        errno.ENOSPC: "no space left on device",
        errno.ENOENT: "folder does not exist",
        errno.EISDIR: "is a folder",
    }.get(err.errno or 0, err.strerror or str(err))
    return OutputPathError(f"cannot write {p}: {why}")


def commit_part(tmp: PathLike, path: PathLike, *, force: bool = False) -> None:
    """Rename a finished ``.part`` file to its real name (refusing, at the last moment, an
    output that appeared meanwhile, unless ``force`` and not a ``.mcap``)."""
    t, p = Path(tmp), Path(path)
    try:
        if force and p.suffix.lower() != ".mcap":
            os.replace(t, p)
        else:
            os.link(t, p)  # fails if p exists: never replaces a file
            t.unlink()
    except FileExistsError as err:
        t.unlink(missing_ok=True)
        raise OutputPathError(f"{p} appeared while writing: kept it, output discarded") from err
    except OSError as err:
        if err.errno in (errno.EPERM, errno.EXDEV, errno.EOPNOTSUPP, errno.EMLINK):
            if p.exists():  # file systems without hard links: check, then rename
                t.unlink(missing_ok=True)
                raise OutputPathError(f"{p} appeared while writing: output discarded") from err
            os.replace(t, p)
            return
        t.unlink(missing_ok=True)
        raise _os_error(p, err) from err


@contextlib.contextmanager
def atomic_output(
    path: PathLike,
    *,
    inputs: Iterable[PathLike] = (),
    suffixes: Collection[str] | None = None,
    force: bool = False,
) -> Iterator[IO[bytes]]:
    """Open ``path`` for writing through ``.STEM.part.EXT``: checked first
    (:func:`check_output`), flushed, fsynced and renamed on success, removed on any error.
    """
    with (
        output_via_part(path, inputs=inputs, suffixes=suffixes, force=force) as tmp,
        open(tmp, "wb") as f,
    ):
        yield f
        f.flush()
        os.fsync(f.fileno())


@contextlib.contextmanager
def output_via_part(
    path: PathLike,
    *,
    inputs: Iterable[PathLike] = (),
    suffixes: Collection[str] | None = None,
    force: bool = False,
    fsync: bool = False,
) -> Iterator[Path]:
    """Like :func:`atomic_output` for writers that take a file name (cv2, matplotlib):
    yields the ``.part`` path to write; renamed on success, removed on error. ``fsync``:
    flush the written file to the disk before the rename (as :func:`atomic_output` does),
    for files rewritten while a program runs, that a power cut must not leave empty."""
    p = check_output(path, inputs=inputs, suffixes=suffixes, force=force)
    tmp = part_path(p)
    try:
        yield tmp
        if not tmp.exists():
            raise OutputPathError(f"cannot write {p}: nothing was written")
        if fsync:
            fd = os.open(tmp, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise _os_error(p, err) from err
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    commit_part(tmp, p, force=force)


@contextlib.contextmanager
def folder_via_part(path: PathLike, *, inputs: Iterable[PathLike] = ()) -> Iterator[Path]:
    """A new output folder (a dataset ...), the rule of :func:`output_via_part` for folders:
    checked at once (an existing ``path`` is refused, never replaced; ``inputs`` must not lie
    in it; its parent must be writable), then yields ``.NAME.part`` (created, empty; one
    left by an interrupted run is removed first) to fill, renamed to ``path`` on success,
    removed with its contents on any error."""
    p = Path(path)
    if str(path) == "" or p.name in ("", ".", ".."):
        raise OutputPathError(f"{str(path)!r} is not a folder name")
    if p.exists() or p.is_symlink():
        raise OutputPathError(f"{p} already exists: choose a new folder (it is never replaced)")
    for i in inputs:
        if p.resolve() in Path(i).resolve().parents:
            raise OutputPathError(f"{i} is an input inside {p}: choose another output folder")
    check_folder(p.parent, for_file=p)
    tmp = part_path(p)
    try:
        if tmp.is_dir() and not tmp.is_symlink():
            shutil.rmtree(tmp)  # left by an interrupted run
        tmp.mkdir()
        yield tmp
        if p.exists():
            raise OutputPathError(f"{p} appeared while writing: kept it, output discarded")
        tmp.rename(p)
    except OSError as err:
        shutil.rmtree(tmp, ignore_errors=True)
        raise _os_error(p, err) from err
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
