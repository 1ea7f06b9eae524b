"""How heavy are the tails of the contributions: the largest deviations from a centre, kept
across blocks (:class:`TailSample`), and the tail index estimated from them.

A tail index below 3 means the variance of the contributions is infinite or too unreliable to
build a normal-theory test on (the variance of the sample variance needs the fourth moment);
the bias test then says "inconclusive" instead of claiming a level.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = ["TailSample"]


class TailSample:
    """The largest deviations above and below a centre (the first values' upper median), kept
    across calls, for the tail estimates."""

    def __init__(self, keep: int):
        self.keep, self.center = keep, None
        self.upper, self.lower = np.empty(0), np.empty(0)

    @classmethod
    def for_count(cls, n: int) -> TailSample:
        """Keeps sqrt(n) order statistics per side (at least 50, at most 20 000)."""
        return cls(min(max(int(math.sqrt(n)), 50), 20_000))

    def add(self, y: np.ndarray) -> None:
        """Takes the finite values ``y`` of one block into the kept extremes."""
        if self.center is None:  # a middle value, not an average of two: finite up to 1.8e308
            self.center = float(np.partition(y, y.size // 2)[y.size // 2])
        self.upper = self._top(np.concatenate([self.upper, self._top(y - self.center)]))
        self.lower = self._top(np.concatenate([self.lower, self._top(self.center - y)]))

    def _top(self, d: np.ndarray) -> np.ndarray:
        d = d[d > 0]
        m = min(self.keep + 1, d.size)
        return np.partition(d, d.size - m)[d.size - m:] if m else d

    @classmethod
    def from_tops(cls, upper: Sequence[float], lower: Sequence[float]) -> TailSample:
        """A tail sample from stored largest deviations (see harness.suite.execute)."""
        t = cls(max(len(upper), len(lower)))
        t.upper, t.lower = np.asarray(upper, dtype=float), np.asarray(lower, dtype=float)
        return t

    def tail_index(self) -> float:
        """The smaller tail index of the two sides (inf for bounded or light tails)."""
        return min(_tail_index(np.sort(self.upper)[::-1]), _tail_index(np.sort(self.lower)[::-1]))


def _tail_index(desc: np.ndarray) -> float:
    """1 / gamma from the moment estimator of the extreme-value index gamma (Dekkers, Einmahl
    & de Haan 1989) on descending order statistics: valid for heavy (gamma > 0), light
    (gamma = 0) and bounded (gamma < 0) tails alike, unlike Hill's.  inf when gamma <= 0."""
    desc = desc[desc > 0]
    if desc.size < 21:
        return math.inf
    k = desc.size - 1
    logs = np.log(desc[:k]) - math.log(desc[k])
    m1, m2 = float(np.mean(logs)), float(np.mean(logs * logs))
    if m2 <= 0:
        return math.inf
    gamma = m1 + 1 - 0.5 / (1 - m1 * m1 / m2)
    return 1 / gamma if gamma > 0 else math.inf
