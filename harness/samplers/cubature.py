"""Adaptive cubature over many boxes of [0, 1]^k at once (the cells of a grid, or any boxes).

The expected cell counts of a sampler check come from tensor Gauss-Legendre cubature of the
claimed density q over each cell, refined where two rules disagree, until the error is far
below the cell's Poisson noise; what error remains is returned beside each integral, so the
check can add it to the chi-square's variance: a sharp lobe, a step inside a cell or an
integrable singularity costs power, not level, except for a step that no rule judging its box
sees (:func:`box_integrals`; declare it as a break).  Written here because
scipy's cubature integrates one region at a time, where a check needs thousands of cells at
once, vectorised.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

import reference_estimators as rest

__all__ = ["box_integrals", "cell_integrals", "grouped_integrals", "rounding_floor",
           "split_points", "tensor_rule"]

#: The relative change of a box's integral that a float32 density's own rounding can cause:
#: Mitsuba's float32 pdfs move a box's rule by up to ~1e-6 of its value where they are
#: steep (measured on the Mitsuba catalogue: roughconductor at alpha 0.01, envmaps), so a
#: split is only worth making when it changes the integral by more than 32 float32 ulps.
FLOAT32_FLOOR = 32 * 2.0**-24


def rounding_floor(values: np.ndarray) -> float:
    """The relative floor below which a change of a box integral of a density with these
    values is its own rounding: FLOAT32_FLOOR when the values are float32
    (:func:`reference_estimators.all_float32`),
    else 0.  Without it the cubature would chase float32 rounding noise to its depth and
    evaluation limits (78 million pdf calls for a Mitsuba BSDF at 1e6 samples, against 8
    million with it)."""
    v = np.asarray(values)
    return FLOAT32_FLOOR if v.dtype == np.float32 or rest.all_float32(v) else 0.0


_GL_X, _GL_W = np.polynomial.legendre.leggauss(4)
_GL_X, _GL_W = (_GL_X + 1) / 2, _GL_W / 2  # on [0, 1]


#: Nodes per call of q by default: a block's arrays (parameters 1 MiB, points 1.5 MiB, values,
#: a numpy pdf's temporaries) stay in the caches and in memory malloc reuses.  Blocks of 2^19
#: nodes (8 and 12 MiB) had the kernel zeroing fresh pages for a fifth of a tabulation's time
#: and the block's passes missing the caches: a setup took 1.5-1.9x as long (the zoo's
#: samplers, Mitsuba's BSDFs and envmaps, alternated in one session; 2^15 and 2^17 came close
#: to 2^16; in 2026-12-05's rerun the zoo's 16 x 32 envmap took 0.77 s at 2^16 and 1.09 s at
#: 2^18).  A q may ask for its own (``pdf_batch``: a renderer's, whose calls each cost a
#: kernel launch, and whose float32 columns reuse the core's memory, wants 2^19).  The
#: integrals do not depend on the block size: every box's nodes lie in one block.
_BLOCK_NODES = 2**16


def tensor_rule(q: Callable[[np.ndarray], np.ndarray], lo: np.ndarray, hi: np.ndarray, nodes: np.ndarray,
                weights: np.ndarray) -> np.ndarray:
    """(M, m) integrals of q over boxes [lo, hi] (M, k) by the tensor rule with points
    ``nodes`` per axis and ``weights`` (g^k,).  A q with ``rule_integrals(lo, hi, nodes,
    weights)`` (:class:`harness.samplers.domains.ParamDensity`) integrates itself, else q is
    called on the rule's nodes (:func:`reference_estimators.cubature_nodes`) and its values
    summed (:func:`reference_estimators.cubature_sums`)."""
    integrals = getattr(q, "rule_integrals", None)
    if integrals is not None:
        return integrals(lo, hi, nodes, weights)
    values = np.asarray(q(rest.cubature_nodes(lo, hi, nodes)), dtype=float)
    return rest.cubature_sums(lo, hi, values, weights)


def _rule(q: Callable[[np.ndarray], np.ndarray], lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Tensor 4-point Gauss-Legendre integrals of q over boxes [lo, hi] (M, k): (M, m), in
    blocks of q's ``pdf_batch`` nodes where it has one
    (:class:`~harness.samplers.domains.ParamDensity`), else _BLOCK_NODES."""
    m, k = lo.shape
    w = _GL_W if k == 1 else np.outer(_GL_W, _GL_W).reshape(-1)
    step = max((getattr(q, "pdf_batch", None) or _BLOCK_NODES) // w.size, 1)
    return np.concatenate([tensor_rule(q, lo[b:b + step], hi[b:b + step], _GL_X, w)
                           for b in range(0, m, step)])


def split_points(lo: np.ndarray, hi: np.ndarray, breaks: np.ndarray | None) -> np.ndarray:
    """Where each interval [lo, hi) (arrays (B,)) is split: the break of ``breaks`` (sorted,
    or None) inside it nearest its middle, else its middle.  A step or kink on a break is then
    cut out of the box by one split, where halving reaches it only to the depth limit (30 to
    40 halvings for each texel edge of an environment map that is not dyadic).  "Inside":
    more than 1e-9 of the box's width from either end, so that a box whose end was meant to
    lie on a break and lies a rounding away is not split into a sliver.  In the core
    (:func:`reference_estimators.split_points`)."""
    return rest.split_points(lo, hi, np.empty(0) if breaks is None else breaks)


def cell_integrals(q: Callable[[np.ndarray], np.ndarray], shape: tuple[int, ...], tol: np.ndarray | float,
                   max_depth: int = 24, max_evals: int = 40_000_000, floor: float = 0.0,
                   breaks: Sequence[np.ndarray | None] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Integrals of q (scalar or vector valued, (M,) or (M, m)) over the cells of a regular
    grid on [0, 1]^k, and their error bounds: arrays (cells, m), cells in C order.  Where every
    side of the grid is even the cells are judged in blocks of 2 per axis
    (:func:`grouped_integrals`: a smooth density's 128 x 256 grid costs 0.7 million pdf calls
    in place of 2.6), else one by one (:func:`box_integrals`)."""
    idx, lo, hi = _grid(shape)
    if any(n % 2 for n in shape):
        return box_integrals(q, lo, hi, tol, max_depth=max_depth, max_evals=max_evals, floor=floor,
                             breaks=breaks)
    # the cells judged by blocks of 2 per axis (grouped_integrals)
    blocks = tuple(n // 2 for n in shape)
    group = np.ravel_multi_index(tuple((idx // 2).T), blocks)
    _, block_lo, block_hi = _grid(blocks)
    return grouped_integrals(q, lo, hi, group, block_lo, block_hi, tol, max_depth=max_depth,
                             max_evals=max_evals, floor=floor, breaks=breaks)


def _grid(shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cells of a regular grid on [0, 1]^k in C order: (their integer indices (C, k), lo,
    hi)."""
    k = len(shape)
    idx = np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), axis=-1).reshape(-1, k)
    size = np.array(shape, dtype=float)
    return idx, idx / size, (idx + 1) / size


