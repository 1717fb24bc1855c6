"""Set up each Dask worker process for one detection at a time (imported on the workers).

A worker runs one task per core: the detector's own thread pools (OpenCV's, numba's) must
not each take every core too, or two workers on two cores oversubscribe them four times.
Dask already sets ``OMP_NUM_THREADS=1`` (and MKL's, OpenBLAS's) in the workers it starts;
OpenCV's pool is not covered by those. A worker plugin reaches every worker, also one
started later (a restarted worker, a worker joining an existing cluster).
"""

from __future__ import annotations

import os
from typing import Any

from distributed.diagnostics.plugin import WorkerPlugin

__all__ = ["SingleThreaded"]


class SingleThreaded(WorkerPlugin):
    """One thread for OpenCV and numba in each worker process."""

    name = "holescan-single-threaded"

    def setup(self, worker: Any) -> None:
        del worker
        os.environ.setdefault("NUMBA_NUM_THREADS", "1")  # before numba is first imported
        import cv2

        cv2.setNumThreads(1)
