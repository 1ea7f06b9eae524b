"""The distribution functions the harness's verdicts and intervals need, from scipy.special.

Why not scipy.stats: importing it costs about 0.8 s (it pulls in scipy.sparse, .spatial and
.optimize), more than a resumed suite's whole command is allowed (issue 19: at most 1 s),
while scipy.special, which scipy.stats calls for these very functions, costs about 0.2 s.
Each function equals its scipy.stats counterpart bit for bit on the arguments the harness
passes (tests/stats/test_distributions.py compares them over grids including 0, 1, +-inf,
NaN and df = inf), and broadcasts like it.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import special

__all__ = ["t_ppf", "t_cdf", "t_sf", "norm_ppf", "norm_sf", "chi2_ppf", "chi2_sf", "f_cdf",
           "log_gamma_sum_sf"]


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


def log_gamma_sum_sf(z: float, weights: Any, shapes: Any) -> float:
    """P(sum_b w_b log G_b >= z) for independent G_b ~ Gamma(shape a_b, scale 1 / a_b) (mean
    1): the law of a log-log slope fitted to mean squared errors of normal estimates (their
    mean over R replicas is sigma^2 Gamma(R / 2, 2 / R)), whose right tail is heavier than a
    normal's.  By the Lugannani-Rice saddlepoint formula on the exact cumulant generating
    function K(t) = sum_b [lgamma(a_b + w_b t) - lgamma(a_b) - w_b t log a_b] (within 10 %
    of a Monte Carlo of 2e6 draws down to 1e-4 for three terms of shape 8: tests/stats); within
    0.01 standard deviations of the mean, and for shapes over 1e4, the first Edgeworth term.
    NaN for a NaN z.  Written here (no scipy.stats law is this sum); the saddlepoint t
    solves K'(t) = z by Newton steps kept inside the domain a_b + w_b t > 0, where K' is
    increasing."""
    w = np.asarray(weights, dtype=np.float64)
    a = np.asarray(shapes, dtype=np.float64)
    if math.isnan(z):
        return math.nan
    if math.isinf(z):
        return 0.0 if z > 0 else 1.0

    def k(t: float) -> tuple[float, float, float]:   # K, K', K''
        at = a + w * t
        return (float(np.sum(special.gammaln(at) - special.gammaln(a) - w * t * np.log(a))),
                float(np.sum(w * (special.digamma(at) - np.log(a)))),
                float(np.sum(w * w * special.polygamma(1, at))))

    _, mean, var = k(0.0)
    x = (z - mean) / math.sqrt(var)
    # near the mean the saddlepoint formula cancels (1/u - 1/r), and for shapes over 1e4 its
    # K(t) loses digits to lgamma's size: there the law is near normal, and the first
    # Edgeworth term holds, P(X >= x) = Phi(-x) + phi(x) (skewness / 6) (x^2 - 1)
    if abs(x) < 0.01 or float(np.min(a)) > 1e4:
        skew = float(np.sum(w ** 3 * special.polygamma(2, a))) / var ** 1.5
        density = math.exp(-0.5 * x * x) / math.sqrt(2 * math.pi)
        return float(min(max(special.ndtr(-x) + density * skew / 6 * (x * x - 1), 0.0), 1.0))
    # the domain of t, and Newton's steps on K'(t) = z bracketed within it
    lo = float(np.max(-a[w > 0] / w[w > 0])) if np.any(w > 0) else -math.inf
    hi = float(np.min(-a[w < 0] / w[w < 0])) if np.any(w < 0) else math.inf
    left, right = (0.0, hi) if z > mean else (lo, 0.0)
    t = 0.0
    for _ in range(200):
        _, slope, curve = k(t)
        if abs(slope - z) <= 1e-12 * max(1.0, abs(z)) or right - left <= 1e-15 * max(1.0, abs(t)):
            break
        if slope < z:
            left = t
        else:
            right = t
        step = t - (slope - z) / curve
        if not left < step < right:   # Newton left the bracket: halve it, or widen an open side
            step = (0.5 * (left + right) if math.isfinite(left) and math.isfinite(right) else
                    max(2 * t, 1.0) if right == math.inf else min(2 * t, -1.0))
        t = step
    kt, _, curve = k(t)
    r = math.copysign(math.sqrt(max(2.0 * (t * z - kt), 0.0)), t)
    u = t * math.sqrt(curve)
    return float(min(max(special.ndtr(-r) + math.exp(-0.5 * r * r) / math.sqrt(2 * math.pi) * (1 / u - 1 / r),
                         0.0), 1.0))