def grouped_integrals(q: Callable[[np.ndarray], np.ndarray], lo: np.ndarray, hi: np.ndarray,
                      group: np.ndarray, parent_lo: np.ndarray, parent_hi: np.ndarray,
                      tol: np.ndarray | float, *, max_evals: int = 40_000_000, floor: float = 0.0,
                      **kw) -> tuple[np.ndarray, np.ndarray]:
    """:func:`box_integrals` of boxes [lo, hi] (B, k) that tile parents [parent_lo, parent_hi]
    (G, k), box i inside parent ``group[i]`` (the 2 x 2 blocks of a grid's cells, a leaf's
    four quarters): each box and each parent is integrated by the rule once, and where a
    parent's rule agrees with the sum of its boxes' to their summed tolerance (or to q's
    rounding ``floor``), the boxes' rules are taken, their error the parent's change shared by
    tolerance; the boxes of other parents go through :func:`box_integrals` (``kw`` passed on).
    A box taken so costs the rule once plus its share of the parent's (20 evaluations a 2-D
    cell of a 2 x 2 block, where :func:`box_integrals` spends 80 to judge a box that has
    converged: its halves along each axis), and its error is the coarser rule's, the parent's.
    The windows no rule sees (:func:`box_integrals`) move with the nodes: a step within 7 % of
    a box's width from an edge it shares with a box of its parent, or from its parent's
    outer edges, agrees in both."""
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    parent_lo, parent_hi = np.asarray(parent_lo, dtype=float), np.asarray(parent_hi, dtype=float)
    nbox, k = lo.shape
    tol = np.broadcast_to(np.asarray(tol, dtype=float), (nbox,))
    # every parent cut along every axis: children that cut it along one only agree with it on a
    # density they resolve no better across (a lobe narrow across: 1.6e-3 off, bound 1e-19)
    uncut = rest.uncut_parents(hi, group, parent_hi)
    if uncut:
        raise ValueError("grouped_integrals: every parent must be cut along every axis by its boxes; "
                         f"{uncut} of {parent_lo.shape[0]} are not")
    own = _rule(q, lo, hi)
    parent = _rule(q, parent_lo, parent_hi)
    # the agreement, each box's value and error, in the core (numpy's passes had cost a tilted
    # lobe's tabulation a tenth of its time)
    value, error, rest_ = rest.grouped_agreement(own, parent, group, tol, floor)
    if rest_.size:
        spent = (nbox + parent.shape[0]) * 4**k
        v, e = box_integrals(q, lo[rest_], hi[rest_], tol[rest_], max_evals=max(max_evals - spent, 0),
                             floor=floor, whole=own[rest_], **kw)
        value[rest_], error[rest_] = v, e
    return value, error


