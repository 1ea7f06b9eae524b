"""The probability-integral (Rosenblatt) transform of a sampler's points through the claimed
density, and the tests on the transformed points that see below any bin width.

In the domain's equal-measure parameter space (:mod:`harness.samplers.domains`) the claimed
density q(s) gives, for a point s,

    u0 = F0(s0)                       the marginal CDF of the first coordinate;
    u1 = F1(s1 | s0 in strip g)       on the square, the CDF of the second coordinate given
                                      the strip of s0 it lies in: G strips of equal claimed
                                      mass (u0 in [g/G, (g+1)/G)).

Under H0 (the points have density q) u0 and u1 are each exactly uniform on [0, 1]: given the
strip, s1 follows the strip's conditional law, whatever the strip.  So a smooth warp that no
bin resolves (an azimuth u^1.005, a lobe 0.3 % too wide) moves the empirical CDF of u0 or u1,
which the Cramer-von Mises test (:mod:`harness.samplers.cramer_von_mises`) sees; and the strips
with bins of u1 are cells of equal claimed probability (:meth:`Transform.statistics`): a
narrow lobe gets as many cells as the rest of the sphere.

The CDFs are tabulated once per claimed pdf (:class:`Transform`, sample-independent) by
adaptive cubature (:mod:`harness.samplers.cdf_tables`); the bound on |table - CDF| they reach
is :attr:`Transform.error`, in units of the strip's mass, and the tests carry it: a statistic
is computed as if every u were that much off in its favour.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

import reference_estimators as rest

from harness.samplers.cdf_tables import AxisCdf, Breaks, tabulate

__all__ = ["AxisCdf", "Transform"]

#: Strips of equal claimed mass along s0 on the square (the conditioning of u1), each
#: integrated across as SUBSTRIPS boxes of equal claimed mass.
STRIPS = 32
SUBSTRIPS = 4
_MARGINAL_PIECES = 32   # boxes across the square for the marginal of s0
_CONDITIONAL_LEAVES = 16  # leaves along s1 a strip of the conditional starts with (refined
                        # where needed: 64 left the zoo's smooth conditionals at bounds of 1e-12
                        # to 1e-6, far below eps, for a quarter of the transform's pdf calls)
_COARSE_PIECES = 4      # the marginal's refinement's, where they agree with those on the starting
                        # leaves (the conditional's strips refine with their own cuts alone)
_MAX_STEP_CUTS = 8      # cuts at density steps per strip of the conditional
_POLE_GRADING = 2.0 ** -np.arange(1, 25)   # cuts of the first and last strips toward s0 = 0, 1


def _snapped_levels(marginal: AxisCdf, count: int) -> tuple[np.ndarray, np.ndarray]:
    """count + 1 cuts of s0 near the marginal's quantiles j / count, each on an edge of the
    marginal's leaves, the first and last at the support's ends.  (cuts, the tabulated CDF at
    them.)  A cut within 8 % of its pieces' width of a step of the density (adjacent leaves'
    densities differing by more than 1.5x) moves onto the step: otherwise the step would lie
    in the margin that the piece's Gauss-Legendre nodes never reach (the outer 7 %), and the
    sliver of mass beyond it would be missed by the conditional's cubature."""
    edges = np.append(marginal.lo, marginal.hi[-1])
    cdf = np.append(marginal.start, 1.0)
    cdf[-1] = 1.0
    target = np.arange(count + 1) / count
    i = np.clip(np.searchsorted(cdf, target), 1, cdf.size - 1)
    i = np.where(np.abs(cdf[i - 1] - target) <= np.abs(cdf[i] - target), i - 1, i)
    i[0] = np.searchsorted(cdf, 0.0, side="right") - 1                  # the support's start
    i[-1] = min(np.searchsorted(cdf, 1.0 - 1e-12), cdf.size - 1)         # and its end
    i = np.maximum.accumulate(i)
    density = marginal.mass / np.maximum(marginal.hi - marginal.lo, 1e-300)
    with np.errstate(divide="ignore", invalid="ignore"):
        jump = np.abs(np.log(density[1:] / density[:-1]))                 # at edges 1 .. L-1
    jump = np.concatenate([[0.0], np.nan_to_num(jump, nan=0.0, posinf=1e300), [0.0]])
    x = edges[i]
    below, above = 0.08 * np.diff(x, prepend=x[0]), 0.08 * np.diff(x, append=x[-1])
    j = np.arange(1, count)   # the ends stay at the support's ends
    a = np.searchsorted(edges, x[j] - below[j])
    b = np.minimum(np.searchsorted(edges, x[j] + above[j]) + 1, jump.size)
    # the cuts whose window holds a step (one numpy pass; a cut's window is searched alone)
    steps_before = np.concatenate([[0], np.cumsum(jump > math.log(1.5))])
    moved = (b > a) & (steps_before[np.maximum(a, b)] > steps_before[a])
    for jj, aa, bb in zip(j[moved], a[moved], b[moved]):
        i[jj] = aa + int(np.argmax(jump[aa:bb]))
    i = np.maximum.accumulate(i)
    return edges[i], cdf[i]


