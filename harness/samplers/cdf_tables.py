"""CDFs of a claimed density along one axis of parameter space, within strips, tabulated by
adaptive cubature for the sampler check's Rosenblatt transform (:mod:`harness.samplers.transform`).

Each CDF is piecewise linear through the quarter points of leaves, from box integrals of q
(:func:`harness.samplers.cubature.grouped_integrals`: each leaf's quarters judged against the
leaf, :func:`harness.samplers.cubature.box_integrals` where they disagree), the leaves refined
until a bound on the interpolation's error within the quarters, for a density monotone on the
leaf (:func:`_interpolation_bound`), is below ``eps``; the bound reached, plus the cubature's
own error, is :attr:`AxisCdf.error`, a bound on |table - CDF| in units of the strip's mass,
which the transform's tests carry.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

import reference_estimators as rest

from harness.samplers.cubature import grouped_integrals, split_points, tensor_rule

__all__ = ["AxisCdf", "Breaks", "tabulate"]

_MAX_DEPTH = 40         # refinement levels along the axis (a level halves a leaf, or grades it: _split)
_GRADED = 2.0           # an end quarter this many times its neighbour's mass: graded cuts (_split)
_GRADING = 2.0 ** -np.arange(4, 0, -1)    # 1/16, 1/8, 1/4, 1/2 of a graded leaf from its end
_MIN_WIDTH = 2.0**-30   # nor below this width: a domain map loses its precision near a pole
_MAX_BOXES = 300_000    # box integrals a tabulation may spend (then it stops with its bound)
_MAX_EVALS = 6_000_000  # pdf evaluations one round of box integrals may spend: a float32 pdf's
                        # rounding noise would otherwise drive every box to the depth limit
_MAX_TABLE_EVALS = 160_000_000  # pdf evaluations a whole tabulation may spend (then it stops
                        # with its bound): a backstop behind the stop at a useless bound
                        # (tabulate); the most a useful table spent is 96 million (Mitsuba's
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
        self.pdf_batch = getattr(q, "pdf_batch", None)   # q's points a call, as the cubature asks q

    def __call__(self, sp: np.ndarray) -> np.ndarray:
        self.evals += sp.shape[0]
        return self.q(sp)

    def rule_integrals(self, lo: np.ndarray, hi: np.ndarray, nodes: np.ndarray,
                       weights: np.ndarray) -> np.ndarray:
        self.evals += weights.size * lo.shape[0]
        return tensor_rule(self.q, lo, hi, nodes, weights)


def tabulate(q: Callable[[np.ndarray], np.ndarray], k: int, axis: int, pieces: np.ndarray, leaves: int,
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
    ``coarse``: fewer pieces (S, P', 2) to refine with instead, strip by strip: in a strip
    that refines past its starting leaves, where on those leaves they give every quarter's
    integral within the refinement's tolerance (or q's rounding) of ``pieces``' and their
    cubature error within it too, or, on a leaf where ``pieces``' own error misses it, within
    1 % of that error (a singular pole or a step along the axis, which pieces across do not
    resolve: the cone's rim, the disk's centre): a density smooth across the pieces (an
    azimuth that does not matter, a lobe at the pole, a strip of the conditional narrow
    across) needs no more, and the strip's pdf calls fall by up to P / P'; a density with
    structure across them (a step, a texel table) keeps ``pieces``.  A strip that does not
    refine (fine on every starting leaf, or stopped: an area light's marginal along the
    light's curved edge) is not tried: its coarse pass would be wasted.  The pieces are only
    how the cubature starts: the table's bound is its own either way.
    A box whose integral is not finite counts as mass 0 with error 1 (the bound then covers
    the whole strip: its tests lose their power, never their level)."""
    if coarse is not None and k != 2:
        # pieces are across the square's other axis: on an interval there is none to cut
        raise ValueError("tabulate: 'coarse' pieces are for the square (k = 2)")
    nstrip = pieces.shape[0]
    used = _used(pieces)
    strip = np.repeat(np.arange(nstrip), leaves)
    a = np.tile(np.arange(leaves) / leaves, nstrip)
    b = np.tile((np.arange(leaves) + 1) / leaves, nstrip)

    counted = _Counted(q)

    def quarters(strip: np.ndarray, a: np.ndarray, b: np.ndarray, strip_tol: np.ndarray):
        """(L, 4) quarter integrals of leaves, their (L,) summed cubature error, and the
        number of (non-empty) boxes integrated."""
        # each leaf's piece judged by its rule against those of its four quarters, each halved
        # across (grouped_integrals: the children must cut the parent along every axis, or a
        # density that varies only across would agree unresolved): 9 rules where each
        # quarter's own halves took 20.  A box's share of the strip's tolerance goes by its
        # length along the axis, never below a 1/4096 leaf's: deep leaves at a singularity or
        # step would otherwise drive the cubature to its depth limit for error it cannot reach
        # (what error remains is summed and carried).  The padding pieces of _cut_at_steps are
        # empty, and not integrated.  The boxes, and their integrals summed back into quarters,
        # in the core (numpy's passes had cost a tilted lobe's tabulation a tenth of its time)
        boxes = rest.leaf_quarters(strip, a, b, pieces, used, strip_tol, axis, k)
        budget = min(_MAX_EVALS, max(_MAX_TABLE_EVALS - counted.evals, 0))
        # the bare change of a box's last split as its error (extrapolate=False): a singular
        # end's leaves are halved again here, down to _MIN_WIDTH, and the stop at a useless
        # bound sums these errors over every level as the effort's measure; the extrapolated
        # tails (about 6 times the change at a pole) summed so made the pole strips of
        # uniform_theta_sphere and the disk's centre hopeless at the first level, with bounds
        # of 0.02 in place of 2e-5.  The kept leaves' own understatement is at most
        # r / (1 - r) times their boxes' tails (2.4 at x^-1/2), far below the bound there.
        # A box whose integral is not finite (a pdf infinite at a node) counts as mass 0 with
        # error 1: unknown mass, the bound becomes the whole strip
        v, e = grouped_integrals(counted, *boxes.boxes(), max_depth=16 if k == 1 else 8, max_evals=budget,
                                 floor=floor, extrapolate=False, breaks=breaks)
        qs, errs = boxes.sums(v, e)
        return qs, errs, boxes.count

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

    def judged(depth: int, settled: float) -> tuple[np.ndarray, np.ndarray, float]:
        """Which leaves stay as they are at this depth (fine, or their strip stopped), their
        interpolation bounds, and the settled bound (_settled_bound) so far."""
        bound = _interpolation_bound(qs)
        spent_all = (spent > _MAX_BOXES) | (counted.evals > _MAX_TABLE_EVALS)
        hopeless = spent_err[strip] > useless * strip_mass[strip]
        stopped = (depth == _MAX_DEPTH) | (b - a < _MIN_WIDTH) | spent_all | hopeless
        settled = max(settled, _settled_bound(bound[stopped], strip_mass[strip[stopped]]))
        # the table's error is at least `settled`: past `useless`, refining to eps is wasted
        target = eps if settled <= useless else settled
        fine = (bound <= target * strip_mass[strip]) & (qs.max(axis=1) <= max_share * strip_mass[strip])
        return fine | stopped, bound, settled

    # only strips that refine further are tried with the coarse pieces
    tried = (np.zeros(nstrip, dtype=bool) if coarse is None
             else np.bincount(strip, ~judged(0, 0.0)[0], minlength=nstrip) > 0)
    if tried.any():
        on = tried[strip]
        fine_pieces = pieces, used
        pieces, used = coarse, _used(coarse)
        coarse_qs, coarse_errs, boxes = quarters(strip[on], a[on], b[on], strip_tol)
        spent += boxes
        # a quarter's tolerance, as the cubature's: its share of the strip's, or q's rounding
        allowed = np.maximum((strip_tol[strip[on]] * np.maximum((b[on] - a[on]) / 4, 1 / 4096))[:, None],
                             floor * qs[on])
        # errs: pieces' own cubature error on each leaf (at the first pass's tighter tolerance)
        agrees = (np.all(np.abs(coarse_qs - qs[on]) <= allowed, axis=1)
                  & (coarse_errs <= allowed.sum(axis=1) + 1.01 * errs[on]))
        take = tried & (np.bincount(strip[on], ~agrees, minlength=nstrip) == 0)   # strip by strip
        pieces, used = _mixed(take, coarse, *fine_pieces)
    done: list[tuple[np.ndarray, ...]] = []
    settled = 0.0   # _settled_bound of the leaves kept so far
    for depth in range(_MAX_DEPTH + 1):
        ok, bound, settled = judged(depth, settled)
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


