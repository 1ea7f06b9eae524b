"""The permutation test of a log-log convergence slope: does the RMSE fall as n^b?

Replicas' squared errors sq (one per replica: an estimate's squared error, or an image's
relMSE) at budgets n_1 < ... < n_B.  The slope is the least-squares slope of log sqrt(mean sq)
on log n.  Under H0 "the RMSE falls as n^b" with errors of one shape at every budget (the
central limit theorem's regime, or any law that only scales), sq n^(-2b) are exchangeable
across budgets: the slope of the observed arrangement is one draw from the slopes of all
arrangements of the pooled values into groups of the budgets' sizes, whatever that shape is.
The p-value is the share of random arrangements whose slope reaches the observed one (the
observed arrangement counted in: (1 + hits) / (1 + draws)), exact at every replica count.

Written here rather than taken from scipy.stats.permutation_test: the statistic is one gather
and one segmented sum per arrangement, all arrangements in one array, and the same
arrangements serve every b of the interval's inversion (scipy redraws them per call, 30
calls an interval).

Why not the slope's parametric law: a budget's mean squared error over R normal estimates is
Gamma(R/2), but the law's shape had to be estimated from the squares' spread where the
estimates are not normal, and at the bound that test rejected t(5) errors at 7.6 % and
centred log-normal ones at 9.9 % for a stated 5 % (16 replicas, 3 budgets, 2000 seeds); this
test 5.05 % and 5.47 % (4000 seeds), with the same power on normal estimates (benchmarks/
convergence_calibration.py; README.md has the table).
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

__all__ = ["SlopePermutationTest"]

#: Arrangements are drawn in blocks of this many, block k from its own stream (seed, k): the
#: first blocks are the same for the p-value and for every interval, so the two agree
BLOCK = 2000
#: The arrangements an interval's end or a p-value at a tail q rests on: at least TAIL_HITS / q
#: (2000 at 95 %, 10 000 at 99 %), so that the end is 50 arrangements in
TAIL_HITS = 50
#: A p-value draws more blocks, doubling, while fewer than HITS arrangements reach the observed
#: slope, up to MAX_DRAWS: p-values down to 1 / (1 + 132 000), small enough for Holm over a
#: suite's cases
HITS = 10
MAX_DRAWS = 66 * BLOCK
#: Permuted slopes within this (times the weights' sum, the scale of a slope's rounding) of the
#: observed one reach it: the same groups summed in another order differ by rounding
_TIES = 1e-9
# the arrangements' stream (numpy's SeedSequence entropy beside the fit's seed and the block)
_STREAM = 0x51_0BE


class SlopePermutationTest:
    """The slope test of one fit: ``squares`` per budget (1-D arrays, one value per replica,
    >= 0), ``budgets`` their sample counts (distinct, at least 3); arrangements drawn from
    ``seed``.  Holds the squares' logs alone (the arrangements are drawn where used)."""

    def __init__(self, squares: Sequence[np.ndarray], budgets: Sequence[int], seed: int):
        sizes = np.array([np.size(s) for s in squares])
        log_n = np.log(np.asarray(budgets, dtype=np.float64))
        x = log_n - log_n.mean()
        self.weights = 0.5 * x / (x @ x)       # the slope per budget's 0.5 log(mean square)
        self._sizes = sizes
        self._starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        self._x = np.repeat(x, sizes)
        pooled = np.concatenate([np.asarray(s, dtype=np.float64).ravel() for s in squares])
        with np.errstate(divide="ignore", invalid="ignore"):   # a zero square: log -inf, its value 0
            self._log_squares = np.log(pooled)
        self._seed = seed
        self._ties = _TIES * max(1.0, float(np.abs(self.weights).sum()))

    @property
    def smallest_pvalue(self) -> float:
        """The smallest p-value the test can give: one over the distinct arrangements of the
        values into the budgets' groups (N! / prod R_j!), or over the most it draws."""
        arrangements = math.factorial(int(self._sizes.sum()))
        for r in self._sizes:
            arrangements //= math.factorial(int(r))
        return max(1 / arrangements, 1 / (1 + MAX_DRAWS))

    def slope(self, values: np.ndarray) -> np.ndarray:
        """The fitted slope of each row of values (..., N) grouped by budget: the weights on
        the log of each group's mean (floored at the smallest normal float)."""
        sums = np.add.reduceat(values, self._starts, axis=-1) / self._sizes
        return np.log(np.maximum(sums, np.finfo(np.float64).tiny)) @ self.weights

    def _block(self, k: int) -> np.ndarray:
        """Block k of the arrangements: (BLOCK, N) indices, each row a permutation."""
        n = self._log_squares.size
        rng = np.random.default_rng([self._seed, _STREAM, k])
        return rng.permuted(np.broadcast_to(np.arange(n, dtype=np.int32), (BLOCK, n)), axis=1)

    def _scaled(self, b: float) -> np.ndarray:
        """sq n^(-2b) over its largest value (the slope ignores one common scale): from the
        logs, so that no b overflows."""
        z = self._log_squares - 2.0 * b * self._x
        top = float(np.max(z))
        if not math.isfinite(top):
            return np.zeros_like(z) if top == -math.inf else np.full_like(z, math.nan)
        return np.exp(z - top)

    def _hits(self, b: float, blocks: Sequence[np.ndarray]) -> tuple[int, int, int]:
        """Arrangements among ``blocks`` whose slope under H0 "slope b" reaches the observed
        one from above and from below, and how many there are."""
        z = self._scaled(b)
        observed = float(self.slope(z))
        above = below = drawn = 0
        for block in blocks:
            permuted = self.slope(z[block])
            above += int(np.sum(permuted >= observed - self._ties))
            below += int(np.sum(permuted <= observed + self._ties))
            drawn += block.shape[0]
        return above, below, drawn

    @staticmethod
    def _blocks_for(tail: float) -> int:
        """Blocks a p-value or an interval end at ``tail`` rests on (at most MAX_DRAWS)."""
        return min(math.ceil(TAIL_HITS / tail / BLOCK), MAX_DRAWS // BLOCK)

    def pvalue_above(self, b: float, tail: float) -> float:
        """One-sided p-value of H0 "the RMSE falls at least as fast as n^b" (small where the
        fitted slope is measurably above b), judged at ``tail``: on the arrangements the
        interval at that tail uses, then more in doubling rounds while fewer than
        :data:`HITS` reach the observed slope (p < 11 / (1 + draws): both reject)."""
        blocks = self._blocks_for(tail)
        hits, _, drawn = self._hits(b, (self._block(k) for k in range(blocks)))
        while hits < HITS and blocks < MAX_DRAWS // BLOCK:
            more = range(blocks, min(2 * blocks, MAX_DRAWS // BLOCK))
            h, _, d = self._hits(b, (self._block(k) for k in more))
            hits, drawn, blocks = hits + h, drawn + d, more.stop
        return (1 + hits) / (1 + drawn)

    def interval(self, slope: float, tail: float) -> tuple[float, float]:
        """The slopes b that neither one-sided test rejects at ``tail``: the low end where
        the share of arrangements reaching the observed slope from above first reaches
        ``tail``, the high end likewise from below ((nan, nan) where every square is 0)."""
        if not np.any(np.isfinite(self._log_squares)):
            return math.nan, math.nan
        blocks = [self._block(k) for k in range(self._blocks_for(tail))]

        def above(b: float) -> bool:     # b is inside, seen from the low end
            h, _, m = self._hits(b, blocks)
            return (1 + h) / (1 + m) >= tail

        def below(b: float) -> bool:
            _, h, m = self._hits(b, blocks)
            return (1 + h) / (1 + m) >= tail

        spread = float(np.std(self.slope(self._scaled(slope)[blocks[0]])))
        step = max(spread, 1e-9 * (1 + abs(slope)))
        return _edge(above, slope, -step), _edge(below, slope, step)


def _edge(inside: Callable[[float], bool], start: float, step: float) -> float:
    """The end of the run of b where ``inside`` holds, from ``start`` toward the sign of
    ``step``: a bracket widened by doubling steps (none found in 60: an infinite end), then
    bisection to 1e-6 of ``step`` or a few ulps (at most 100 halvings)."""
    if not inside(start):
        return start
    inner, outer = start, start + step
    for _ in range(60):
        if not inside(outer):
            break
        inner, outer = outer, outer + 2 * (outer - inner)
    else:
        return math.copysign(math.inf, step)
    for _ in range(100):
        if abs(outer - inner) <= max(1e-6 * abs(step), 4 * np.spacing(abs(inner))):
            break
        mid = 0.5 * (inner + outer)
        inner, outer = (mid, outer) if inside(mid) else (inner, mid)
    return 0.5 * (inner + outer)
