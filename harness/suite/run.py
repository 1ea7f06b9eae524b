"""Runs a suite: plan every kind's work units, execute the missing ones, measure from what is
stored.

The kinds of case (harness.suite.estimators, .sampler_checks, .renders) implement one
protocol (harness.suite.kind); this module sees nothing else of them.  Units are stored as
they finish (SQLite), so a killed run resumes where it stopped, and a finished suite re-runs
without computing anything.  Threads run locally; ``dask`` sends the same jobs to a cluster.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import reference_estimators as rest

from harness.suite.estimators import EstimatorKind
from harness.suite.execute import JobResult, execute
from harness.suite.kind import CaseKind, Outcome
from harness.suite.parse import Suite
from harness.suite.renders import RenderKind
from harness.suite.sampler_checks import SamplerKind
from harness.suite.store import Store

__all__ = ["KINDS", "RunSummary", "run_suite", "kinds_of"]

KINDS: tuple[type, ...] = (EstimatorKind, SamplerKind, RenderKind)
_COMMIT_EVERY = 0.1  # seconds between commits: a kill loses at most this much finished work


@dataclass(frozen=True)
class RunSummary:
    """What a run measured: one :class:`Outcome` per kind of case (in the order of ``KINDS``),
    and how much work it planned and computed."""

    outcomes: tuple[Outcome, ...]
    units_planned: int
    units_run: int
    seconds: float
    db: Path
    run: int          # the run's number in the database (its measurements are stored under it)

    def __getitem__(self, kind: str) -> Outcome:
        """The outcome of one kind: "estimator", "sampler" or "render"."""
        for o in self.outcomes:
            if o.kind == kind:
                return o
        raise KeyError(f"no kind of case {kind!r}; expected one of {[o.kind for o in self.outcomes]}")

    @property
    def cases(self) -> int:
        return sum(len(o.names) for o in self.outcomes)

    @property
    def failed(self) -> int:
        return sum(o.failed for o in self.outcomes)


def kinds_of(suite: Suite) -> list[CaseKind]:
    """Every kind of case, built from the suite."""
    return [k(suite) for k in KINDS]


def run_suite(suite: Suite, db: str | Path, *, threads: int | None = None, dask: str | None = None,
              progress: Callable[[int, int], None] | None = None, wait: float = 60) -> RunSummary:
    """Runs what is missing from ``db`` for ``suite`` and measures every case from the store.
    ``progress(done, total)`` is called as units finish; ``wait``: seconds to wait for a lock
    another process holds on the database.  Errors of the database, the disk (full, not
    writable) or its images raise :class:`~harness.suite.store.StoreError` (one line naming
    the file and the cause); an unreachable Dask scheduler ClusterError."""
    start = time.perf_counter()
    threads = threads or suite.threads or rest.hardware_threads()
    store = Store(db, timeout=wait)   # StoreError naming the file if it cannot be opened
    finished = False
    try:
        with store.translated():
            summary = _run(suite, store, threads, dask, progress, start)
        finished = True
        return summary
    finally:
        store.close(quiet=not finished)


def _run(suite: Suite, store: Store, threads: int, dask: str | None,
         progress: Callable[[int, int], None] | None, start: float) -> RunSummary:
    run = store.start_run(suite.name, str(suite.path), suite.revision, suite.alpha, suite.families)
    kinds = kinds_of(suite)
    for k in kinds:
        k.register(store)
    done, last, ran, total = 0, time.perf_counter(), 0, 0
    planned: set = set()

    def sink(result: JobResult) -> None:
        nonlocal done, last
        for name, image in result.images.items():
            store.put_image(name, image)
        store.put(result.unit, result.payload, result.seconds)
        done += 1
        if result.images or time.perf_counter() - last > _COMMIT_EVERY:
            store.commit()
            last = time.perf_counter()
        if progress:
            progress(done, total)

    while True:  # one pass, plus one per further look of cases with a precision target
        jobs = [j for k in kinds for j in k.plan(store)]
        store.plan_units(suite.name, {j.unit for j in jobs} - planned)
        planned |= {j.unit for j in jobs}
        stored = store.stored_keys({j.unit.case_key for j in jobs})
        missing = [j for j in jobs if j.unit not in stored]
        total, done = len(planned), len(planned) - len(missing)
        ran += execute(missing, sink, threads=threads, dask=dask) if missing else 0
        store.commit()
        if not any([k.advance(store) for k in kinds]):
            break
    outcomes = tuple(k.outcome(store) for k in kinds)
    store.finish_run(run, [row for o in outcomes for row in o.rows], total, ran)
    return RunSummary(outcomes, total, ran, time.perf_counter() - start, store.path, run)
