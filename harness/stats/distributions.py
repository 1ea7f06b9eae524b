"""The distribution functions the harness's verdicts and intervals need, from scipy.special.

Why not scipy.stats: importing it costs about 0.8 s (it pulls in scipy.sparse, .spatial and
.optimize), more than a resumed suite's whole command is allowed (issue 19: at most 1 s),
while scipy.special, which scipy.stats calls for these very functions, costs about 0.2 s.
Each function equals its scipy.stats counterpart bit for bit on the arguments the harness
passes (tests/stats/test_distributions.py compares them over grids including 0, 1, +-inf,
NaN and df = inf), and broadcasts like it.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from scipy import special

__all__ = ["t_ppf", "t_cdf", "t_sf", "norm_ppf", "norm_sf", "chi2_ppf", "chi2_sf", "f_cdf"]


def _out(v: Any) -> Any:
    """A 0-d result as a numpy float64 scalar (as scipy.stats returns), arrays as they are."""
    return v[()] if isinstance(v, np.ndarray) and v.ndim == 0 else v


def t_ppf(q: Any, df: Any) -> Any:
    """Quantile of Student's t with ``df`` degrees of freedom (df = inf: the normal's); -inf at
    q = 0 (special.stdtrit returns +inf there)."""
    q = np.asarray(q, dtype=np.float64)
    return _out(np.where(q == 0, -np.inf, special.stdtrit(df, q)))


def t_cdf(x: Any, df: Any) -> Any:
    """P(T <= x) for Student's t with ``df`` degrees of freedom."""
    return _out(special.stdtr(df, x))


def t_sf(x: Any, df: Any) -> Any:
    """P(T > x) for Student's t with ``df`` degrees of freedom (the lower tail at -x: accurate
    far out, where 1 - cdf cancels)."""
    return _out(special.stdtr(df, np.negative(x)))


def norm_ppf(q: Any) -> Any:
    """Quantile of the standard normal."""
    return _out(special.ndtri(q))


def norm_sf(x: Any) -> Any:
    """P(Z > x) for the standard normal."""
    return _out(special.ndtr(np.negative(x)))


def chi2_ppf(q: Any, k: Any) -> Any:
    """Quantile of the chi-square with ``k`` degrees of freedom, as scipy.stats computes it:
    2 P^-1(k/2, q) through the regularised incomplete gamma function (accurate for small q)."""
    return _out(2.0 * special.gammaincinv(np.divide(k, 2.0), q))


def chi2_sf(x: Any, k: Any) -> Any:
    """P(X > x) for the chi-square with ``k`` degrees of freedom."""
    return _out(special.chdtrc(k, x))


def f_cdf(x: Any, d1: Any, d2: Any) -> Any:
    """P(F <= x) for Fisher's F with (d1, d2) degrees of freedom."""
    return _out(special.fdtr(d1, d2, x))

