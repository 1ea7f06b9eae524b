"""Executes work units locally on threads or on a Dask cluster; the caller's process is the
only writer to the store, so a result is stored exactly once, whoever computed it.

A job is a small frozen object naming its :class:`~harness.suite.plan.Unit` and holding the
plain values (names, numbers, JSON) its ``run()`` needs, so Dask workers need nothing but the
installed package, and a unit's result is the same bits wherever it runs.  Each kind of case
defines its jobs (harness.suite.estimators, .sampler_checks, .renders).

Jobs marked ``serial`` (renders: Mitsuba and OpenGL use every core themselves and keep
per-process contexts) run one at a time: in the caller's thread locally, one after another on
the cluster under Dask, after the parallel jobs, so their wall times measure one render alone.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from harness.suite.plan import Unit

__all__ = ["Job", "JobResult", "ClusterError", "run_local", "run_dask", "execute"]


class ClusterError(RuntimeError):
    """The Dask scheduler cannot be reached (one line naming its address and the cause)."""


@dataclass(frozen=True)
class JobResult:
    """What a job computed: the unit's stored payload (JSON-able), its wall time (s) and the
    images to store beside the database (name -> float array (height, width, channels))."""

    unit: Unit
    payload: dict[str, Any]
    seconds: float
    images: dict[str, np.ndarray] = field(default_factory=dict)


class Job(Protocol):
    """One unit of work: ``run()`` computes the unit's payload from plain values."""

    unit: Unit
    serial: bool

    def run(self) -> JobResult: ...


def _run(job: Job) -> JobResult:
    return job.run()


def run_local(jobs: list[Job], threads: int) -> Iterator[JobResult]:
    """Parallel jobs on a thread pool (the core releases the GIL), results in order; then the
    serial ones in this thread."""
    parallel = [j for j in jobs if not j.serial]
    if parallel:
        pool = ThreadPoolExecutor(max_workers=max(threads, 1))
        try:
            yield from pool.map(_run, parallel)
        finally:  # interrupted (Ctrl-C, a failing sink): queued jobs are dropped, running ones end
            pool.shutdown(wait=True, cancel_futures=True)
    for j in jobs:
        if j.serial:
            yield j.run()


_CONNECT_TIMEOUT = "10s"   # how long to try a scheduler's address before giving up


def run_dask(jobs: list[Job], address: str, threads: int) -> Iterator[JobResult]:
    """Jobs on a Dask cluster: ``address`` of a scheduler, or "local" for a LocalCluster of
    ``threads`` single-threaded worker processes.  Serial jobs go one at a time."""
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = LocalCluster(n_workers=max(threads, 1), threads_per_worker=1, processes=True,
                           dashboard_address=None) if address == "local" else None
    try:
        client = Client(cluster if cluster is not None else address, timeout=_CONNECT_TIMEOUT)
    except (OSError, TimeoutError, ValueError) as e:  # unreachable, refused, or not an address
        if cluster is not None:
            cluster.close()
        raise ClusterError(f"cannot reach the Dask scheduler at {address}: "
                           f"{str(e).splitlines()[0] if str(e) else type(e).__name__}") from None
    try:
        parallel = [j for j in jobs if not j.serial]
        if parallel:
            for fut in as_completed(client.map(_run, parallel, pure=False)):
                yield fut.result()
        for j in jobs:
            if j.serial:
                yield client.submit(_run, j, pure=False).result()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def execute(jobs: Iterable[Job], sink: Callable[[JobResult], None], *, threads: int,
            dask: str | None = None) -> int:
    """Computes the jobs and hands each result to ``sink``; returns how many ran."""
    jobs = list(jobs)
    results = run_dask(jobs, dask, threads) if dask else run_local(jobs, threads)
    n = 0
    for result in results:
        sink(result)
        n += 1
    return n
