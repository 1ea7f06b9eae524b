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

from harness.samplers.domains import Domain
from harness.usercode import UserCodeError, array_result, call, callable_name

__all__ = ["checked_pdf", "drawn_points"]


def drawn_points(sample: Callable[[np.ndarray], Any], u: np.ndarray,
                 dom: Domain) -> tuple[np.ndarray, np.ndarray | None]:
    """The points ``sample`` draws from uniforms u, as float64 of shape (N,) on an interval
    or (N, point_dim), and the pdf values it reported with them: a (points, pdf) tuple gives
    both, a bare array None.  Errors name the sampler."""
    name = callable_name(sample)
    n = u.shape[0]
    want = (n,) if dom.point_dim == 1 else (n, dom.point_dim)
    out = call(sample, name, u, what=f"points of shape {want} on the {dom.kind}")
    x = array_result(out[0] if isinstance(out, tuple) else out, None, name, f"uniforms of shape {u.shape}")
    if x.size != n * dom.point_dim:
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
    """pdf, returning float64 of shape (N,) for N points; errors name it and the input."""
    if getattr(pdf, "_checked", False):
        return pdf
    name = callable_name(pdf)

    def checked(x: np.ndarray) -> np.ndarray:
        n = x.shape[0]
        p = call(pdf, name, x, what=f"densities of shape ({n},)")
        a = array_result(p, None, name, f"points of shape {x.shape}")
        if a.size != n:
            raise UserCodeError(f"{name} returned shape {a.shape} for points of shape {x.shape}, {x.dtype}; "
                                f"expected shape ({n},), one density per point")
        return a.reshape(n)

    checked._checked = True
    return checked
