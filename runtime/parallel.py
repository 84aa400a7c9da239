"""An ordered parallel map over local processes or a Ray cluster.

Simulated episodes and experiment runs are independent, CPU-bound and seeded, so the
results do not depend on where they run. Local spawned processes are the default; Ray
(`pip install 'neural-asm[ray]'`) lets a sweep outgrow one machine: it joins the cluster
named by ``RAY_ADDRESS`` when set (every node needs this project installed, as workers import
it), and otherwise starts a local instance with `workers` CPUs.
"""

from __future__ import annotations

import os
import signal
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from multiprocessing import get_context
from itertools import repeat
from typing import Any, Literal, get_args

from tqdm.auto import tqdm

Backend = Literal["processes", "ray"]
BACKENDS: tuple[str, ...] = get_args(Backend)


@dataclass(frozen=True)
class Parallel:
    """Where independent jobs run: `workers` local processes, or a Ray cluster (`workers`
    CPUs of a local instance when no cluster is named)."""

    workers: int = 2
    backend: Backend = "processes"

    def __post_init__(self) -> None:
        if self.backend not in BACKENDS:
            raise ValueError(f"backend must be one of {BACKENDS}, got {self.backend!r}")
        if self.workers < 1:
            raise ValueError(f"workers must be >= 1, got {self.workers}")

    def map(self, fn: Callable[..., Any], args: Sequence[tuple], **options: Any) -> list[Any]:
        """``parallel_map`` here (options: initializer, desc, unit, progress, chunksize)."""
        return parallel_map(fn, args, self, **options)


def parallel_map(
    fn: Callable[..., Any],
    args: Sequence[tuple],
    where: Parallel = Parallel(),
    initializer: Callable[[], None] | None = None,
    desc: str = "jobs",
    unit: str = "job",
    progress: bool = True,
    chunksize: int = 1,
) -> list[Any]:
    """``[fn(*a) for a in args]``, in order, run ``where`` says: local processes or Ray.

    `fn` and `initializer` must be importable module-level functions (they are sent to
    other processes); `initializer` runs once per process before its first job (on Ray,
    before every job: Ray reuses worker processes without telling). Local
    processes take `chunksize` jobs at a time: more amortises many short jobs, 1 balances
    long uneven ones.
    """
    if not args:
        return []
    bar = tqdm(total=len(args), desc=desc, unit=unit, disable=not progress)
    try:
        if where.backend == "ray":
            return _ray_map(fn, args, where.workers, initializer, bar)
        if where.workers == 1:
            if initializer is not None:
                initializer()
            results = []
            for a in args:
                results.append(fn(*a))
                bar.update()
            return results
        return _process_map(fn, args, where.workers, initializer, chunksize, bar)
    finally:
        bar.close()


def _process_map(fn, args, workers, initializer, chunksize, bar) -> list[Any]:
    """Ctrl-C reaches the whole process group; only this process answers it: the workers
    ignore it (no traceback from each), and the pool is shut down without waiting for them."""
    results = []
    pool = ProcessPoolExecutor(workers, mp_context=get_context("spawn"), initializer=_worker_start,
                               initargs=(initializer,))
    try:
        for result in pool.map(_apply, repeat(fn), args, chunksize=chunksize):
            results.append(result)
            bar.update()
    except BaseException:
        running = list((pool._processes or {}).values())  # the jobs already running are stopped too
        pool.shutdown(wait=False, cancel_futures=True)
        for process in running:
            process.terminate()
        raise
    pool.shutdown()
    return results


def _worker_start(initializer: Callable[[], None] | None) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if initializer is not None:
        initializer()


def _apply(fn, args):
    return fn(*args)


def _run_initialised(initializer, fn, *args):
    if initializer is not None:
        initializer()
    return fn(*args)


def _ray_map(fn, args, workers, initializer, bar) -> list[Any]:
    try:
        import ray
    except ImportError as err:
        raise RuntimeError("the ray backend needs Ray: pip install 'neural-asm[ray]'") from err
    started_here = not ray.is_initialized()
    if started_here:
        if _joins_cluster():  # ray.init reads RAY_ADDRESS itself
            ray.init(log_to_driver=False, configure_logging=False)
        else:  # a fresh local instance, never one that happens to be running already
            ray.init(address="local", num_cpus=workers, include_dashboard=False,
                     log_to_driver=False, configure_logging=False)
    try:
        task = ray.remote(_run_initialised)
        refs = [task.remote(initializer, fn, *a) for a in args]
        index = {ref: i for i, ref in enumerate(refs)}
        results: list[Any] = [None] * len(args)
        pending = list(refs)
        try:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                results[index[done[0]]] = ray.get(done[0])
                bar.update()
        finally:
            for ref in pending:  # a failed job: do not leave the others running on a shared cluster
                ray.cancel(ref)
        return results
    finally:
        if started_here:
            ray.shutdown()


def _joins_cluster() -> bool:
    return bool(os.environ.get("RAY_ADDRESS"))
