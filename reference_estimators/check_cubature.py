"""The sampler check's cubature kernels (src/check_cubature.h, src/check_refine.h,
src/check_quarters.h; bound in src/bind_cubature.cpp): the tensor rule's nodes, their points and
float32 directions on a domain, the weighted sums that make the boxes' integrals, and the
bookkeeping of the adaptive refinement and of the CDF tables' leaves
(harness.samplers.cubature, harness.samplers.cdf_tables), each one pass over numpy arrays in
C++.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from . import _core
from .checks import _check_domain

__all__ = [
    "cubature_nodes", "cubature_points", "cubature_float32_directions", "cubature_cap_float32_directions",
    "interleaved_order", "cubature_sums", "cubature_moment_sums", "split_points", "BoxRefinement",
    "uncut_parents", "grouped_agreement", "leaf_quarters", "interpolation_bound",
]


def cubature_nodes(lo: Any, hi: Any, nodes: Any) -> np.ndarray:
    """The nodes (M g^k, k) of the tensor rule with the g points ``nodes`` (in [0, 1]) per axis
    on the boxes [lo, hi] (M, k), k = 1 or 2: box by box, node (i, j) of a box at row i g + j
    (numpy's meshgrid "ij" order), each coordinate lo + (hi - lo) * node.  One pass in C++."""
    a, b = (np.ascontiguousarray(v, dtype=np.float64) for v in (lo, hi))
    return _core.cubature_nodes(a, b, np.ascontiguousarray(nodes, dtype=np.float64).reshape(-1))


def cubature_points(kind: str, lo: Any, hi: Any, nodes: Any,
                    interval: tuple[float, float] = (0.0, 1.0), columns: Any = None) -> np.ndarray:
    """The points on the sampler check's domain ``kind`` of the tensor rule's nodes on the
    parameter boxes [lo, hi] (M, k): domain_points(kind, cubature_nodes(lo, hi, nodes)), the
    same bits, without the parameter array; ``interval`` the interval's ends; ``columns``: a
    permutation of the points' coordinates, the result then that array's [:, columns] (a
    sphere about another pole, :meth:`harness.samplers.domains.Domain.from_pole_frame`)
    without numpy's copy.  One pass in C++ on all threads."""
    a, b = (np.ascontiguousarray(v, dtype=np.float64) for v in (lo, hi))
    order = [] if columns is None else [int(c) for c in columns]
    return _core.cubature_points(_check_domain(kind), float(interval[0]), float(interval[1]), a, b,
                                 np.ascontiguousarray(nodes, dtype=np.float64).reshape(-1), order)


def cubature_float32_directions(kind: str, lo: Any, hi: Any, nodes: Any, columns: Any = None,
                                slack: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """(columns (3, N) float32, ok (N,)): the values of float32_unit_rows(cubature_points(kind,
    lo, hi, nodes, columns=columns), slack), the same bits, on the hemisphere or sphere: the
    directions of the tensor rule's nodes as a float32 renderer's pdf takes them, without an
    (N, 3) array of doubles.  In the interleaved order: the boxes in blocks of 8 (the last may
    be shorter), node k of box b of a block of w boxes at k w + b within the block (one node of
    every box of a block is a vector's lanes), which :func:`cubature_sums` reads with
    ``interleaved=True``.  One pass in C++ on all threads."""
    a, b = (np.ascontiguousarray(v, dtype=np.float64) for v in (lo, hi))
    order = [] if columns is None else [int(c) for c in columns]
    return _core.cubature_float32_directions(_check_domain(kind), a, b,
                                             np.ascontiguousarray(nodes, dtype=np.float64).reshape(-1), order,
                                             float(slack))


def interleaved_order(boxes: int, per: int) -> np.ndarray:
    """(boxes per,) int64: the box-major index (node k of box b at b per + k) of the node at
    each position of :func:`cubature_float32_directions`' interleaved order (blocks of 8
    boxes, the last shorter, node k of box b of a block of w at k w + b), so that
    ``box_major[..., interleaved_order(M, per)]`` is those values in that order."""
    idx = np.arange(boxes * per, dtype=np.int64).reshape(boxes, per)
    full = boxes // 8 * 8
    head = idx[:full].reshape(-1, 8, per).transpose(0, 2, 1).reshape(-1)
    return np.concatenate([head, idx[full:].T.reshape(-1)])


def cubature_cap_float32_directions(lo: Any, hi: Any, nodes: Any, axis: Any, t: Any, b: Any, cos_alpha: float,
                                    scale: float, slack: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """(columns (3, N) float32, ok (N,)): the values of float32_unit_rows(cap_to_world(
    cubature_points("hemisphere", lo, hi, nodes), axis, t, b, cos_alpha, scale), slack), the
    same bits, in :func:`cubature_float32_directions`' interleaved order: the world directions
    an area light's pdf is evaluated at for the tensor rule's nodes on boxes of its cap's map,
    as the float32 renderer takes them, in one pass in C++ on all threads."""
    lo_, hi_ = (np.ascontiguousarray(v, dtype=np.float64) for v in (lo, hi))
    frame = [np.ascontiguousarray(v, dtype=np.float64).reshape(-1) for v in (axis, t, b)]
    g = np.ascontiguousarray(nodes, dtype=np.float64).reshape(-1)
    return _core.cubature_cap_float32_directions(lo_, hi_, g, *frame, float(cos_alpha), float(scale),
                                                 float(slack))


def split_points(lo: Any, hi: Any, breaks: Any) -> np.ndarray:
    """Where each interval [lo, hi) (arrays (B,)) is split: the break of ``breaks`` (sorted
    coordinates) strictly inside it, more than 1e-9 of its width from either end, nearest its
    middle (of the first at or above the middle and the one before it, that one only when
    strictly nearer), else its middle.  One pass in C++
    (harness.samplers.cubature.split_points states why)."""
    a, b = (np.ascontiguousarray(v, dtype=np.float64).reshape(-1) for v in (lo, hi))
    return _core.split_points(a, b, np.ascontiguousarray(breaks, dtype=np.float64).reshape(-1))


#: The bookkeeping of the sampler check's adaptive cubature in C++
#: (harness.samplers.cubature.box_integrals): ``BoxRefinement(lo, hi, whole, tol, floor,
#: extrapolate, breaks)`` over boxes [lo, hi] (N, k), k = 1 or 2, with the rule's integrals
#: ``whole`` (N, m) and tolerances ``tol`` (N,), ``breaks`` a list per axis of sorted split
#: coordinates (empty: none); then per level ``halves()`` -> (clo, chi) every box's halves
#: along each axis (axis-major, (2 k B, k)), ``step(parts, last)`` with their integrals
#: (2 k B, m) -> whether boxes remain, and at the end ``result()`` -> (integrals, errors) (N, m).
BoxRefinement = _core.BoxRefinement


def _indices(x: Any, name: str) -> np.ndarray:
    """x as contiguous int64 (N,); a ValueError naming ``name`` unless its values are integers
    (a float index would be truncated)."""
    a = np.asarray(x)
    if a.size and not np.issubdtype(a.dtype, np.integer):
        raise ValueError(f"'{name}' must hold integer indices, got dtype {a.dtype}")
    return np.ascontiguousarray(a, dtype=np.int64).reshape(-1)


def uncut_parents(hi: Any, group: Any, parent_hi: Any) -> int:
    """How many parent boxes (G, k) are not cut along every axis by their boxes: parent g is
    cut along an axis where a box i with group[i] == g ends below it there (hi[i] <
    parent_hi[g]).  One pass in C++ (harness.samplers.cubature.grouped_integrals)."""
    return int(_core.uncut_parents(np.ascontiguousarray(hi, dtype=np.float64), _indices(group, "group"),
                                   np.ascontiguousarray(parent_hi, dtype=np.float64)))


def grouped_agreement(own: Any, parent: Any, group: Any, tol: Any,
                      floor: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """grouped_integrals' judgement (harness.samplers.cubature): the rule's integrals ``own``
    (B, m) over boxes that tile parents with integrals ``parent`` (G, m), box i in parent
    group[i], tolerances ``tol`` (B,).  A parent agrees where every column of |the sum of its
    boxes' - its own| is finite and column 0 is at most the sum of its boxes' tolerances, or
    ``floor`` times |its own|.  (value (B, m): own; error (B, m): for the boxes of agreeing
    parents the parent's change times the box's share of their tolerance, else 0; rest (R,)
    int64: the other boxes' rows, ascending.)  numpy's order of operations (bincount's sums),
    the same bits, in one pass in C++."""
    return _core.grouped_agreement(np.ascontiguousarray(own, dtype=np.float64),
                                   np.ascontiguousarray(parent, dtype=np.float64),
                                   _indices(group, "group"),
                                   np.ascontiguousarray(tol, dtype=np.float64).reshape(-1), float(floor))


def leaf_quarters(strip: Any, a: Any, b: Any, pieces: Any, used: Any, strip_tol: Any, axis: int,
                  k: int) -> Any:
    """The boxes of the sampler check's CDF tables (harness.samplers.cdf_tables.tabulate), a
    core ``LeafQuarters``: for leaves [a, b) (L,) along ``axis`` of strips ``strip`` (L,)
    (integer indices into ``pieces``), the strips' pieces across (S, P, 2), their non-empty
    counts ``used`` (S,) (integers, at least 1) and tolerances ``strip_tol`` (S,) on the
    k-dimensional parameter space.  Its ``boxes()`` -> (lo, hi, group, parent_lo, parent_hi,
    tol): the boxes to integrate (rows, k) (each leaf's quarters times its non-empty pieces,
    halved across on the square), their parents' indices (rows,) int64, the parents (G, k)
    (each leaf's pieces) and the boxes' tolerances (rows,), as grouped_integrals takes them;
    ``count``: the quarter boxes integrated; ``sums(v, e)`` -> (quarter masses (L, 4), summed
    errors (L,)) from the boxes' integrals and errors (rows, m).  ValueError for indices that
    are not integers or out of range."""
    f64 = [np.ascontiguousarray(v, dtype=np.float64) for v in (a, b, pieces, strip_tol)]
    return _core.LeafQuarters(_indices(strip, "strip"), f64[0].reshape(-1), f64[1].reshape(-1), f64[2],
                              _indices(used, "used"), f64[3].reshape(-1), int(axis), int(k))


def interpolation_bound(qs: Any) -> np.ndarray:
    """(L,) the sampler check's CDF tables' bound on the interpolation's error within each
    leaf's quarters, from its quarter masses qs (L, 4)
    (harness.samplers.cdf_tables._interpolation_bound states it): the numpy code's order of
    operations, the same values (a zero's sign aside), in one pass in C++."""
    q = np.ascontiguousarray(qs, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != 4:
        raise ValueError(f"'qs' must be quarter masses of shape (L, 4), got {q.shape}")
    return _core.interpolation_bound(q)


def cubature_sums(lo: Any, hi: Any, values: Any, weights: Any, scale: float = 1.0,
                  interleaved: bool = False) -> np.ndarray:
    """(M, m) integrals of the tensor rule on the boxes [lo, hi] (M, k): the sum over each
    box's nodes, in order, of ``weights`` (g^k,) times ``values`` (M g^k,) or (M g^k, m) at
    cubature_nodes' nodes, times the box's volume, times ``scale`` (a constant factor of
    the integrand).  float32 values are summed as given (widened as read: the same bits as
    their float64 copy), other values as float64.  ``interleaved``: one column (M g^k,) in
    :func:`cubature_float32_directions`' order, each box's nodes summed in node order as
    box-major ones are (the same bits).  One pass in C++."""
    a, b = (np.ascontiguousarray(v, dtype=np.float64) for v in (lo, hi))
    w = np.ascontiguousarray(weights, dtype=np.float64).reshape(-1)
    return _core.cubature_sums(a, b, _node_values(values), w, float(scale), bool(interleaved))


def _node_values(values: Any) -> np.ndarray:
    """The values at the rule's nodes as the core's sums read them: float32 as given (a float32
    renderer's pdf), anything else as float64; contiguous."""
    v = np.asarray(values)
    return np.ascontiguousarray(v, dtype=np.float32 if v.dtype == np.float32 else np.float64)


def cubature_moment_sums(lo: Any, hi: Any, values: Any, weights: Any, c: float, scale: float = 1.0,
                         interleaved: bool = False) -> np.ndarray:
    """(M, 3) integrals of q, h q and h^2 q, h = q / (q + c) (0 when c <= 0), by the tensor rule
    on the boxes [lo, hi] (M, k), from q = ``values`` * ``scale`` (M g^k,) at cubature_nodes'
    nodes: cubature_sums of those columns made in numpy (values * scale, h * q, h * h * q), the
    same bits, without their arrays.  float32 values are read as given (widened), others as
    float64; ``interleaved``: in :func:`cubature_float32_directions`' order.  One pass in C++."""
    a, b = (np.ascontiguousarray(v, dtype=np.float64) for v in (lo, hi))
    w = np.ascontiguousarray(weights, dtype=np.float64).reshape(-1)
    return _core.cubature_moment_sums(a, b, _node_values(values).reshape(-1), w, float(c), float(scale),
                                      bool(interleaved))
