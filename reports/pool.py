"""Draws many figures at once on worker processes: matplotlib spends ~0.2 s of pure Python
per figure and holds the GIL, so threads would not help and processes do.

Workers are forked (Linux), which costs milliseconds where a fresh interpreter would spend a
second importing matplotlib; forking is only done from a process running no other thread (a
forked child inherits no locks held by threads that do not exist), else, or with fewer than
``MIN_PER_WORKER`` figures per worker, the figures are drawn here, one after the other.
"""
from __future__ import annotations

import multiprocessing
import os
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any, TypeVar

__all__ = ["draw_all", "MIN_PER_WORKER"]

T = TypeVar("T")
MIN_PER_WORKER = 4


def _call(job: tuple[Callable[..., T], tuple[Any, ...]]) -> T:
    fn, args = job
    return fn(*args)


def draw_all(jobs: Sequence[tuple[Callable[..., T], tuple[Any, ...]]], *,
             workers: int | None = None) -> list[T]:
    """``[fn(*args) for fn, args in jobs]``, in order, on up to ``workers`` processes
    (default: the CPUs this process may use, at most 8).  ``fn`` must be a module-level function."""
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    n = min(workers or min(cpus, 8), len(jobs) // MIN_PER_WORKER)
    if n < 2 or threading.active_count() > 1 or "fork" not in multiprocessing.get_all_start_methods():
        return [_call(j) for j in jobs]
    with ProcessPoolExecutor(n, mp_context=multiprocessing.get_context("fork")) as pool:
        return list(pool.map(_call, jobs))
