"""The user's sample and pdf called as the sampler checks call them: results as float64
arrays of the shape expected, and any error (an exception, a wrong shape) a
:class:`~harness.usercode.UserCodeError` naming the callable, its input's shape and dtype, and
the shape expected back.  Shared by the chi-square check (:mod:`harness.samplers.check`) and
the MCMC cross-check (:mod:`harness.samplers.mcmc`).
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

import reference_estimators as rest

from harness.samplers.domains import Domain, Float32DirectionPdf
from harness.stats.validate import count, integer_in
from harness.usercode import UserCodeError, array_result, call, callable_name

__all__ = ["MAX_SAMPLES", "MAX_UDIM", "MAX_UNIFORMS", "checked_pdf", "checked_sample_count", "drawn_points",
           "uniforms"]

#: The most samples a check takes: it holds them in memory (0.9 GB for a plain sampler's 1e7)
MAX_SAMPLES = 100_000_000
#: The most canonical uniforms a sample may take (a rejection sampler takes several tries)
MAX_UDIM = 1024
#: The most uniforms a check holds, sample count times udim (3.2 GB)
MAX_UNIFORMS = 4 * MAX_SAMPLES


def checked_sample_count(sample_count: Any) -> int:
    """A check's sample count: a whole number from 1000 to :data:`MAX_SAMPLES`."""
    n = count(sample_count, "sample_count")
    if not 1000 <= n <= MAX_SAMPLES:
        raise ValueError(f"'sample_count' must be from 1000 to {MAX_SAMPLES:,} (a check holds its samples in "
                         f"memory), got {sample_count!r}")
    return n


def uniforms(n: int, udim: Any, dom: Domain, seed: int, case_id: int) -> np.ndarray:
    """The check's n canonical uniforms (stream ``seed``, ``case_id``), (n, udim): ``udim``
    None takes the domain's default, else an integer from 1 to :data:`MAX_UDIM` (0 had been
    taken for the default)."""
    d = dom.udim if udim is None else integer_in(udim, "udim", 1, MAX_UDIM)
    if n * d > MAX_UNIFORMS:
        raise ValueError(f"{n:,} samples of {d} uniforms each: a check holds at most {MAX_UNIFORMS:,} "
                         "uniforms in memory; take fewer samples")
    return rest.points(n, d, seed=seed, case_id=case_id)


def drawn_points(sample: Callable[[np.ndarray], Any], u: np.ndarray,
                 dom: Domain) -> tuple[np.ndarray, np.ndarray | None]:
    """The points ``sample`` draws from uniforms u, as float64 of shape (N,) on an interval
    or (N, point_dim), and the pdf values it reported with them: a (points, pdf) tuple gives
    both, a bare array None.  Errors name the sampler."""
    name = callable_name(sample)
    n = u.shape[0]
    want = (n,) if dom.point_dim == 1 else (n, dom.point_dim)
    out = call(sample, name, u, what=f"points of shape {want} on the {dom.kind}")
    if isinstance(out, tuple) and not out:
        raise UserCodeError(f"{name} returned an empty tuple for uniforms of shape {u.shape}; expected "
                            f"points of shape {want} on the {dom.kind}, or (points, pdf)")
    x = array_result(out[0] if isinstance(out, tuple) else out, None, name, f"uniforms of shape {u.shape}")
    # the shape as it is (an interval's (N, 1) aside): a (point_dim, N) array reshaped had
    # scrambled the coordinates of a correct sampler into a failing one
    if x.shape != want and not (dom.point_dim == 1 and x.shape == (n, 1)):
        raise UserCodeError(f"{name} returned points of shape {x.shape} for uniforms of shape {u.shape}; "
                            f"expected shape {want} on the {dom.kind}")
    reported = None
    if isinstance(out, tuple) and len(out) >= 2 and out[1] is not None:
        reported = array_result(out[1], None, name, f"uniforms of shape {u.shape}")
        if reported.size != n:
            raise UserCodeError(f"{name} returned {reported.size} pdf values with {n} points for uniforms of "
                                f"shape {u.shape}; expected one pdf value per point")
        reported = reported.reshape(n)
    return x.reshape(want), reported