def box_integrals(q: Callable[[np.ndarray], np.ndarray], lo: np.ndarray, hi: np.ndarray,
                  tol: np.ndarray | float, *, max_depth: int = 24,
                  max_evals: int = 40_000_000, floor: float = 0.0, extrapolate: bool = True,
                  breaks: Sequence[np.ndarray | None] | None = None,
                  whole: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Integrals of q (scalar or vector valued, (M,) or (M, m)) over the boxes [lo, hi]
    (arrays (B, k) inside [0, 1]^k), and their error bounds: arrays (B, m).

    Each box is integrated by the 4-point tensor rule on itself and on its two halves along
    every axis; where the best split still changes the integral (component 0) by more than
    the box's share of its tolerance ``tol`` (absolute, per box or one for all), the box is
    halved along the axis that changed most, and so on (up to ``max_depth`` splits or
    ``max_evals`` evaluations), unless the change is within ``floor`` (relative) of the
    box's integral: the density's own rounding (:func:`rounding_floor`), which no split
    can reduce.  Splitting along one axis at a time follows a lobe that is
    thin in one direction only.  The error of a box that converged is the change of its last
    split: honest for smooth parts (the rule's error shrinks some 2^8 times a halving there).
    A box that stopped at ``max_depth`` or ``max_evals`` without converging holds a
    singularity or a step, where the change of the last split understates what remains: at
    x^-a the changes shrink by r = 2^(a-1) a halving, and the error left after the last is
    r / (1 - r) times its change (2.4 times at a = 1/2, 14 times at a = 0.9: a correct
    sampler of x^-0.9 failed its normalisation test on every seed with the bare change).  So
    its error is extrapolated from the changes of its last three splits, as a geometric tail
    (``extrapolate=False``: the bare change, for a caller that refines such boxes further
    itself and measures its effort by those changes).  The bookkeeping of each level runs in
    the core (:class:`reference_estimators.BoxRefinement`, which states the extrapolation);
    q is called here, once a level on every box's halves along every axis.

    ``breaks``: per axis, the sorted coordinates where q may step or kink (an environment
    map's texel edges; None: none declared); a box with one inside is split there rather than
    halved (:func:`split_points`), its tolerance shared by width.  Breaks only move splits:
    the integrals and bounds stay the cubature's own, whether or not q steps there.

    What no rule sees: a step between a box's end and its nearest node in either half (3.5 %
    of its width), or between the two halves' nodes about its middle (46.5-53.5 %), lies
    between every node of the box's rule and of its halves' rules, and they agree on the
    wrong value: a 1:9 step at 0.49 or 0.02 of [0, 1] is integrated 1.6 % and 1.8 % off with
    a bound of 0 (measured; a 5-point rule closes the middle window but not the ends, at 1.5
    times the evaluations).  A break declared at the step removes it.

    ``whole``: the rule's integrals over the boxes themselves (B, m), where the caller has them
    (:func:`grouped_integrals`), so they are not computed again; ``max_evals`` counts them all
    the same (the budget means what it did).
    """
    if max_depth < 0:
        raise ValueError(f"'max_depth' must be at least 0, got {max_depth}")
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    ncell, k = lo.shape
    tol = np.ascontiguousarray(np.broadcast_to(np.asarray(tol, dtype=float), (ncell,)))
    whole = _rule(q, lo, hi) if whole is None else np.asarray(whole, dtype=float)
    whole = whole.reshape(ncell, -1)       # a scalar q's (M,) as one column
    # the decisions (split where, converged, the next level's boxes, the unconverged boxes'
    # extrapolated errors) in the core, level by level, q integrated over the halves between
    axes = [np.empty(0) if breaks is None or breaks[axis] is None else np.asarray(breaks[axis], dtype=float)
            for axis in range(k)]
    state = rest.BoxRefinement(lo, hi, whole, tol, floor, extrapolate, axes)
    evals = ncell * 4**k
    for depth in range(max_depth + 1):
        clo, chi = state.halves()
        evals += clo.shape[0] * 4**k
        parts = _rule(q, clo, chi)
        if not state.step(parts.reshape(parts.shape[0], -1), depth == max_depth or evals > max_evals):
            break
    return state.result()