def _cut_at_steps(edges: np.ndarray, levels: np.ndarray, marginal: AxisCdf,
                  most: int = _MAX_STEP_CUTS) -> np.ndarray:
    """The pieces (S, P, 2) across each strip [edges[g], edges[g + 1]) that the conditional's
    cubature integrates as one box each: cut at the ``levels`` inside the strip, at the edges
    of marginal leaves where the claimed density steps (the ``most`` largest steps per
    strip), and, where the density at s0 = 0 or 1 is more than twice its strip's mean (a pole
    of the domain map where the density is singular), geometrically toward that end, at
    2^-1 .. 2^-24 of the strip's width (``edges`` and ``levels`` sorted and finite, as
    :func:`_snapped_levels` gives them).  Strips with fewer cuts are padded with empty pieces
    at their end.  Halving leaves along s1 never reduces the error of a box that crosses a
    step or holds a singularity in s0: a texel table's columns and the poles of a lat-long map
    had left conditional bounds of 1.5e-3 to 5.9e-3, past what the tests resolve at 1e6
    samples (now 1e-12 to 8e-5)."""
    lo, hi = marginal.lo, marginal.hi
    density = marginal.mass / np.maximum(hi - lo, 1e-300)
    with np.errstate(divide="ignore", invalid="ignore"):
        jump = np.abs(np.log(density[1:] / density[:-1]))          # at the edge hi[i] = lo[i + 1]
    jump = np.nan_to_num(jump, nan=0.0, posinf=1e300)
    # a step: a jump of more than 1e-6 (relative) that is 4x one of its neighbours' (on a
    # smooth density adjacent leaves' jumps are alike; a step inside a leaf jumps at both
    # of its edges, flat beyond)
    side = np.minimum(np.concatenate([[0.0], jump[:-1]]), np.concatenate([jump[1:], [0.0]]))
    step = (jump > 1e-6) & (jump > 4 * side)
    step_at, size = hi[:-1][step], jump[step]
    # each strip's steps and levels, as ranges of those sorted arrays: strictly inside it, and
    # within it ends included
    first, last = np.searchsorted(step_at, edges[:-1], side="right"), np.searchsorted(step_at, edges[1:])
    level_first = np.searchsorted(levels, edges[:-1])
    level_last = np.searchsorted(levels, edges[1:], side="right")

    def mean(a: float, b: float) -> float:
        """The density's mean over the strip [a, b)."""
        return marginal.mass[(lo >= a) & (hi <= b)].sum() / max(b - a, 1e-300)

    cuts = []
    for g in range(edges.size - 1):
        a, b = edges[g], edges[g + 1]
        keep = step_at[first[g]:last[g]]
        if keep.size > most:
            keep = keep[np.argsort(-size[first[g]:last[g]], kind="stable")[:most]]
        mine = levels[level_first[g]:level_last[g]]
        ends = []
        if g == 0 and density[0] > 2 * mean(a, b):              # singular at s0 = 0 (a pole)
            ends.append(a + (b - a) * _POLE_GRADING)
        if g == edges.size - 2 and density[-1] > 2 * mean(a, b):  # or at s0 = 1
            ends.append(b - (b - a) * _POLE_GRADING)
        cuts.append(np.unique(np.concatenate([[a, b], mine, keep, *ends])))
    width = max(c.size for c in cuts) - 1
    pieces = np.empty((len(cuts), width, 2))
    for g, c in enumerate(cuts):
        c = np.concatenate([c, np.full(width + 1 - c.size, c[-1])])
        pieces[g, :, 0], pieces[g, :, 1] = c[:-1], c[1:]
    return pieces