def _used(pieces: np.ndarray) -> np.ndarray:
    """Each strip's non-empty pieces of ``pieces`` (S, P, 2): at least 1 (S,)."""
    return np.maximum(np.sum(pieces[:, :, 1] > pieces[:, :, 0], axis=1), 1)


def _mixed(take: np.ndarray, coarse: np.ndarray, fine: np.ndarray, fine_used: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray]:
    """The pieces (S, P, 2) and their used counts (S,) of ``coarse`` for the strips ``take``
    (S,) bool, of ``fine`` for the others, the narrower padded with empty pieces at the end
    where they mix (empty pieces add zeros to a leaf's sum, which can move its last bit)."""
    if take.all():
        return coarse, _used(coarse)
    if not take.any():
        return fine, fine_used
    width = max(coarse.shape[1], fine.shape[1])
    def padded(p: np.ndarray) -> np.ndarray:
        end = np.broadcast_to(p[:, -1:, 1:], (p.shape[0], width - p.shape[1], 1))
        return np.concatenate([p, np.concatenate([end, end], axis=2)], axis=1)
    mixed = np.where(take[:, None, None], padded(coarse), padded(fine))
    return mixed, np.where(take, _used(coarse), fine_used)


def _settled_bound(bound: np.ndarray, strip_mass: np.ndarray) -> float:
    """The largest interpolation bound, in units of its strip's mass, of leaves kept because
    their strip stopped refining (its effort spent, its depth or width limits), not because
    they were fine; 0 for none.  The table's error is at least that, so once it is past
    ``useless`` (:func:`tabulate`) the other strips refine to it rather than to eps: an area
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
    the leaf's bound.  In the core (:func:`reference_estimators.interpolation_bound`: its
    thirty numpy passes a refinement level had cost a lobe's tabulation a twelfth of its time)."""
    return rest.interpolation_bound(qs)
