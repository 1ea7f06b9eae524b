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

The CDFs are tabulated once per claimed pdf (:class:`Transform`, sample-independent) from box
integrals of q (:func:`harness.samplers.cubature.grouped_integrals`: each leaf's quarters judged
against the leaf, :func:`harness.samplers.cubature.box_integrals` where they disagree):
piecewise linear through the quarter points of leaves refined until a bound on the
interpolation's error within the quarters, for a density monotone on the leaf
(:func:`_interpolation_bound`), is below ``eps``; the bound
reached, plus the cubature's own error, is :attr:`Transform.error`, a bound on |table - CDF|
in units of the strip's mass, and the tests carry it: a statistic is computed as if every u
were that much off in its favour.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

import reference_estimators as rest

from harness.samplers.cubature import grouped_integrals, halves, split_points, tensor_rule

__all__ = ["AxisCdf", "Transform"]

#: Strips of equal claimed mass along s0 on the square (the conditioning of u1), each
#: integrated across as SUBSTRIPS boxes of equal claimed mass.
STRIPS = 32
SUBSTRIPS = 4
_MARGINAL_PIECES = 32   # boxes across the square for the marginal of s0
_CONDITIONAL_LEAVES = 16  # leaves along s1 a strip of the conditional starts with (refined
                        # where needed: 64 left the zoo's smooth conditionals at bounds of 1e-12
                        # to 1e-6, far below eps, for a quarter of the transform's pdf calls)
_COARSE_PIECES = 4      # its refinement's, where they agree with those on the starting leaves
_MAX_STEP_CUTS = 8      # cuts at density steps per strip of the conditional
_POLE_GRADING = 2.0 ** -np.arange(1, 25)   # cuts of the first and last strips toward s0 = 0, 1
_MAX_DEPTH = 40         # refinement levels along the axis (a level halves a leaf, or grades it: _split)
_GRADED = 2.0           # an end quarter this many times its neighbour's mass: graded cuts (_split)
_GRADING = 2.0 ** -np.arange(4, 0, -1)    # 1/16, 1/8, 1/4, 1/2 of a graded leaf from its end
_MIN_WIDTH = 2.0**-30   # nor below this width: a domain map loses its precision near a pole
_MAX_BOXES = 300_000    # box integrals a tabulation may spend (then it stops with its bound)
_MAX_EVALS = 6_000_000  # pdf evaluations one round of box integrals may spend: a float32 pdf's
                        # rounding noise would otherwise drive every box to the depth limit
_MAX_TABLE_EVALS = 160_000_000  # pdf evaluations a whole tabulation may spend (then it stops
                        # with its bound): a backstop behind the stop at a useless bound
                        # (_tabulate); the most a useful table spent is 96 million (Mitsuba's
                        # Beckmann alpha = 0.01), the zoo's at most 27 million


#: Per parameter axis, the sorted coordinates where a claimed density may step or kink, or
#: None where none are declared (:func:`harness.samplers.cubature.split_points`).
Breaks = tuple[np.ndarray | None, ...] | None


@dataclass(frozen=True)
class AxisCdf:
    """A CDF along one axis of parameter space within each of a set of strips: piecewise
    linear over leaves [lo, hi) sorted by (strip, lo), ``start`` the CDF at lo and ``mass``
    the leaf's share of its strip's mass.  ``error`` bounds |table - CDF| (units of the
    strip's mass) for every strip."""

    strip: np.ndarray   # (L,) int
    lo: np.ndarray      # (L,)
    hi: np.ndarray      # (L,)
    start: np.ndarray   # (L,)
    mass: np.ndarray    # (L,)
    strip_mass: np.ndarray  # (S,) each strip's integral of q
    error: float

    @property
    def table(self) -> tuple[np.ndarray, ...]:
        """(lo, hi, start, mass, offsets), the form the core's lookups take: strip g's leaves
        are offsets[g] .. offsets[g + 1] - 1."""
        offsets = np.searchsorted(self.strip, np.arange(self.strip_mass.size + 1))
        return self.lo, self.hi, self.start, self.mass, offsets

    def __call__(self, strip: np.ndarray, x: np.ndarray) -> np.ndarray:
        """The CDF at coordinates x of points in strips ``strip`` (arrays (N,)), in [0, 1]."""
        return rest.piecewise_linear_lookup(*self.table, strip, x)


