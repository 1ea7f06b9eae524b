"""The sampler check's batch kernels (src/checks.h and the src/check_*.h it includes): the
work of harness.samplers.check that is not the user's sample and pdf calls (domain maps,
histograms, the Rosenblatt transform, Cramer-von Mises sums, the pdf's screening, a float32
renderer's rows and columns), and the Mitsuba adapter's weight check, each one pass over numpy
arrays in C++.  The cubature's kernels
are :mod:`reference_estimators.check_cubature`'s.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from . import _core
from .arguments import stream_arg

__all__ = [
    "CHECK_DOMAINS", "domain_params", "dithered_domain_params", "domain_points", "grid_histogram",
    "rosenblatt", "piecewise_linear_lookup", "transform_statistics", "cramer_von_mises_sum", "pdf_summary",
    "all_float32", "dither_float32", "float32_nudged", "finite_rows", "pdf_mismatches", "float64_rows",
    "float32_columns", "take_rows", "nan_rows", "produced_rows", "float32_unit_rows", "cap_to_world",
    "cap_to_hemisphere", "cap_density",
    "rect_to_square", "rect_to_world", "rect_density", "RowLookup", "weight_agreement",
]

#: The sampling domains of the sampler check, in the order the core numbers them.
CHECK_DOMAINS = ("interval", "half_line", "square", "disk", "hemisphere", "sphere")


def _check_domain(kind: str) -> int:
    if kind not in CHECK_DOMAINS:
        raise ValueError(f"'kind' must be one of {CHECK_DOMAINS}, got {kind!r}")
    return CHECK_DOMAINS.index(kind)


def _domain_points_arg(kind: str, x: Any) -> tuple[int, np.ndarray]:
    """(the domain's code, x as float64 in C order): (N, 1) points on the interval and half
    line as (N,); another shape goes on as it is, for the core to refuse by name."""
    code = _check_domain(kind)
    a = np.ascontiguousarray(x, dtype=np.float64)
    if CHECK_DOMAINS[code] in ("interval", "half_line") and a.ndim == 2 and a.shape[1] == 1:
        a = a.reshape(-1)
    return code, a


def domain_params(kind: str, x: Any, lo: float = 0.0, hi: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(s, inside): the equal-measure parameters s (N, k) in [0, 1]^k of points x on the sampler
    check's domain ``kind`` (harness.samplers.domains states the maps; [lo, hi] the interval's
    ends) and whether each point lies inside it (finite; unit vectors within 1e-5 of unit
    squared norm, z >= -1e-12 on the hemisphere; r^2 <= 1 + 1e-12 on the disk).  x: (N,) or
    (N, 1) on the interval and half line, (N, 2) on the square and disk, (N, 3) unit vectors
    on the hemisphere and sphere.  One pass in C++ with the GIL released."""
    code, a = _domain_points_arg(kind, x)
    return _core.domain_params(code, float(lo), float(hi), a)


def dithered_domain_params(kind: str, x: Any, u: Any = None, lo: float = 0.0, hi: float = 1.0, *,
                           stream: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(s, inside): :func:`domain_params`' s of the points x dithered within their float32
    rounding (:func:`dither_float32` with uniforms ``u`` of x's shape) and its ``inside`` of x
    as given: the same bits as those two calls, in one pass in C++ whose dithered points go to
    reused scratch rows, never to an array (the sampler check's float32 points need both, and
    nothing else of either).  ``stream`` = (seed, case_id) in place of ``u``: the uniforms
    ``points(N, coordinates, seed=seed, case_id=case_id)`` gives, drawn chunk by chunk inside
    the pass, so that no array of them is written out either."""
    if (u is None) == (stream is None):
        raise ValueError("give the uniforms 'u' or a 'stream' (seed, case_id), one of them")
    code, a = _domain_points_arg(kind, x)
    if stream is not None:
        return _core.streamed_dithered_domain_params(code, float(lo), float(hi), a, *stream_arg(stream))
    w = np.ascontiguousarray(u, dtype=np.float64)
    w = w.reshape(a.shape) if w.size == a.size else w     # else the core says what is wrong
    return _core.dithered_domain_params(code, float(lo), float(hi), a, w)


def domain_points(kind: str, s: Any, lo: float = 0.0, hi: float = 1.0) -> np.ndarray:
    """Points x(s) of parameters s (N, k) on the sampler check's domain ``kind``, the inverse
    of :func:`domain_params`: (N,) on the interval ([lo, hi]) and half line, (N, 2) on the
    square and disk, unit vectors (N, 3) on the hemisphere and sphere.  The azimuth's cosine
    and sine are those of 2 pi s1 with an exact argument reduction (numpy's cos(2 pi s1) first
    rounds 2 pi s1): the same points to rounding.  In C++ with the GIL released."""
    a = np.ascontiguousarray(s, dtype=np.float64)
    return _core.domain_points(_check_domain(kind), float(lo), float(hi), a)


def cap_to_world(h: Any, axis: Any, t: Any, b: Any, cos_alpha: float, scale: float) -> np.ndarray:
    """World directions (N, 3) of points h (N, 3) of the hemisphere (normalised first) through
    the equal-area map of the cap {d : <d, axis> >= cos_alpha} onto it, frame (t, b, axis)
    orthonormal, scale = 1 - cos_alpha: c = clip(cos_alpha + z scale, -1, 1) along the axis,
    the azimuth kept (its cosine and sine as x / r and y / r, r = sqrt(x^2 + y^2); the pole
    at azimuth 0).  A point below the horizon maps outside the cap, a NaN row to NaN.  In C++
    on all threads, vectorised, each value numpy's expression in its order of operations
    (harness.adapters.mitsuba.cap.Cap.to_world)."""
    a = np.ascontiguousarray(h, dtype=np.float64).reshape(-1, 3)
    frame = [np.ascontiguousarray(v, dtype=np.float64).reshape(-1) for v in (axis, t, b)]
    return _core.cap_to_world(a, *frame, float(cos_alpha), float(scale))


def cap_to_hemisphere(d: Any, axis: Any, t: Any, b: Any, cos_alpha: float, scale: float,
                      rim_slack: float) -> np.ndarray:
    """Points (N, 3) of the hemisphere of world directions d (N, 3) through the equal-area map
    of the cap {d : <d, axis> >= cos_alpha} (frame t, b, axis orthonormal, scale = 1 -
    cos_alpha), the inverse of :func:`cap_to_world`: d normalised, c = <d, axis> (moved onto
    cos_alpha where it is below it by at most ``rim_slack``: float32 rounding of the rim),
    z = (c - cos_alpha) / scale and the azimuth about the axis kept (its cosine and sine as
    <d, t> / rho and <d, b> / rho, rho their norm; the axis at azimuth 0), radius sqrt(max(0,
    1 - z^2)).  NaN and zero rows give NaN rows.  In C++ on all threads, vectorised
    (harness.adapters.mitsuba.cap.Cap.to_hemisphere)."""
    a = np.ascontiguousarray(d, dtype=np.float64).reshape(-1, 3)
    frame = [np.ascontiguousarray(v, dtype=np.float64).reshape(-1) for v in (axis, t, b)]
    return _core.cap_to_hemisphere(a, *frame, float(cos_alpha), float(scale), float(rim_slack))


def cap_density(h: Any, p: Any, scale: float) -> np.ndarray:
    """(N,): the world pdf values p (N,) rounded to float32 times ``scale`` in float32,
    widened (numpy's float32 product), at the hemisphere points h (N, 3) that are finite with
    z >= 0, else 0: the density of the Mitsuba adapter's cap map
    (harness.adapters.mitsuba.cap.CapView.pdf) in one pass in C++."""
    a = np.ascontiguousarray(h, dtype=np.float64).reshape(-1, 3)
    return _core.cap_density(a, np.ascontiguousarray(p, dtype=np.float64).reshape(-1), float(scale))


def _rectangle_frame(frame: tuple) -> list:
    """A rectangle light's frame (to_corner, e0, e1, normal, dual, height, area) as the core
    takes it: four 3-vectors, the dual basis (2, 3) and two numbers, contiguous float64."""
    *vectors, height, area = frame
    if len(vectors) != 5:
        raise ValueError("'frame' must be (to_corner, e0, e1, normal, dual, height, area)")
    if np.shape(vectors[4]) != (2, 3):
        raise ValueError(f"'dual' must be the dual basis (f0, f1), shape (2, 3), got {np.shape(vectors[4])}")
    arrays = [np.ascontiguousarray(v, dtype=np.float64).reshape(-1) for v in vectors]
    return [*arrays, float(height), float(area)]


def rect_to_square(d: Any, frame: tuple, slack: float) -> np.ndarray:
    """Points s (N, 2) of a rectangle light's square where the rays from its reference point
    along the world directions d (N, 3) hit its plane (``frame``: to_corner = corner - ref,
    e0, e1, the unit normal n, the dual basis (f0, f1) of (e0, e1), height = <n, corner -
    ref>, area = |e0 x e1|): t = height / <d, n>, o = (ref - corner) + t d, s_i = <o, f_i>,
    each within ``slack`` of [0, 1] clamped onto it; (-1, -1) where 0 < t < inf fails (the ray
    misses the plane in front of ref, or runs along it); NaN rows stay NaN.  In C++ on all
    threads, each value its numpy definition's
    (tests/core/test_check_kernels_area_light_maps.py) left to right
    (harness.adapters.mitsuba.rectangle.Rectangle.to_domain)."""
    a = np.ascontiguousarray(d, dtype=np.float64)
    return _core.rect_to_square(a, *_rectangle_frame(frame), float(slack))


def rect_to_world(s: Any, frame: tuple) -> np.ndarray:
    """Unit world directions (N, 3) from a rectangle light's reference point towards the
    points P(s) = corner + s0 e0 + s1 e1 of s (N, 2) (``frame`` as :func:`rect_to_square`):
    w / sqrt(w0^2 + w1^2 + w2^2), w = (corner - ref) + s0 e0 + s1 e1.  In C++ on all
    threads (Rectangle.to_world)."""
    a = np.ascontiguousarray(s, dtype=np.float64)
    return _core.rect_to_world(a, *_rectangle_frame(frame))


def rect_density(s: Any, p: Any, frame: tuple) -> np.ndarray:
    """(N,): the world pdf values p (N,) rounded to float32 times the map's Jacobian J(s) =
    area |<w, n>| / (dist2 sqrt(dist2)) (w = P(s) - ref, dist2 = <w, w>: steradians per unit
    area of the square) rounded to float32, multiplied in float32 and widened, at the points
    s (N, 2) inside [0, 1]^2, else 0: the density of the Mitsuba adapter's rectangle map
    (harness.adapters.mitsuba.rectangle.Rectangle.density) in one pass in C++."""
    a = np.ascontiguousarray(s, dtype=np.float64)
    return _core.rect_density(a, np.ascontiguousarray(p, dtype=np.float64).reshape(-1),
                              *_rectangle_frame(frame))


#: ``RowLookup(x)`` over rows x (N, k), k = 1 to 3 (read in place, kept alive by the lookup):
#: ``find(q)`` -> (M,) int64, for each row of q (M, k) the first row of x equal to it value for
#: value (numpy's ==: 0.0 equals -0.0, NaN equals nothing), or -1.  A hash table built in one
#: pass in C++ (the Mitsuba adapter's CapView looks a few points up among a million drawn).
RowLookup = _core.RowLookup


def float32_unit_rows(x: Any, slack: float) -> tuple[np.ndarray, np.ndarray]:
    """(columns, ok): the rows of x (N, 3) as float32 unit vectors, columns (3, N) float32 (row
    j of it C-contiguous): a row whose length is within ``slack`` of 1 rounded as given,
    another finite non-zero one normalised in float64 first; ``ok`` (N,) False for a row that
    is not a finite non-zero vector (its column entries are then +z).  What a float32
    renderer's pdf is called with, in one pass in C++ (numpy took 34 ns a row)."""
    a = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3)
    return _core.float32_unit_rows(a, float(slack))


def float32_columns(rows: Any, cap: float) -> np.ndarray:
    """(c, N) float32: the rows (N, c) (float64) as columns, each value rounded to float32 and
    then capped at ``cap`` (a float32; NaN kept): numpy's minimum(rows[:, j], cap,
    dtype=float32) for every column j, in one pass in C++ into memory the core reuses (see
    :func:`float64_rows`).  What a float32 renderer's sample call is given from the uniforms."""
    a = np.ascontiguousarray(rows, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] == 0:
        raise ValueError(f"'rows' must have shape (N, c), c >= 1, got {a.shape}")
    if not (abs(cap) <= float(np.finfo(np.float32).max) and float(np.float32(cap)) == cap):
        raise ValueError(f"'cap' must be a float32 value, got {cap!r}")
    return _core.float32_columns(a, float(cap))


def float64_rows(columns: Any) -> np.ndarray:
    """(N, c) float64 in C order: float32 columns as rows, cast and transposed in one pass in
    C++, into memory the core reuses from call to call (a fresh numpy array of a million
    directions cost 5-10 ms of page faults on a loaded machine, more than the copy).
    ``columns``: a float32 array (c, N) (a float32 renderer's vectors, as drjit gives them), or
    a list or tuple of c float32 arrays (N,) (a drjit vector's components, each read in place:
    drjit's (3, N) copy of a million directions cost 1.7 ms, more than this pass)."""
    if isinstance(columns, (list, tuple)):
        cols = [np.asarray(c) for c in columns]
        if (not cols or any(c.dtype != np.float32 or c.ndim != 1 for c in cols)
                or len({c.shape for c in cols}) != 1):
            got = [(c.dtype, c.shape) for c in cols]
            raise ValueError("'columns' must be float32 of shape (c, N), c >= 1, or c >= 1 float32 "
                             f"columns of one shape (N,); got {got}")
        return _core.float64_rows_of([np.ascontiguousarray(c) for c in cols])
    a = np.asarray(columns)
    if a.dtype != np.float32 or a.ndim != 2 or a.shape[0] == 0:
        raise ValueError(f"'columns' must be float32 of shape (c, N), c >= 1, got {a.dtype} {a.shape}")
    return _core.float64_rows(np.ascontiguousarray(a))


def take_rows(x: Any, keep: Any) -> np.ndarray:
    """x[keep] for x (N,) or (N, k) float64 and ``keep`` (N,) bool: the rows kept, in order,
    in one pass in C++ into memory the core reuses (see :func:`float64_rows`)."""
    a = np.ascontiguousarray(x, dtype=np.float64)
    m = np.ascontiguousarray(keep, dtype=bool).reshape(-1)
    return _core.take_rows(a, m)


def nan_rows(x: Any, keep: Any) -> np.ndarray:
    """x (N,) or (N, k) float64 with the rows not kept NaN (numpy's where(keep[:, None], x,
    nan)), in one pass in C++ into memory the core reuses (see :func:`float64_rows`)."""
    a = np.ascontiguousarray(x, dtype=np.float64)
    m = np.ascontiguousarray(keep, dtype=bool).reshape(-1)
    return _core.nan_rows(a, m)


def grid_histogram(s: Any, inside: Any, shape: tuple[int, ...]) -> np.ndarray:
    """Counts (float64, of ``shape``) of the parameter points s (N, k) marked ``inside`` (N,)
    on the regular grid ``shape`` (k = 1 or 2 cell counts) over [0, 1]^k, C order: each
    coordinate clamped to [0, 1 - 2^-53], then cell min(floor(s m), m - 1).  Points with a
    NaN coordinate count nowhere.  One pass in C++."""
    a = np.ascontiguousarray(s, dtype=np.float64)
    m = np.ascontiguousarray(inside, dtype=bool).reshape(-1)
    return _core.grid_histogram(a, m, [int(v) for v in shape])


def _table(t: tuple) -> tuple:
    lo, hi, start, mass, offsets = t
    return (*(np.ascontiguousarray(a, dtype=np.float64).reshape(-1) for a in (lo, hi, start, mass)),
            np.ascontiguousarray(offsets, dtype=np.int64).reshape(-1))


def rosenblatt(marginal: tuple, conditional: tuple | None, edges: Any,
               s: Any) -> tuple[np.ndarray, np.ndarray]:
    """(u (N, k), strip (N,) int64): the Rosenblatt transform of parameter points s (N, k)
    through piecewise-linear tables, each (lo, hi, start, mass, offsets) as
    :func:`piecewise_linear_lookup` takes them: u0 = marginal(strip 0, s0); with a
    ``conditional`` (the square, k = 2) also the strip g of s0 (the last of ``edges`` at or
    below s0, clamped to 0 .. len(edges) - 2, as numpy's searchsorted(side="right") - 1
    clipped) and u1 = conditional(g, s1); without one, strip 0.  One pass in C++."""
    a = np.ascontiguousarray(s, dtype=np.float64)
    cond = None if conditional is None else _table(conditional)
    e = np.ascontiguousarray(edges, dtype=np.float64).reshape(-1)
    return _core.rosenblatt(_table(marginal), cond, e, a)


def _strided(a: Any) -> np.ndarray:
    """a as float64, strided views kept (the core reads them in place) unless a stride is
    negative (the core's strides are unsigned) or not a whole number of values (a field of a
    packed structured array: the core's strides count values)."""
    v = np.asarray(a, dtype=np.float64)
    return np.ascontiguousarray(v) if any(s < 0 or s % v.itemsize for s in v.strides) else v


def transform_statistics(marginal: tuple, conditional: tuple | None, edges: Any, s: Any,
                         bins: int) -> tuple[np.ndarray, np.ndarray]:
    """(sums (k, 2), counts (strips * bins,) float64) of the Rosenblatt transform u of parameter
    points s (N, k) (as :func:`rosenblatt`), without returning u: the
    :func:`cramer_von_mises_sum` of each column of u, and the counts of the cells of equal
    claimed probability, strip g and bin min(floor(v bins), bins - 1) of v = u1 on the square
    (strips: len(edges) - 1), of v = u0 on an interval (one strip); a NaN v counts nowhere.
    In C++ on all hardware threads (fixed chunks: the same for any thread count), u kept in
    buffers that are reused from call to call."""
    a = np.ascontiguousarray(s, dtype=np.float64)
    cond = None if conditional is None else _table(conditional)
    e = np.ascontiguousarray(edges, dtype=np.float64).reshape(-1)
    return _core.transform_statistics(_table(marginal), cond, e, a, int(bins))


def cramer_von_mises_sum(u: Any) -> np.ndarray:
    """For each column of u (N, k) (or the one of u (N,)), its values clamped to [0, 1] (the
    uniform law's CDF there, as in scipy's cramervonmises): (upper, slack), bracketing S =
    sum_i ((2 i - 1) / (2 N) - u_(i))^2 over the sorted values u_(1) <= ... <= u_(N) as
    upper >= S >= upper - slack; S + 1 / (12 N) is the column's Cramer-von Mises statistic
    N W^2.  Without a sort: from the values' counts in K cells of width about 1 / (64 sqrt(N)),
    the order within a cell bounded (slack about N / (2 K^2), 1.2e-4 for uniform values at any
    N; see checks.h).  NaN for a column holding a NaN.  Array (k, 2).  In C++, the columns on
    the hardware threads, each summed in a fixed order (the same on any thread count); strided
    columns are read in place."""
    v = _strided(u)
    if v.ndim not in (1, 2):
        raise ValueError(f"'u' must have shape (N,) or (N, k), got {v.shape}")
    return _core.cramer_von_mises_sum(v.reshape(v.shape[0], -1))


def finite_rows(x: Any) -> np.ndarray:
    """(N,) bool: whether each row of x ((N, ...), or each value of x (N,)) is finite in every
    value (numpy's all(isfinite(x), axis=1), which takes 15 ns a 3-vector).  One pass in C++
    on all threads; float64 (N,) and (N, k) views are read in place, whatever their strides
    (a transposed (3, N) array as well)."""
    a = _strided(x)
    return _core.finite_rows(a.reshape(a.shape[0], math.prod(a.shape[1:])) if a.ndim > 2 else a)


def produced_rows(x: Any, pdf: Any, weight: Any = None, delta: Any = None) -> np.ndarray:
    """(N,) bool: which samples a renderer's sample call produced: the direction (row of x
    (N, 3)) finite, the pdf it reported (N,) above 0, some channel of its ``weight`` (N, c) not
    0 (a NaN is not 0, as numpy's !=; a view whose rows all are one row, as a constant weight
    comes back, is read as that row), and ``delta`` (N,) 0 (it did not sample a Dirac lobe);
    ``weight`` and ``delta`` None where the sampler has none.  numpy's comparisons, the same
    flags, in one pass in C++ on all threads."""
    a = np.ascontiguousarray(_real(x, "x"), dtype=np.float64)
    p = np.ascontiguousarray(_real(pdf, "pdf"), dtype=np.float64).reshape(-1)
    empty = np.empty(0)
    w, constant = _one_row_if_constant(empty if weight is None else _real(weight, "weight"), len(a))
    d = empty if delta is None else np.ascontiguousarray(_real(delta, "delta"), dtype=np.float64)
    return _core.produced_rows(a, p, weight is not None, w, constant, delta is not None, d)


def _one_row_if_constant(w: np.ndarray, n: int) -> tuple[np.ndarray, bool]:
    """(w as float64 in C order, whether it is one constant row): a view (n, c) whose rows are
    all its first (row stride 0: a constant weight as the Mitsuba adapter returns it) becomes
    that row alone, (1, c), so that the core reads one row, not n copies of it."""
    constant = w.ndim == 2 and len(w) == n > 0 and w.strides[0] == 0
    return np.ascontiguousarray(w[:1] if constant else w, dtype=np.float64), constant


def _real(v: Any, name: str) -> np.ndarray:
    """v as a numpy array of real numbers (views kept); ValueError naming ``name`` for complex
    ones, whose imaginary parts a float64 copy would drop."""
    a = np.asarray(v)
    if np.iscomplexobj(a):
        raise ValueError(f"'{name}' must hold real numbers, got {a.dtype}")
    return a


def all_float32(v: Any) -> bool:
    """Whether every finite non-zero value of v (any shape) is a float32 (rounds to itself
    through float32), and there is one: a float32 renderer's numbers, whether returned as
    float32 or float64.  One vectorised pass in C++, stopping after the block of 1024 values
    that holds the first value that is not."""
    return bool(_core.all_float32(np.ascontiguousarray(v, dtype=np.float64).reshape(-1)))


def dither_float32(v: Any, u: Any) -> np.ndarray:
    """v (any shape) with each value moved to below + (above - below) u, below and above half
    way to its float32 neighbours (the value rounded to float32 first), u uniforms of v's
    size; a value whose result is not finite (NaN, infinite, beyond float32's range or at its
    end) is kept.  The same bits as numpy's (x + nextafter(x32, -inf)) / 2 etc.; one pass in
    C++ on all threads.  Array of v's shape."""
    a = np.ascontiguousarray(v, dtype=np.float64)
    w = np.ascontiguousarray(u, dtype=np.float64)
    return _core.dither_float32(a.reshape(-1), w.reshape(-1)).reshape(a.shape)


def float32_nudged(x: Any, column: int, steps: int) -> np.ndarray:
    """(N, d) float64: the points x (N, d) rounded to float32, with column ``column`` moved by
    |steps| float32 ulps, up for steps > 0 and down for steps < 0.  The bits of numpy's
    x.astype(float32) with |steps| np.nextafter calls in float32 on the column, towards +-inf,
    cast back to float64 (NaN stays NaN; a step toward an infinity stops there, one away from it
    leaves it for float32's largest value); one pass in C++ on all threads."""
    a = np.ascontiguousarray(x, dtype=np.float64)
    if a.ndim != 2 or not 0 <= column < a.shape[1]:
        raise ValueError(f"'x' must have shape (N, d) and 'column' be one of its d columns, "
                         f"got {a.shape}, {column}")
    if not -2**31 <= int(steps) < 2**31:   # the core's int32 (float32 has 2^32 values in all)
        raise ValueError(f"'steps' must be in [-2^31, 2^31), got {steps}")
    return _core.float32_nudged(a, int(column), int(steps))


def pdf_summary(kind: str, measure: float, s: Any, inside: Any, p: Any,
                c: float, total: float = 1.0) -> tuple[int, int, int, float]:
    """(bad, zero, used, h_sum) over pdf values p / ``total`` (p (N,); numpy's division, without
    its array) at points with parameters s (N, k) and ``inside`` flags: ``bad`` counts them
    NaN, infinite or negative (every point), ``zero`` 0 at inside points; over the ``used``
    inside points with a good value above 0 (a point of pdf 0 has probability 0 under the
    density, and is counted in ``zero``), h_sum is the sum of h = q / (q + c) with q = p J / total
    the density in parameter space (J = ``measure``, the domain's measure per unit of s, or
    1 / (1 - s)^2 on the half line, the only domain that reads s); 0 unless c > 0.  One pass
    in C++ with a compensated sum."""
    code = _check_domain(kind)
    a = np.ascontiguousarray(s, dtype=np.float64)
    m = np.ascontiguousarray(inside, dtype=bool).reshape(-1)
    v = np.ascontiguousarray(p, dtype=np.float64).reshape(-1)
    bad, zero, used, h_sum = _core.pdf_summary(code, float(measure), a, m, v, float(c), float(total))
    return int(bad), int(zero), int(used), float(h_sum)


def pdf_mismatches(reported: Any, p: Any, rtol: float) -> np.ndarray:
    """(M,) int64, ascending: the rows where the pdf a sampler reported with its sample,
    ``reported`` (N,), differs from the claimed pdf at the sample, ``p`` (N,), by more than
    ``rtol`` relative (|reported - p| > rtol |p|, or NaN either side), or is infinite or
    negative: numpy's ~(abs(reported - p) <= rtol * abs(p)) | ~isfinite(reported) |
    (reported < 0), the same operations, in one pass in C++ without its temporaries."""
    r = np.ascontiguousarray(reported, dtype=np.float64).reshape(-1)
    v = np.ascontiguousarray(p, dtype=np.float64).reshape(-1)
    return _core.pdf_mismatches(r, v, float(rtol))


def weight_agreement(w: Any, e: Any, p: Any, atol: float,
                     rtol: float) -> tuple[np.ndarray, np.ndarray, float]:
    """The weight check of a renderer's samples
    (harness.adapters.mitsuba.checks.weight_consistency) for N samples of c channels: the
    weights w (N, c) a sample call returned (a view whose rows are one constant weight, row
    stride 0, is read as that one row), the values e (N, c) re-evaluated at their directions
    and the pdf p (N,) there.  Per channel ratio = e / p and diff = |w - ratio|.  (mismatch
    (N,) bool: not bad, and a channel with diff not within atol + rtol |ratio|; bad (N,) bool:
    a channel of w not finite, or negative; max_rel: the largest relative difference, diff /
    |ratio| where |ratio| > atol, else diff, over the rows not bad, NaN as +inf and +inf as
    the largest double, 0 for none.)  numpy's expressions, the same values, in one pass in
    C++ on all threads."""
    wa, ea = np.asarray(w, dtype=np.float64), np.ascontiguousarray(e, dtype=np.float64)
    if wa.shape != ea.shape:
        raise ValueError(f"'w' must have the shape of 'e', {ea.shape}; got {wa.shape}")
    wa, constant = _one_row_if_constant(wa, ea.shape[0])
    pa = np.ascontiguousarray(p, dtype=np.float64).reshape(-1)
    mismatch, bad, most = _core.weight_agreement(wa, constant, ea, pa, float(atol), float(rtol))
    return mismatch, bad, float(most)


def piecewise_linear_lookup(lo: Any, hi: Any, start: Any, mass: Any, offsets: Any, strip: Any,
                            x: Any) -> np.ndarray:
    """A piecewise-linear table looked up at points x (N,) of strips ``strip`` (N,): for the leaf
    i of the point's strip (leaves offsets[g] .. offsets[g + 1] - 1, sorted by ``lo``) with the
    largest lo[i] <= x (the strip's first leaf if none), start[i] + mass[i] * t with t the
    point's place in [lo[i], hi[i]] clamped to [0, 1]; the result clamped to [0, 1], NaN for a
    strip outside the table.  One pass in C++ with the GIL released."""
    as64 = [np.ascontiguousarray(a, dtype=np.float64).reshape(-1) for a in (lo, hi, start, mass, x)]
    off = np.ascontiguousarray(offsets, dtype=np.int64).reshape(-1)
    g = np.ascontiguousarray(strip, dtype=np.int64).reshape(-1)
    return _core.piecewise_linear_lookup(*as64[:4], off, g, as64[4])
