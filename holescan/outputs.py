"""Output files that never destroy data: one rule for every verb that writes.

* an output is never one of the inputs, and never an existing ``.mcap`` (a flight log);
* any other existing file is refused unless the caller says ``force``;
* the folder must exist and be writable, the name must not be a folder;
* the file is written as ``.STEM.part.EXT`` beside it, flushed and fsynced, renamed when
  complete and its folder fsynced, so a crash or an error leaves no half-written output under
  the real name (at most a ``.part``, replaced by the next run).

Four doors onto the one rule, for the four shapes a writer has:

* :func:`atomic_output` (a ``with`` block writing a binary file object: JSON, zip, pickle);
* :func:`output_via_part` (a ``with`` block for libraries that take a file name: rasterio,
  cv2, matplotlib);
* :class:`PartFile` (a file whose writer lives longer than a block and closes it later: the
  MCAP writer, the ``.oni`` writer);
* :func:`folder_via_part` (a new folder filled, then renamed: a dataset).

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
from types import TracebackType
from typing import IO

from holescan.errors import InputError

__all__ = [
    "OutputPathError",
    "PartFile",
    "PathLike",
    "atomic_output",
    "check_folder",
    "check_output",
    "commit_part",
    "folder_via_part",
    "output_via_part",
    "part_path",
]

PathLike = str | os.PathLike[str]
"""A file name as the writers take it."""


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
    replace: bool = False,
) -> Path:
    """Check that ``path`` may be written; return it as a :class:`Path`.

    Parameters
    ----------
    inputs : the files the command reads (an output is never one of them).
    suffixes : allowed extensions, lower case with the dot (``{".png", ".jpg"}``).
    force : allow replacing an existing file that is not an input and not a ``.mcap``.
    replace : the output is this program's own file, rewritten on every run (a
        reprocessing sidecar, the station's files): an existing one is replaced whatever
        its extension (still never an input).

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
    if (p.exists() or p.is_symlink()) and not replace:
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


def _fsync_path(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_folder(folder: Path) -> None:
    """Make a rename in ``folder`` durable (file systems that cannot are left as they are)."""
    with contextlib.suppress(OSError):
        _fsync_path(folder if str(folder) else Path("."))


def commit_part(
    tmp: PathLike, path: PathLike, *, force: bool = False, replace: bool = False
) -> None:
    """Rename a finished (already fsynced) ``.part`` file to its real name, then fsync the
    folder. An output that appeared meanwhile is refused at this last moment (the ``.part``
    removed), unless ``force`` and not a ``.mcap``, or ``replace`` (see :func:`check_output`).
    """
    t, p = Path(tmp), Path(path)
    _rename_part(t, p, force=force, replace=replace)
    _fsync_folder(p.parent)


def _rename_part(t: Path, p: Path, *, force: bool, replace: bool) -> None:
    try:
        if replace or (force and p.suffix.lower() != ".mcap"):
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


class PartFile:
    """An output file open for writing under its ``.part`` name, for writers that keep it
    open across calls and close it later (the MCAP writer, the ``.oni`` writer).

    The path is checked at once (:func:`check_output`); ``.STEM.part.EXT`` is created
    (one left by a crashed run is replaced). :meth:`commit` flushes, fsyncs, closes and
    renames it to the real name; :meth:`discard` closes and removes it. As a context
    manager: committed on a clean exit, discarded on an exception.

    Parameters
    ----------
    path, inputs, suffixes, force, replace : as :func:`check_output`.

    Attributes
    ----------
    path : the output's real name.
    part : the name it is written under until :meth:`commit`.
    file : the binary file, open for writing (seekable).

    Raises
    ------
    OutputPathError : the path may not be written, or the ``.part`` cannot be created.
    """

    def __init__(
        self,
        path: PathLike,
        *,
        inputs: Iterable[PathLike] = (),
        suffixes: Collection[str] | None = None,
        force: bool = False,
        replace: bool = False,
    ) -> None:
        self.path = check_output(
            path, inputs=inputs, suffixes=suffixes, force=force, replace=replace
        )
        self.part = part_path(self.path)
        self._force = force
        self._replace = replace
        try:
            self._file: IO[bytes] | None = open(self.part, "wb")  # noqa: SIM115
        except OSError as err:
            raise _os_error(self.path, err) from err

    @property
    def file(self) -> IO[bytes]:
        if self._file is None:
            raise OutputPathError(f"{self.path}: already committed or discarded")
        return self._file

    @property
    def closed(self) -> bool:
        return self._file is None

    def commit(self) -> None:
        """Flush, fsync, close, rename into place (and fsync the folder). On an error the
        ``.part`` is removed and :class:`OutputPathError` raised. Idempotent."""
        f, self._file = self._file, None
        if f is None:
            return
        try:
            try:
                f.flush()
                os.fsync(f.fileno())
            finally:
                f.close()
        except OSError as err:
            self.part.unlink(missing_ok=True)
            raise _os_error(self.path, err) from err
        commit_part(self.part, self.path, force=self._force, replace=self._replace)

    def discard(self) -> None:
        """Close and remove the ``.part``: nothing appears under the real name. Idempotent."""
        f, self._file = self._file, None
        if f is None:
            return
        try:
            with contextlib.suppress(OSError):  # a failed flush of what is thrown away anyway
                f.close()
        finally:
            self.part.unlink(missing_ok=True)

    def __enter__(self) -> PartFile:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.discard()


@contextlib.contextmanager
def atomic_output(
    path: PathLike,
    *,
    inputs: Iterable[PathLike] = (),
    suffixes: Collection[str] | None = None,
    force: bool = False,
    replace: bool = False,
) -> Iterator[IO[bytes]]:
    """Open ``path`` for writing through ``.STEM.part.EXT``: checked first
    (:func:`check_output`), flushed, fsynced and renamed on success, removed on any error
    (a :class:`PartFile` in a ``with`` block).
    """
    with PartFile(path, inputs=inputs, suffixes=suffixes, force=force, replace=replace) as out:
        yield out.file


@contextlib.contextmanager
def output_via_part(
    path: PathLike,
    *,
    inputs: Iterable[PathLike] = (),
    suffixes: Collection[str] | None = None,
    force: bool = False,
    replace: bool = False,
    fsync: bool = True,
) -> Iterator[Path]:
    """Like :func:`atomic_output` for writers that take a file name (rasterio, cv2,
    matplotlib): yields the ``.part`` path to write (the extension kept, for libraries that
    choose the format by it); fsynced and renamed on success, removed on error.

    ``fsync=False`` only for bulk files whose loss in a power cut costs nothing but a rerun
    (a dataset's images): the rename still keeps a half-written file from the real name.
    """
    p = check_output(path, inputs=inputs, suffixes=suffixes, force=force, replace=replace)
    tmp = part_path(p)
    try:
        tmp.unlink(missing_ok=True)  # left by a crashed run: never taken for this output
        yield tmp
        if not tmp.exists():
            raise OutputPathError(f"cannot write {p}: nothing was written")
        if fsync:
            _fsync_path(tmp)
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise _os_error(p, err) from err
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    commit_part(tmp, p, force=force, replace=replace)


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
        _fsync_folder(p.parent)
    except OSError as err:
        shutil.rmtree(tmp, ignore_errors=True)
        raise _os_error(p, err) from err
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
