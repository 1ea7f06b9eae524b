"""The wall time of one estimate from its replicas' times, the time's standard error from
blocks of consecutive replicas, and the degrees of freedom of errors combined from such parts:
what every efficiency figure (the core's, a user's, a renderer's) times with."""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = ["median_time", "time_blocks", "satterthwaite"]


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
