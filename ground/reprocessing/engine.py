"""The engine: partition tasks run on Dask, results handed back in task order.

A :class:`distributed.LocalCluster` of ``workers`` single-threaded processes by default, or
the cluster of an existing scheduler (``scheduler="tcp://HOST:8786"``: a plain Dask
client, so dask-jobqueue, Kubernetes or hand-started ``dask worker`` processes all work).
``workers=0`` runs the same tasks in this process, one after the other (no cluster).

Finished partitions come from / go to the :class:`~ground.reprocessing.cache.PartitionCache`. The
scheduler retries the tasks of a worker that dies (``distributed.scheduler.allowed-failures``);
each partition's result is used once, by its index, however often it was computed.
Results are handed to ``on_result`` strictly in task order (buffered until the earlier
ones are in), so the merge on the client does not depend on which worker finished first.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib.util
import logging
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from holescan.errors import HolescanError
from holescan.ground.errors import EngineError
from holescan.ground.reprocessing.cache import PartitionCache
from holescan.ground.reprocessing.options import ReprocessOptions
from holescan.ground.reprocessing.plan import PartitionTask
from holescan.ground.reprocessing.task import PartitionResult, run_partition

__all__ = ["EngineError", "EngineStats", "TaskStats", "run_tasks"]

_log = logging.getLogger(__name__)

_POLL_S = 0.05


@dataclasses.dataclass(frozen=True)
class TaskStats:
    """One partition's numbers (what it found went to ``on_result``)."""

    key: str
    frames: int
    read_s: float
    detect_s: float
    worker: str
    peak_rss_mib: float
    cached: bool


@dataclasses.dataclass
class EngineStats:
    """What the engine did. dashboard : the Dask dashboard's address (None without one).
    start_s : cluster start-up (or connection). computed / cached : partitions.
    workers : worker processes seen. results : each partition's numbers, in task order."""

    dashboard: str | None = None
    start_s: float = 0.0
    computed: int = 0
    cached: int = 0
    workers: int = 0
    stopped: bool = False
    results: list[TaskStats] = dataclasses.field(default_factory=list)
    taken: set[int] = dataclasses.field(default_factory=set)


OnResult = Callable[[PartitionTask, PartitionResult, bool], None]
"""``on_result(task, result, cached)``: called in task order."""
OnTick = Callable[[EngineStats], None]


@contextlib.contextmanager
def _client(opts: ReprocessOptions, stats: EngineStats) -> Iterator[Any]:
    from distributed import Client, LocalCluster  # a dependency of the ground side only

    t0 = time.monotonic()
    dashboard = importlib.util.find_spec("bokeh") is not None
    if opts.scheduler is not None:
        try:
            client = Client(opts.scheduler, timeout="20s")  # type: ignore[no-untyped-call]
        except (OSError, TimeoutError) as err:
            raise EngineError(f"cannot reach the Dask scheduler {opts.scheduler}: {err}") from err
        cluster = None
    else:
        cluster = LocalCluster(  # type: ignore[no-untyped-call]
            n_workers=opts.workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":8787" if dashboard else None,
            silence_logs=logging.ERROR,
        )
        client = Client(cluster)  # type: ignore[no-untyped-call]
    try:
        from holescan.ground.reprocessing.worker import (
            SingleThreaded,
        )  # imports distributed: only here

        client.register_plugin(SingleThreaded())
        n = max(1, opts.workers) if cluster is not None else 1
        client.wait_for_workers(n, timeout=120)
        stats.workers = len(client.scheduler_info(n_workers=-1)["workers"])
        stats.dashboard = client.dashboard_link if dashboard else None
        stats.start_s = time.monotonic() - t0
        yield client
    finally:
        client.close()  # type: ignore[no-untyped-call]
        if cluster is not None:
            cluster.close()


def run_tasks(
    tasks: Sequence[PartitionTask],
    opts: ReprocessOptions,
    cache: PartitionCache,
    on_result: OnResult,
    *,
    stop: threading.Event | None = None,
    tick: OnTick | None = None,
) -> EngineStats:
    """Run ``tasks`` (see the module docstring); ``stop`` set: submit nothing more, cancel
    what is not finished, return (``stats.stopped``)."""
    stop = stop or threading.Event()
    stats = EngineStats()
    ready: dict[int, tuple[PartitionResult, bool]] = {}
    delivered = [0]

    def deliver() -> None:
        while delivered[0] in ready:
            i = delivered[0]
            result, cached = ready.pop(i)
            stats.results.append(
                TaskStats(
                    result.key,
                    result.frames,
                    result.read_s,
                    result.detect_s,
                    result.worker,
                    result.peak_rss_mib,
                    cached,
                )
            )
            on_result(tasks[i], result, cached)
            delivered[0] += 1
        if tick is not None:
            tick(stats)

    todo: list[int] = []
    for i, task in enumerate(tasks):
        hit = cache.get(task.key)
        if hit is None:
            todo.append(i)
        else:
            ready[i] = (hit, True)
            stats.cached += 1
    deliver()
    if not todo:
        return stats
    if opts.workers == 0 and opts.scheduler is None:
        for i in todo:
            if stop.is_set():
                stats.stopped = True
                break
            result = run_partition(tasks[i])
            cache.put(result)
            stats.computed += 1
            ready[i] = (result, False)
            deliver()
        return stats
    with _client(opts, stats) as client:
        if tick is not None:
            tick(stats)
        _run_on_cluster(client, tasks, todo, cache, stats, ready, deliver, stop)
    return stats


def _dask_key(task: PartitionTask) -> str:
    """Unique per task (two flights with the same bytes are still two pieces of work)."""
    return f"holescan-partition-{task.flight}-{task.number}-{task.key}"


def _run_on_cluster(
    client: Any,
    tasks: Sequence[PartitionTask],
    todo: list[int],
    cache: PartitionCache,
    stats: EngineStats,
    ready: dict[int, tuple[PartitionResult, bool]],
    deliver: Callable[[], None],
    stop: threading.Event,
) -> None:
    from distributed import as_completed

    futures = {client.submit(run_partition, tasks[i], key=_dask_key(tasks[i])): i for i in todo}
    pending = set(futures)
    done = as_completed(futures)  # type: ignore[no-untyped-call]
    try:
        while not done.is_empty():  # type: ignore[no-untyped-call]
            if stop.is_set():  # also when no result comes (workers gone): poll, do not block
                stats.stopped = True
                break
            batch = done.next_batch(block=False)  # type: ignore[no-untyped-call]
            if not batch:
                time.sleep(_POLL_S)
                continue
            for fut in batch:
                pending.discard(fut)
                _take(fut, futures[fut], tasks, cache, stats, ready)
            deliver()
    finally:
        if pending:
            client.cancel(list(pending))


def _take(
    fut: Any,
    i: int,
    tasks: Sequence[PartitionTask],
    cache: PartitionCache,
    stats: EngineStats,
    ready: dict[int, tuple[PartitionResult, bool]],
) -> None:
    if i in stats.taken:
        return  # used once, however often it was computed
    stats.taken.add(i)
    try:
        result: PartitionResult = fut.result()
    except HolescanError:
        raise
    except Exception as err:
        raise EngineError(
            f"partition {tasks[i].number} of {tasks[i].url} failed: {type(err).__name__}: {err}"
        ) from err
    cache.put(result)
    stats.computed += 1
    ready[i] = (result, False)
