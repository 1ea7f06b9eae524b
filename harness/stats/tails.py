"""How heavy are the tails of the contributions, and do they end: the largest deviations from a
centre on each side, kept across blocks (:class:`TailSample`), the tail index estimated from
them, and the signatures of a clamped or a truncated tail.

A tail index below 3 means the variance of the contributions is infinite or too unreliable to
build a normal-theory test on (the variance of the sample variance needs the fourth moment);
the bias test then says "inconclusive" instead of claiming a level, unless the tail is seen to
*end* (:meth:`Side.end`): a clamp (an atom at the maximum above continuous values) or a
truncation (the top of the tail compressed against a bound).  A tail that ends has a finite
variance whatever its index below the end, so a deficit of the mean can be proved.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

import reference_estimators as rest

from harness.stats import distributions

__all__ = ["TailSample", "Side", "TailEnd", "tail_index_of"]

_MIN_ORDER = 21          # order statistics below which no tail estimate is made
_TOP_SPACINGS = 20       # the topmost normalised spacings compared with the rest for truncation
_CONTINUOUS = 0.9        # share of distinct values below an atom for it to read as a clamp


@dataclass(frozen=True)
class TailEnd:
    """Where and how a tail ends: ``kind`` "clamp" (``count`` contributions equal the maximum
    ``value``) or "truncation" (the top spacings compressed, ``pvalue`` of the Pareto-tail
    model's F test)."""

    kind: str
    value: float
    count: int = 1
    pvalue: float = math.nan

    def __str__(self) -> str:
        if self.kind == "clamp":
            return f"clamped at {self.value:.6g} ({self.count} contributions equal it)"
        return f"tail truncated near {self.value:.6g} (top spacings compressed, p = {self.pvalue:.2g})"


class Side:
    """The largest deviations on one side of the centre: the maximum ``peak``, how many values
    equal it (``ties``, counted exactly across blocks) and the ``keep`` largest values strictly
    below it (``below``), so that an atom at the maximum is told from a continuous tail even
    when it holds more than ``keep`` values."""

    def __init__(self, keep: int, peak: float | None = None, ties: int = 0, below: Any = ()):
        self.keep, self.peak, self.ties = keep, peak, ties
        self.below = np.asarray(below, dtype=float)

    def add(self, y: np.ndarray, center: float, upper: bool) -> None:
        """Takes a block's deviations from ``center`` (y - center if ``upper``, else center - y;
        only the positive ones count), selected in one pass by the core."""
        peak, ties, below = rest.side_extremes(y, center, upper=upper, keep=self.keep)
        if ties:
            self.merge(Side(self.keep, peak, ties, below))

    def merge(self, other: Side) -> None:
        """Takes the extremes of another side (about the same centre) into this one."""
        if other.peak is None:
            return
        if self.peak is None or other.peak > self.peak:
            low, high = self, other
        elif other.peak < self.peak:
            low, high = other, self
        else:
            self.ties += other.ties
            self.below = self._top(np.concatenate([self.below, other.below]))
            return
        old = np.full(min(low.ties, self.keep), low.peak if low.peak is not None else 0.0)
        self.below = self._top(np.concatenate([low.below, old, high.below]))
        self.peak, self.ties = high.peak, high.ties

    def _top(self, d: np.ndarray) -> np.ndarray:
        m = min(self.keep, d.size)
        return np.sort(np.partition(d, d.size - m)[d.size - m:])[::-1] if m else d

    def descending(self) -> np.ndarray:
        """The ``keep`` + 1 largest deviations, ties included, largest first."""
        if self.peak is None:
            return np.empty(0)
        atom = np.full(min(self.ties, self.keep + 1), self.peak)
        return np.concatenate([atom, self.below])[: self.keep + 1]

    @classmethod
    def of_values(cls, keep: int, side: Mapping[str, Any], shift: float) -> Side:
        """The side of deviations d = v + ``shift`` > 0 from one side of rest.value_tails (v: the
        values, or -values for the lower side; shift -center or +center), in float64 as
        numpy computes them; values whose deviations round to the peak's count as its ties."""
        if side["peak"] is None:
            return cls(keep)
        peak = side["peak"] + shift
        if not peak > 0:
            return cls(keep)
        d = np.asarray(side["below"], dtype=float) + shift
        return cls(keep, peak, int(side["ties"]) + int(np.sum(d == peak)), d[(d < peak) & (d > 0)][:keep])

    def state(self) -> dict[str, Any]:
        """JSON-serialisable: what :meth:`from_state` restores."""
        return {"peak": self.peak, "ties": self.ties, "below": self.below.tolist()}

    @classmethod
    def from_state(cls, keep: int, state: Mapping[str, Any]) -> Side:
        return cls(keep, state["peak"], int(state["ties"]), state["below"])

    def tail_index(self) -> float:
        """1 / gamma of the moment estimator over the kept order statistics (inf when light,
        bounded or too few)."""
        return tail_index_of(self.descending())

    def end(self, level: float) -> TailEnd | None:
        """The tail's end, if its top shows one.

        Clamp: at least two values equal the maximum while the values below it are continuous
        (``_CONTINUOUS`` of them distinct): an estimator that is discrete by design (a rare
        event's 1/p, hit or miss) has few distinct values below its atom and is not a clamp.

        Truncation: under a Pareto-type tail the normalised log-spacings i log(x_i / x_{i+1})
        of the top k order statistics are independent exponentials of one mean (Renyi), so
        the mean of the top ``_TOP_SPACINGS`` over the mean of the rest is F(2j, 2(k - j)).
        A ratio in its lower ``level`` quantile says the top of the tail is compressed against
        a bound.  Light and bounded tails show it too (harmless: their variance is finite);
        a tail whose local index falls with the threshold (lognormal) shows it more often
        than ``level``, which the bias test's calibration measures."""
        if self.peak is None:
            return None
        if self.ties >= 2:
            continuous = np.unique(self.below).size >= _CONTINUOUS * self.below.size
            if self.below.size >= _MIN_ORDER - 1 and continuous:
                return TailEnd("clamp", self.peak, self.ties)
            return None
        desc = self.descending()
        desc = desc[desc > 0]
        k = desc.size - 1
        j = min(_TOP_SPACINGS, k // 4)
        if k < 2 * _MIN_ORDER or j < 5:
            return None
        spacings = np.arange(1, k + 1) * np.diff(-np.log(desc))
        rest = float(np.mean(spacings[j:]))
        if rest <= 0:
            return None
        p = float(distributions.f_cdf(float(np.mean(spacings[:j])) / rest, 2 * j, 2 * (k - j)))
        return TailEnd("truncation", float(desc[0]), 1, p) if p < level else None


class TailSample:
    """The largest deviations above and below a centre (the first values' upper median), kept
    across calls, for the tail estimates."""

    def __init__(self, keep: int):
        self.keep, self.center = keep, None
        self.up, self.down = Side(keep), Side(keep)

    @classmethod
    def for_count(cls, n: int) -> TailSample:
        """Keeps sqrt(n) order statistics per side (at least 50, at most 20 000)."""
        return cls(min(max(int(math.sqrt(n)), 50), 20_000))

    def add(self, y: np.ndarray) -> None:
        """Takes the finite values ``y`` of one block into the kept extremes."""
        if y.size == 0:
            return
        if self.center is None:  # a middle value, not an average of two: finite up to 1.8e308
            self.center = float(np.partition(y, y.size // 2)[y.size // 2])
        self.up.add(y, self.center, upper=True)
        self.down.add(y, self.center, upper=False)

    def state(self) -> dict[str, Any]:
        """JSON-serialisable: what :meth:`from_state` restores (see harness.suite.estimators)."""
        return {"keep": self.keep, "center": self.center, "upper": self.up.state(),
                "lower": self.down.state()}

    @classmethod
    def from_state(cls, state: Mapping[str, Any]) -> TailSample:
        t = cls(int(state["keep"]))
        t.center = state["center"]
        t.up, t.down = Side.from_state(t.keep, state["upper"]), Side.from_state(t.keep, state["lower"])
        return t

    @classmethod
    def from_parts(cls, parts: Sequence[Mapping[str, Any]], keep: int, part_keep: int) -> TailSample | None:
        """The tail sample of the union of several sets of values from each set's tails
        (rest.value_tails with ``part_keep`` per side, e.g. the bias test's units), about the
        first part's median; ``keep`` deviations per side, as :meth:`add` over all the values
        would keep them.  None where the parts cannot give that exactly: a part that kept only
        ``part_keep`` values below its peak may have had more above the ``keep``-th largest of
        the union (then the caller reads the values again: harness.suite.estimators)."""
        if not parts:
            raise ValueError("'parts' must hold the tails of at least one set of values")
        merged = rest.merge_tails(list(parts), keep)
        out = cls(keep)
        out.center = parts[0]["median"]
        for name in ("upper", "lower"):
            below = merged[name]["below"]
            bound = below[keep - 1] if len(below) >= keep else -math.inf  # the union's keep-th below the peak
            if any(len(p[name]["below"]) >= part_keep and p[name]["below"][-1] > bound for p in parts):
                return None
        if out.center is None:  # no finite value at all: no deviations
            return out
        out.up = Side.of_values(keep, merged["upper"], -out.center)
        out.down = Side.of_values(keep, merged["lower"], out.center)
        return out

    @property
    def upper(self) -> np.ndarray:
        """The largest deviations above the centre, largest first."""
        return self.up.descending()

    @property
    def lower(self) -> np.ndarray:
        """The largest deviations below the centre, largest first."""
        return self.down.descending()

    def tail_index(self) -> float:
        """The smaller tail index of the two sides (inf for bounded or light tails)."""
        return min(self.up.tail_index(), self.down.tail_index())


def tail_index_of(desc: np.ndarray) -> float:
    """1 / gamma from the moment estimator of the extreme-value index gamma (Dekkers, Einmahl
    & de Haan 1989) on descending order statistics: valid for heavy (gamma > 0), light
    (gamma = 0) and bounded (gamma < 0) tails alike, unlike Hill's.  inf when gamma <= 0."""
    desc = desc[desc > 0]
    if desc.size < _MIN_ORDER:
        return math.inf
    k = desc.size - 1
    logs = np.log(desc[:k]) - math.log(desc[k])
    m1, m2 = float(np.mean(logs)), float(np.mean(logs * logs))
    if m2 <= 0:
        return math.inf
    gamma = m1 + 1 - 0.5 / (1 - m1 * m1 / m2)
    return 1 / gamma if gamma > 0 else math.inf
