"""How much room the flight log's disk has left: a small protocol, so the writer, the
pre-flight disk budget and the retention rule can be given a fake disk in tests and a
real one (:class:`SystemDiskSpace`) in flight."""

from __future__ import annotations

import os
import shutil
from typing import Protocol, runtime_checkable

__all__ = ["DiskSpace", "SystemDiskSpace"]


@runtime_checkable
class DiskSpace(Protocol):
    """Anything that says how many bytes can still be written under a folder."""

    def free_bytes(self, folder: str | os.PathLike[str]) -> int:
        """Bytes an unprivileged writer can still put in ``folder``'s file system."""
        ...


class SystemDiskSpace:
    """The real file system's free space (``shutil.disk_usage``: what ``df`` shows as
    available, i.e. without the blocks reserved for root)."""

    def free_bytes(self, folder: str | os.PathLike[str]) -> int:
        return int(shutil.disk_usage(folder).free)
