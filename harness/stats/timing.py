"""The wall time of one estimate from its replicas' times, the time's standard error from
blocks of consecutive replicas, and the degrees of freedom of errors combined from such parts:
what every efficiency figure (the core's, a user's, a renderer's) times with.

The reference clock (:data:`CLOCK`, :func:`reference_clock`) is a fixed piece of work timed
beside each replica, on the same thread just before it: the replicas' time over the clock's
is their time in clock ticks (:func:`clock_time`), from which the machine's state (its clock
speed, what else runs on it, which process it is) cancels, as it cancels from the ratio of
two techniques whose replicas ran interleaved."""
from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np

import reference_estimators as rest

__all__ = ["CLOCK", "reference_clock", "clock_time", "median_time", "time_blocks", "satterthwaite"]

# The reference clock: uniform Monte Carlo of the catalogue's gaussian over one core chunk
# (65 536 samples) on one thread, always the same seed, so always the same work, run twice
# just before the replica on the replica's thread and timed the second time.  Why this kernel:
# it runs the path every catalogue replica runs (the core's points, integrand and accumulator,
# called from Python), so it slows down with what slows a replica down (clock speed, the other
# thread of the suite or other jobs on the core and its caches, the process's state).  Why one
# chunk: a clock shorter than a replica, or the fastest of several ticks, is disturbed less
# than the replica by a busy neighbour, and the time in clock units then moves with the load
# (measured, 96 replicas of gaussian at 62 500 samples, with and without a busy process on
# the other core: time in clock units changed by -4 % (uniform) and -9 % (importance:linear)
# for one tick of 16 384 samples, -2 % and -4 % for the fastest of 3 such ticks, -0.1 % and
# -0.5 % for one tick of a whole chunk).  Why the second tick: the first one after the worker
# thread picks up a unit runs with cold caches and predictors, a cost that differs from one
# process to the next, while the replica after it runs warm; timed cold, the clock made the
# figure in ticks vary more between fresh processes than the figure in seconds (SD of log10
# 0.042 against 0.0065, uniform MC, idle machine), timed warm 0.003-0.006, and its interval
# then covers the median of 20 fresh runs as often as it claims (benchmarks/
# efficiency_coverage.py: 58/60 and 57/60 at 95 %, against 12/20 and 18/20 timed cold).  Its
# cost, about 0.4 ms per unit of a replica (at most 1/16 of the unit's work once a replica
# holds 32 chunks), is paid only by the cases that measure efficiency, for the replicas of
# their largest budget.  The clock's description is part of every estimator case's key:
# changing it makes every stored clock reading stale.
CLOCK = {"integrand": "gaussian", "technique": "uniform", "samples": 65536, "seed": 0, "case_id": 0xC10C,
         "replica": 0, "version": 3, "ticks": "the second of two"}


def reference_clock() -> float:
    """Wall time (s) of one reading of the reference clock (:data:`CLOCK`) on this thread, now:
    the second of two runs of its work, back to back (the first warms the caches)."""
    f = rest.integrand(CLOCK["integrand"])
    t = rest.technique(f, CLOCK["technique"])

    def tick() -> None:
        rest.integrate_chunks(f, t, CLOCK["samples"], 0, 1, seed=CLOCK["seed"], case_id=CLOCK["case_id"],
                              replica=CLOCK["replica"], threads=1)

    tick()
    start = time.perf_counter()
    tick()
    return time.perf_counter() - start


def clock_time(seconds: np.ndarray, clock: np.ndarray) -> tuple[float, float]:
    """Time of one estimate in clock ticks, and its standard error, from each replica's time
    and the clock's reading beside it (same order, same length): the median time over the
    median reading, so the figure in ticks is the one in seconds over the run's clock
    (exactly: what a reader can check).  Its standard error is the spread between blocks of
    4 consecutive replicas (as :func:`median_time`) of each block's median time over its
    median reading: it sees what the machine's state of the moment leaves of the ratio, so,
    unlike the time in seconds, it describes other runs too.  Medians per block, not the
    replica-by-replica ratio: a replica or a reading that shared its core with something else
    (a 4 ms time slice, on a busy machine) is then one outlier of its series, not of both."""
    t, c = np.asarray(seconds, dtype=np.float64), np.asarray(clock, dtype=np.float64)
    if t.shape != c.shape:
        raise ValueError(f"'clock' must have one time per replica: {c.shape} against {t.shape} replica times")
    if not np.all(c > 0):
        raise ValueError(f"'clock' times must be positive, got min {float(np.min(c)) if c.size else 'none'}")
    ticks = float(np.median(t) / np.median(c))
    if t.size < 2:
        return ticks, math.nan
    blocks = time_blocks(t.size)
    ratios = np.array([np.median(bt) / np.median(bc)
                       for bt, bc in zip(np.array_split(t, blocks), np.array_split(c, blocks))])
    return ticks, float(np.std(ratios, ddof=1) / math.sqrt(blocks))


def median_time(seconds: np.ndarray) -> tuple[float, float]:
    """Wall time of one estimate (s) from R replicas' times, in the order they ran: the median,
    and its standard error from the spread between blocks of 4 consecutive replicas (at least
    2 blocks): SD of the block medians / sqrt(blocks).  Between blocks, because the machine's
    speed drifts during a run: replicas that ran back to back share a state of the machine, so
    the spread within a block understates the time's uncertainty (measured: 11x on 8 blocks of
    32 replicas).  The median, because a replica that shared its core with something else is an
    outlier of the machine, not of the technique."""
    t = np.asarray(seconds, dtype=np.float64)
    med = float(np.median(t))
    if t.size < 2:
        return med, math.nan
    blocks = time_blocks(t.size)
    medians = np.array([np.median(b) for b in np.array_split(t, blocks)])
    return med, float(np.std(medians, ddof=1) / math.sqrt(blocks))


def time_blocks(replicas: int) -> int:
    """How many blocks of consecutive replicas :func:`median_time` compares: the time's standard
    error has ``time_blocks - 1`` degrees of freedom."""
    return max(2, replicas // 4)


def satterthwaite(parts: Sequence[tuple[float, float]]) -> float:
    """Degrees of freedom of a sum of independent squared standard errors, each given as
    (standard error, its degrees of freedom): the Welch-Satterthwaite approximation."""
    num = sum(s * s for s, _ in parts) ** 2
    den = sum(s ** 4 / df for s, df in parts if s > 0)
    return num / den if den > 0 else math.inf