@dataclass(frozen=True)
class Transform:
    """The Rosenblatt transform of parameter points through a claimed density q, tabulated
    once: ``marginal`` (u0) and, on the square, ``conditional`` (u1 given the strip of s0;
    strips of equal claimed mass, their s0 edges ``edges``).  ``error`` bounds |u - exact u|
    for any point (units of probability)."""

    marginal: AxisCdf
    conditional: AxisCdf | None
    edges: np.ndarray
    probability: np.ndarray   # each strip's claimed probability (from the marginal)
    error: float

    @classmethod
    def build(cls, q: Callable[[np.ndarray], np.ndarray], k: int, n: int, floor: float = 0.0,
              breaks: Breaks = None, total: float | None = None) -> Transform:
        """Tabulates q's CDFs for a test of ``n`` points: to eps = 0.02 / sqrt(n) on the
        square, so that the carried error moves sqrt(n W^2) by at most about 0.02, and ten
        times finer on an interval (cheap there), where the equiprobable chi-square's up to
        1024 bins would otherwise feel the error.  On the square the strips'
        edges are the marginal's quantiles g / STRIPS, each strip integrated across as
        SUBSTRIPS pieces of equal claimed mass, cut further at the density's steps and toward
        a singular pole (:func:`_cut_at_steps`), and refined with those cuts alone where the
        substrips add nothing (``coarse``, strip by strip: 37 % fewer pdf calls for the
        Mitsuba catalogue's conditionals, 9.1 -> 3.7 million for a GGX lobe at 45
        degrees); a strip whose integral disagrees with the
        marginal's 1 / STRIPS (mass the cubature missed) adds the disagreement to the bound.
        ``floor``: q's rounding (:func:`harness.samplers.cubature.rounding_floor`).  A strip
        whose cubature has spent an error of 1 / sqrt(n) in all stops refining: carried, an
        error that size moves sqrt(n W^2) by 1, and a strip that has missed by that much is a
        step or singularity across its boxes that halving does not resolve (a rotated
        checkerboard: refining on to the limits took 6x the pdf calls and kept leaves carrying
        8x the error).  The bound carried is that of the leaves kept.  ``breaks``: where q may
        step or kink, per axis; ``total``: q's integral as far as known (the base grid's
        cubature), which sets the marginal's first pass (both as
        :func:`harness.samplers.cdf_tables.tabulate` takes them)."""
        expect = np.array([total]) if total is not None and math.isfinite(total) and total > 0 else None
        eps = 0.02 / math.sqrt(n)
        useless = 1 / math.sqrt(n)
        if k == 1:
            eps /= 10
            marginal = tabulate(q, 1, 0, np.zeros((1, 1, 2)), 1024, eps, floor=floor, useless=useless,
                                 breaks=breaks, expect=expect)
            return cls(marginal, None, np.array([0.0, 1.0]), np.ones(1), marginal.error)
        def across(count: int) -> np.ndarray:
            cuts = np.arange(count + 1) / count
            return np.stack([cuts[:-1], cuts[1:]], axis=1)[None]

        marginal = tabulate(q, 2, 0, across(_MARGINAL_PIECES), 128, eps / 8,
                             max_share=1 / (4 * STRIPS * SUBSTRIPS), floor=floor, useless=useless,
                             coarse=across(_COARSE_PIECES), breaks=breaks, expect=expect)
        levels, cdf = _snapped_levels(marginal, STRIPS * SUBSTRIPS)
        edges = levels[::SUBSTRIPS]
        pieces = _cut_at_steps(edges, levels, marginal)
        probability = np.diff(cdf[::SUBSTRIPS])
        share = marginal.strip_mass[0] * probability
        conditional = tabulate(q, 2, 1, pieces, _CONDITIONAL_LEAVES, eps, floor=floor, useless=useless,
                                breaks=breaks, expect=share, coarse=_cut_at_steps(edges, edges, marginal))
        missed = np.abs(conditional.strip_mass - share) / np.maximum(share, 1e-300)
        error_u1 = conditional.error + float(missed.max())
        conditional = dataclasses.replace(conditional, error=error_u1)
        return cls(marginal, conditional, edges, probability, max(marginal.error, error_u1))

    def __call__(self, s: np.ndarray) -> np.ndarray:
        """u (N, k) of parameter points s (N, k)."""
        return self.apply(s)[0]

    def apply(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u (N, k), the strip of each point (N,); all 0 on an interval).  One pass in the
        core (:func:`reference_estimators.rosenblatt`)."""
        conditional = None if self.conditional is None else self.conditional.table
        return rest.rosenblatt(self.marginal.table, conditional, self.edges, s)

    def statistics(self, s: np.ndarray, bins: int) -> tuple[np.ndarray, ...]:
        """What the tests need of the transform u of parameter points s (N, k), without u
        itself: (the Cramer-von Mises sum's bracket of each column of u (k, 2), the observed counts, the
        claimed probabilities and a bound on those probabilities' error of the cells of equal
        claimed probability (C,): bins of u0 on an interval, strips x bins of u1 on the
        square).  The bound: on an interval a bin's two edges are each off by at most the
        marginal's error e0; on the square strip g's probability p_g is off by at most 2 e0
        (its edges), spread over its bins, and each bin's share of the strip by at most 2 e1
        (the conditional's error), so a cell is off by at most 2 e0 / bins + 2 e1 (p_g + 2 e0),
        whatever p_g claims.  One call to the core
        (:func:`reference_estimators.transform_statistics`)."""
        conditional = None if self.conditional is None else self.conditional.table
        sums, counts = rest.transform_statistics(self.marginal.table, conditional, self.edges, s, bins)
        e0 = self.marginal.error
        if self.conditional is None:
            return sums, counts, np.full(bins, 1.0 / bins), np.full(bins, 2 * e0)
        e1 = self.conditional.error
        strip = np.repeat(self.probability, bins)
        return sums, counts, strip / bins, 2 * e0 / bins + 2 * e1 * (strip + 2 * e0)