class _Counted:
    """q with a count of the points it was evaluated at (``evals``), called as q is: on
    parameter points, or integrating itself over boxes (``rule_integrals``, which the
    cubature uses where q has it: :class:`harness.samplers.domains.ParamDensity`)."""

    def __init__(self, q: Callable[[np.ndarray], np.ndarray]):
        self.q, self.evals = q, 0

    def __call__(self, sp: np.ndarray) -> np.ndarray:
        self.evals += sp.shape[0]
        return self.q(sp)

    def rule_integrals(self, lo: np.ndarray, hi: np.ndarray, nodes: np.ndarray,
                       weights: np.ndarray) -> np.ndarray:
        self.evals += weights.size * lo.shape[0]
        return tensor_rule(self.q, lo, hi, nodes, weights)


def _tabulate(q: Callable[[np.ndarray], np.ndarray], k: int, axis: int, pieces: np.ndarray, leaves: int,
              eps: float, max_share: float = 1.0, floor: float = 0.0, useless: float = math.inf,
              coarse: np.ndarray | None = None, breaks: Breaks = None,
              expect: np.ndarray | None = None) -> AxisCdf:
    """The CDF of q along ``axis`` within each strip: strip g spans all of [0, 1] along
    ``axis`` (cut into ``leaves`` leaves to start) and, on the square, the pieces pieces[g, j]
    = (lo, hi) across it (arrays (S, P, 2); each leaf quarter is integrated as one box per
    piece, so the cubature starts where the mass is).  Leaves are halved (:func:`_split`: graded
    toward an end of the axis that holds their mass) while the bound on the
    interpolation's error within their quarters (:func:`_interpolation_bound`) exceeds eps
    (times the strip's mass) or a quarter holds more than ``max_share`` of it, or until
    _MAX_DEPTH, _MIN_WIDTH or _MAX_BOXES or _MAX_TABLE_EVALS, or until the cubature error
    spent in a strip (summed over every box integrated, refined-away ones included: the
    effort's measure, which refinement only adds to) exceeds ``useless`` (times the strip's
    mass): a strip whose cubature has missed by that much in all is a step or singularity that
    more halving does not resolve.  Once a stopped strip keeps a leaf whose bound exceeds
    ``useless`` (the table's error is then at least that), eps is raised to that bound
    (:func:`_settled_bound`).
    The table's bound counts only the leaves it keeps: their interpolation bound and their
    boxes' cubature error (a refined-away leaf's integral is not in the table, nor its error).
    The cubature stops at q's rounding ``floor`` (relative).  ``breaks``: per axis, where q
    may step or kink (:func:`harness.samplers.cubature.split_points`): a leaf with one inside
    is split there rather than halved, and so are the cubature's boxes.  ``expect``: each
    strip's mass as known beforehand (S,) (the marginal's from the base grid's cubature, a
    strip's of the conditional from the marginal), which sets the first pass's tolerance
    (else a thousandth of the refinement's, relative to the pieces' measure: a pass that drove
    every box of Mitsuba's 256 x 128 envmap to its float32 floor and to the evaluation limit).
    ``coarse``: fewer pieces (S, P', 2) to refine with instead, where on the starting leaves
    they give every quarter's integral within the refinement's tolerance (or q's rounding) of
    ``pieces``' and their cubature error within it too, or, on a leaf where ``pieces``' own
    error misses it, within 1 % of that error (a singular pole or a step along the axis,
    which pieces across do not resolve: the cone's rim, the disk's centre): a density smooth
    across the pieces (an azimuth that does not matter, a lobe at the pole) needs no more, and
    the refinement's pdf calls fall by P / P'; a density with structure across them (a step,
    a texel table) keeps ``pieces``.
    A box whose integral is not finite counts as mass 0 with error 1 (the bound then covers
    the whole strip: its tests lose their power, never their level)."""
    nstrip, npiece = pieces.shape[:2]
    used = np.maximum(np.sum(pieces[:, :, 1] > pieces[:, :, 0], axis=1), 1)   # non-empty pieces
    strip = np.repeat(np.arange(nstrip), leaves)
    a = np.tile(np.arange(leaves) / leaves, nstrip)
    b = np.tile((np.arange(leaves) + 1) / leaves, nstrip)

    counted = _Counted(q)

    def quarters(strip: np.ndarray, a: np.ndarray, b: np.ndarray, strip_tol: np.ndarray):
        """(L, 4) quarter integrals of leaves, their (L,) summed cubature error, and the
        number of (non-empty) boxes integrated."""
        edges = a[:, None] + (b - a)[:, None] * np.arange(5)[None, :] / 4      # (L, 5)
        qa, qb = edges[:, :4].reshape(-1), edges[:, 1:].reshape(-1)           # (4L,)
        g = np.repeat(strip, 4)
        # a box's share of the strip's tolerance by its length along the axis, never below a
        # 1/4096 leaf's: deep leaves at a singularity or step would otherwise drive the cubature
        # to its depth limit for error it cannot reach (what error remains is summed and carried)
        tol = np.repeat(strip_tol[g] * np.maximum(qb - qa, 1 / 4096) / used[g], npiece)
        lo, hi = np.empty((qa.size * npiece, k)), np.empty((qa.size * npiece, k))
        lo[:, axis], hi[:, axis] = np.repeat(qa, npiece), np.repeat(qb, npiece)
        if k == 2:
            lo[:, 1 - axis], hi[:, 1 - axis] = pieces[g, :, 0].reshape(-1), pieces[g, :, 1].reshape(-1)
        budget = min(_MAX_EVALS, max(_MAX_TABLE_EVALS - counted.evals, 0))
        val, err = np.zeros(lo.shape[0]), np.zeros(lo.shape[0])
        full = np.all(hi > lo, axis=1)          # the padding pieces of _cut_at_steps are empty
        # the bare change of a box's last split as its error (extrapolate=False): a singular
        # end's leaves are halved again here, down to _MIN_WIDTH, and the stop at a useless
        # bound sums these errors over every level as the effort's measure; the extrapolated
        # tails (about 6 times the change at a pole) summed so made the pole strips of
        # uniform_theta_sphere and the disk's centre hopeless at the first level, with bounds
        # of 0.02 in place of 2e-5.  The kept leaves' own understatement is at most
        # r / (1 - r) times their boxes' tails (2.4 at x^-1/2), far below the bound there
        # each leaf's piece judged by its rule against those of its four quarters, each halved
        # across (grouped_integrals: the children must cut the parent along every axis, or a
        # density that varies only across would agree unresolved): 9 rules where each
        # quarter's own halves took 20
        nleaf, nfull = a.size, int(full.sum())
        group = np.repeat(np.arange(nleaf), 4 * npiece) * npiece + np.tile(np.arange(npiece), 4 * nleaf)
        group = group[full]
        parents, group = np.unique(group, return_inverse=True)
        plo, phi = np.empty((nleaf * npiece, k)), np.empty((nleaf * npiece, k))
        plo[:, axis], phi[:, axis] = np.repeat(a, npiece), np.repeat(b, npiece)
        if k == 2:
            plo[:, 1 - axis] = pieces[strip, :, 0].reshape(-1)
            phi[:, 1 - axis] = pieces[strip, :, 1].reshape(-1)
        clo, chi, ctol, cgroup = lo[full], hi[full], tol[full], group
        if k == 2:      # rows 2i, 2i + 1: the halves across of box i
            clo, chi = halves(clo, chi, 1 - axis, (clo[:, 1 - axis] + chi[:, 1 - axis]) / 2)
            ctol, cgroup = np.repeat(ctol / 2, 2), np.repeat(cgroup, 2)
        v, e = grouped_integrals(counted, clo, chi, cgroup, plo[parents], phi[parents], ctol,
                                 max_depth=16 if k == 1 else 8, max_evals=budget, floor=floor,
                                 extrapolate=False, breaks=breaks)
        if k == 2:
            v, e = v.reshape(nfull, 2, -1).sum(axis=1), e.reshape(nfull, 2, -1).sum(axis=1)
        bad = ~(np.isfinite(v[:, 0]) & np.isfinite(e[:, 0]))   # a pdf infinite at a node
        val[full] = np.where(bad, 0.0, v[:, 0])
        err[full] = np.where(bad, 1.0, e[:, 0])   # unknown mass: the bound becomes the whole strip
        return (np.maximum(val, 0).reshape(-1, 4, npiece).sum(axis=2),
                err.reshape(-1, 4 * npiece).sum(axis=1), nfull)

    # a first pass finds the strips' masses: at half the refinement's tolerance (below) for
    # the masses expected, where they are known, else at a tolerance relative to the boxes' measure
    if expect is not None:
        first_tol = 0.05 * eps * np.maximum(expect, 1e-300)
    else:
        measure = np.ones(nstrip) if k == 1 else np.sum(pieces[:, :, 1] - pieces[:, :, 0], axis=1)
        first_tol = 1e-3 * eps * measure
    qs, errs, spent = quarters(strip, a, b, first_tol)
    strip_mass = np.bincount(strip, qs.sum(axis=1), minlength=nstrip)
    strip_tol = 0.1 * eps * np.maximum(strip_mass, 1e-300)   # cubature error: a tenth of eps
    spent_err = np.bincount(strip, errs, minlength=nstrip)
    if coarse is not None:
        fine = pieces, used, npiece
        pieces, npiece = coarse, coarse.shape[1]
        used = np.maximum(np.sum(coarse[:, :, 1] > coarse[:, :, 0], axis=1), 1)
        coarse_qs, coarse_errs, boxes = quarters(strip, a, b, strip_tol)
        spent += boxes
        # a quarter's tolerance, as the cubature's: its share of the strip's, or q's rounding
        allowed = np.maximum((strip_tol[strip] * np.maximum((b - a) / 4, 1 / 4096))[:, None], floor * qs)
        # errs: pieces' own cubature error on each leaf (at the first pass's tighter tolerance)
        if not (np.all(np.abs(coarse_qs - qs) <= allowed)
                and np.all(coarse_errs <= allowed.sum(axis=1) + 1.01 * errs)):
            pieces, used, npiece = fine
    done: list[tuple[np.ndarray, ...]] = []
    settled = 0.0   # _settled_bound of the leaves kept so far
    for depth in range(_MAX_DEPTH + 1):
        bound = _interpolation_bound(qs)
        spent_all = (spent > _MAX_BOXES) | (counted.evals > _MAX_TABLE_EVALS)
        hopeless = spent_err[strip] > useless * strip_mass[strip]
        stopped = (depth == _MAX_DEPTH) | (b - a < _MIN_WIDTH) | spent_all | hopeless
        settled = max(settled, _settled_bound(bound[stopped], strip_mass[strip[stopped]]))
        # the table's error is at least `settled`: past `useless`, refining to eps is wasted
        target = eps if settled <= useless else settled
        fine = (bound <= target * strip_mass[strip]) & (qs.max(axis=1) <= max_share * strip_mass[strip])
        ok = fine | stopped
        done.append((strip[ok], a[ok], b[ok], qs[ok], bound[ok], errs[ok]))
        if ok.all():
            break
        strip, a, b = _split(strip[~ok], a[~ok], b[~ok], qs[~ok], None if breaks is None else breaks[axis])
        qs, errs, boxes = quarters(strip, a, b, strip_tol)
        spent_err += np.bincount(strip, errs, minlength=nstrip)
        spent += boxes
    strip, a, b, qs, bound, errs = (np.concatenate(v) for v in zip(*done))
    # quarter sub-leaves, sorted by (strip, lo), cumulated within their strip
    edges = a[:, None] + (b - a)[:, None] * np.arange(5)[None, :] / 4
    sub_strip = np.repeat(strip, 4)
    sub_lo, sub_hi, sub_q = edges[:, :4].reshape(-1), edges[:, 1:].reshape(-1), qs.reshape(-1)
    order = np.lexsort((sub_lo, sub_strip))
    sub_strip, sub_lo, sub_hi, sub_q = sub_strip[order], sub_lo[order], sub_hi[order], sub_q[order]
    total = np.bincount(sub_strip, sub_q, minlength=nstrip)
    norm = np.where(total > 0, total, 1.0)
    cum = np.cumsum(sub_q)
    before = cum - sub_q - np.concatenate([[0.0], np.cumsum(total)[:-1]])[sub_strip]
    worst = np.zeros(nstrip)
    np.maximum.at(worst, strip, bound)
    # and the rounding of the cumulated sums (an ulp of the total per addition)
    error = float(np.max((worst + np.bincount(strip, errs, minlength=nstrip)) / norm)) + sub_q.size * 2.0**-52
    return AxisCdf(sub_strip, sub_lo, sub_hi, before / norm[sub_strip], sub_q / norm[sub_strip], total, error)


