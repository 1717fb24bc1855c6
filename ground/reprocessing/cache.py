"""Finished partitions kept on disk, so an interrupted run or a rerun does only the rest.

One file per partition, ``KEY.pkl``, where the key hashes the log's content (its chunk
index, or every chunk's header with its CRC), the partition's chunk range and the detector
settings (:func:`ground.reprocessing.plan.partition_key`). Written by the client as results arrive
(through the output-path rule, :func:`outputs.atomic_output`: ``.KEY.part.pkl``, fsynced,
then renamed, so a killed run leaves no half file). The files are pickles made
by this program for this program: do not put files from elsewhere in the folder.
"""

from __future__ import annotations

import logging
import pickle
from pathlib import Path

from holescan.ground.reprocessing.task import PartitionResult
from holescan.outputs import atomic_output

__all__ = ["PartitionCache"]

_log = logging.getLogger(__name__)


class PartitionCache:
    """``get(key)`` / ``put(result)`` in ``folder`` (None: a cache that keeps nothing)."""

    def __init__(self, folder: Path | None) -> None:
        self.folder = folder
        if folder is not None:
            folder.mkdir(parents=True, exist_ok=True)

    def _path(self, key: str) -> Path:
        assert self.folder is not None
        return self.folder / f"{key}.pkl"

    def get(self, key: str) -> PartitionResult | None:
        if self.folder is None:
            return None
        path = self._path(key)
        try:
            with open(path, "rb") as f:
                result = pickle.load(f)
        except FileNotFoundError:
            return None
        except (OSError, pickle.UnpicklingError, EOFError, AttributeError, ImportError) as err:
            _log.warning("cached partition %s unreadable (%s): computing it again", path, err)
            return None
        if not isinstance(result, PartitionResult) or result.key != key:
            _log.warning("cached partition %s is not the expected one: computing it again", path)
            return None
        return result

    def put(self, result: PartitionResult) -> None:
        if self.folder is None:
            return
        with atomic_output(self._path(result.key), force=True) as f:
            pickle.dump(result, f, protocol=pickle.HIGHEST_PROTOCOL)