def checked_pdf(pdf: Callable[[np.ndarray], Any]) -> Callable[[np.ndarray], np.ndarray]:
    """pdf, returning float64 of shape (N,) for N points; errors name it and the input.  A
    :class:`Float32DirectionPdf` stays one, its float32 entry checked too (its float32
    densities kept as float32), and its ``directions`` (None, or float32 columns (3, N) and ok
    (N,) for the N nodes asked)."""
    if getattr(pdf, "_checked", False):
        return pdf
    name = callable_name(pdf.pdf if isinstance(pdf, Float32DirectionPdf) else pdf)

    def checked(x: np.ndarray) -> np.ndarray:
        return _densities(pdf, name, x, x.shape[0], f"points of shape {x.shape}, {x.dtype}", float)

    checked._checked = True
    if not isinstance(pdf, Float32DirectionPdf):
        return checked

    def checked_columns(columns: np.ndarray) -> np.ndarray:
        return _densities(pdf.float32_columns, name, columns, columns.shape[1],
                          f"float32 direction columns of shape {columns.shape}", None)

    out = Float32DirectionPdf(checked, checked_columns,
                              None if pdf.directions is None else _checked_directions(pdf.directions))
    object.__setattr__(out, "_checked", True)
    return out


def _checked_directions(directions: Callable[..., Any]
                        ) -> Callable[..., tuple[np.ndarray, np.ndarray] | None]:
    """A Float32DirectionPdf's ``directions``: None, or (float32 columns (3, N) with C-contiguous
    rows, ok (N,) bool) for the N = boxes x nodes^2 nodes of the boxes [lo, hi] (M, 2); any
    other result, or an exception, a UserCodeError naming it."""
    name = callable_name(directions)

    def checked(lo: np.ndarray, hi: np.ndarray, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        n = lo.shape[0] * np.size(nodes) ** lo.shape[1]
        want = f"None or (float32 columns of shape (3, {n}), bool ok of shape ({n},))"
        got = call(directions, name, lo, hi, nodes, what=want)
        if got is None:
            return None
        boxes = f"{lo.shape[0]} boxes; expected {want}"
        if not (isinstance(got, tuple) and len(got) == 2):
            raise UserCodeError(f"{name} returned {type(got).__name__} for {boxes}")
        try:
            columns, ok = (np.asarray(v) for v in got)
        except Exception as e:   # a ragged list, an object whose __array__ raises
            raise UserCodeError(f"{name} returned a pair that is not two arrays ({type(e).__name__}: {e}) "
                                f"for {boxes}") from None
        if columns.dtype != np.float32 or columns.shape != (3, n) or ok.dtype != np.bool_ or ok.shape != (n,):
            raise UserCodeError(f"{name} returned columns {columns.shape} {columns.dtype}, "
                                f"ok {ok.shape} {ok.dtype} for {boxes}")
        return np.ascontiguousarray(columns), ok
    return checked


def _densities(fn: Callable[[np.ndarray], Any], name: str, points: np.ndarray, n: int, given: str,
               dtype: type | None) -> np.ndarray:
    """fn(points) as n densities (n,): float64, or (dtype None) float32 where fn returned
    float32; a UserCodeError naming ``name`` for an exception or another count."""
    p = call(fn, name, points, what=f"densities of shape ({n},)")
    a = np.asarray(p) if dtype is None and isinstance(p, np.ndarray) and p.dtype == np.float32 else None
    if a is None:
        a = array_result(p, None, name, given)
    if a.size != n:
        raise UserCodeError(f"{name} returned shape {a.shape} for {given}; expected shape ({n},), "
                            "one density per point")
    return a.reshape(n)