def _settled_bound(bound: np.ndarray, strip_mass: np.ndarray) -> float:
    """The largest interpolation bound, in units of its strip's mass, of leaves kept because
    their strip stopped refining (its effort spent, its depth or width limits), not because
    they were fine; 0 for none.  The table's error is at least that, so once it is past
    ``useless`` (:func:`_tabulate`) the other strips refine to it rather than to eps: an area
    light's strip along the light's curved edge stops at the first pass with a bound of 0.1,
    and the other 31 had then spent 34 million pdf calls on bounds of 2e-5 that the table's
    error hid."""
    return float(np.max(bound / np.maximum(strip_mass, 1e-300))) if bound.size else 0.0


def _split(strip: np.ndarray, lo: np.ndarray, hi: np.ndarray, qs: np.ndarray,
           breaks: np.ndarray | None) -> tuple[np.ndarray, ...]:
    """The leaves [lo, hi) of strips ``strip`` (arrays (L,)) split for refinement, their
    quarter masses qs (L, 4): (strip, lo, hi) of the children, each leaf's in order.  A leaf is
    halved, or cut at a break inside (:func:`harness.samplers.cubature.split_points`); one at
    an end of the axis (0 or 1) whose end quarter holds more than _GRADED times its neighbour's
    mass (a pole's singularity, a lobe at the pole) is cut at 1/16, 1/8, 1/4 and 1/2 of its
    width from that end at once (unless that makes a child narrower than _MIN_WIDTH): halving
    it took a level of the refinement per halving (each a pass over the cubature's boxes, the
    singular one refined to the cubature's depth limit again) down to _MIN_WIDTH, about 23
    levels at a lat-long map's poles.  Where halving would have refined down to the graded
    leaves (it always does at a singular end, to _MIN_WIDTH) the leaves kept are halving's (a
    quarter's integral is its own boxes', whatever level made it), unless a strip stops on its
    effort (_MAX_BOXES, a useless bound), which the skipped levels no longer add to; where it
    would have stopped sooner (a lobe at the end holding little of the strip), graded leaves
    are finer than needed: a valid table with a smaller bound, for a few more leaves."""
    mid = split_points(lo, hi, breaks)
    # no break inside, and no child narrower than _MIN_WIDTH
    plain = (mid == (lo + hi) / 2) & (hi - lo >= _MIN_WIDTH / _GRADING[0])
    low = plain & (lo == 0) & (qs[:, 0] > _GRADED * qs[:, 1])
    high = plain & (hi == 1) & ~low & (qs[:, 3] > _GRADED * qs[:, 2])
    graded = low | high
    w = (hi - lo)[:, None]
    cuts = np.full((lo.size, 6), np.nan)
    cuts[:, 0] = lo
    cuts[~graded, 1], cuts[~graded, 2] = mid[~graded], hi[~graded]
    cuts[low, 1:5] = lo[low, None] + w[low] * _GRADING
    cuts[high, 1:5] = hi[high, None] - w[high] * _GRADING[::-1]
    cuts[graded, 5] = hi[graded]
    children = ~np.isnan(cuts[:, 1:])
    return np.repeat(strip, children.sum(axis=1)), cuts[:, :-1][children], cuts[:, 1:][children]


def _interpolation_bound(qs: np.ndarray) -> np.ndarray:
    """A bound on |linear interpolation - CDF| within each leaf's quarters, from the leaves'
    quarter masses qs (L, 4), for a density monotone on the leaf, and always at most the
    largest quarter's mass (a quarter's mass bounds any CDF within it).

    Two bounds, the smaller taken.  The leaf's: twice the CDF's largest deviation from its
    chord over the leaf at the quarter points (the CDF is convex or concave; within a factor 2
    of the largest deviation, and a quarter's own chord is nearer).  The quarters': with the
    density monotone, on quarter i it lies between its neighbours' mean densities d[i - 1] and
    d[i + 1] (the leaf's ends: 0, and no bound above), and a density between L and U with mean
    d on a quarter of width w leaves its CDF at most w (d - L)(U - d) / (U - L) from the
    quarter's chord (the step from L to U that keeps the mean: the extreme case), w (d - L)
    where U is unbounded.  On a smooth density the quarters' bound is a quarter of the leaf's
    (the end quarters' slopes, p' w^2 against 4 p' w^2), so about half the leaves reach a given
    eps.  Quarter densities that are not monotone (a density with an extremum on the leaf) keep
    the leaf's bound."""
    m = qs.sum(axis=1)
    cum = np.cumsum(qs, axis=1)[:, :3]
    gap = np.max(np.abs(cum - m[:, None] * np.array([0.25, 0.5, 0.75])), axis=1)
    leaf = np.minimum(2 * gap, qs.max(axis=1))
    steps = np.diff(qs, axis=1)
    rising, falling = np.all(steps >= 0, axis=1), np.all(steps <= 0, axis=1)
    # in units of a quarter's width w (masses are w d): the rising case, and the falling one
    # as the rising case of the quarters reversed
    d = np.where(falling[:, None], qs[:, ::-1], qs)
    low = np.concatenate([np.zeros((d.shape[0], 1)), d[:, :3]], axis=1)
    high = np.concatenate([d[:, 1:], np.full((d.shape[0], 1), np.inf)], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        inner = (d - low) * (high - d) / (high - low)
    quarters = np.where(np.isinf(high), d - low, np.where(high > low, inner, 0.0))
    return np.where(rising | falling, np.minimum(leaf, quarters.max(axis=1)), leaf)


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
    for j in range(1, count):   # the ends stay at the support's ends
        a, b = np.searchsorted(edges, [x[j] - below[j], x[j] + above[j]])
        b = min(b + 1, jump.size)
        if b > a and jump[a:b].max() > math.log(1.5):
            i[j] = a + int(np.argmax(jump[a:b]))
    i = np.maximum.accumulate(i)
    return edges[i], cdf[i]


def _cut_at_steps(edges: np.ndarray, levels: np.ndarray, marginal: AxisCdf,
                  most: int = _MAX_STEP_CUTS) -> np.ndarray:
    """The pieces (S, P, 2) across each strip [edges[g], edges[g + 1]) that the conditional's
    cubature integrates as one box each: cut at the ``levels`` inside the strip, at the edges
    of marginal leaves where the claimed density steps (the ``most`` largest steps per
    strip), and, where the density at s0 = 0 or 1 is more than twice its strip's mean (a pole
    of the domain map where the density is singular), geometrically toward that end, at
    2^-1 .. 2^-24 of the strip's width.  Strips with fewer cuts are padded with empty pieces
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
    cuts = []
    for g in range(edges.size - 1):
        a, b = edges[g], edges[g + 1]
        inside = (step_at > a) & (step_at < b)
        keep = step_at[inside][np.argsort(-size[inside], kind="stable")[:most]]
        mine = levels[(levels >= a) & (levels <= b)]
        ends = []
        within = (lo >= a) & (hi <= b)
        mean = marginal.mass[within].sum() / max(b - a, 1e-300)
        if g == 0 and density[0] > 2 * mean:              # singular at s0 = 0 (a pole)
            ends.append(a + (b - a) * _POLE_GRADING)
        if g == edges.size - 2 and density[-1] > 2 * mean:  # or at s0 = 1
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
        a singular pole (:func:`_cut_at_steps`); a strip whose integral disagrees with the
        marginal's 1 / STRIPS (mass the cubature missed) adds the disagreement to the bound.
        ``floor``: q's rounding (:func:`harness.samplers.cubature.rounding_floor`).  A strip
        whose cubature has spent an error of 1 / sqrt(n) in all stops refining: carried, an
        error that size moves sqrt(n W^2) by 1, and a strip that has missed by that much is a
        step or singularity across its boxes that halving does not resolve (a rotated
        checkerboard: refining on to the limits took 6x the pdf calls and kept leaves carrying
        8x the error).  The bound carried is that of the leaves kept.  ``breaks``: where q may
        step or kink, per axis (:func:`_tabulate`); ``total``: q's integral as far as known
        (the base grid's cubature), which sets the marginal's first pass (:func:`_tabulate`)."""
        expect = np.array([total]) if total is not None and math.isfinite(total) and total > 0 else None
        eps = 0.02 / math.sqrt(n)
        useless = 1 / math.sqrt(n)
        if k == 1:
            eps /= 10
            marginal = _tabulate(q, 1, 0, np.zeros((1, 1, 2)), 1024, eps, floor=floor, useless=useless,
                                 breaks=breaks, expect=expect)
            return cls(marginal, None, np.array([0.0, 1.0]), np.ones(1), marginal.error)
        def across(count: int) -> np.ndarray:
            cuts = np.arange(count + 1) / count
            return np.stack([cuts[:-1], cuts[1:]], axis=1)[None]

        marginal = _tabulate(q, 2, 0, across(_MARGINAL_PIECES), 128, eps / 8,
                             max_share=1 / (4 * STRIPS * SUBSTRIPS), floor=floor, useless=useless,
                             coarse=across(_COARSE_PIECES), breaks=breaks, expect=expect)
        levels, cdf = _snapped_levels(marginal, STRIPS * SUBSTRIPS)
        pieces = _cut_at_steps(levels[::SUBSTRIPS], levels, marginal)
        probability = np.diff(cdf[::SUBSTRIPS])
        share = marginal.strip_mass[0] * probability
        conditional = _tabulate(q, 2, 1, pieces, _CONDITIONAL_LEAVES, eps, floor=floor, useless=useless,
                                breaks=breaks, expect=share)
        missed = np.abs(conditional.strip_mass - share) / np.maximum(share, 1e-300)
        error_u1 = conditional.error + float(missed.max())
        conditional = dataclasses.replace(conditional, error=error_u1)
        return cls(marginal, conditional, levels[::SUBSTRIPS], probability, max(marginal.error, error_u1))

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
