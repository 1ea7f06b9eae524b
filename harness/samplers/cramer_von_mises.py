"""The Cramer-von Mises test of points against the uniform law, every point allowed to be off
by a bound (the sampler check's transformed coordinates, :mod:`harness.samplers.transform`,
carry their tables' error): the statistic from the core's sort-free bracket
(:func:`reference_estimators.cramer_von_mises_sum`) and its limiting law (:func:`cvm_sf`)."""
from __future__ import annotations

import math

import numpy as np
from scipy import special

import reference_estimators as rest

__all__ = ["cramer_von_mises", "cramer_von_mises_columns", "cramer_von_mises_from_sums", "cvm_sf"]


def cvm_sf(w2: float) -> float:
    """P(W^2 > w2) under H0 for the Cramer-von Mises statistic of n uniform points, in its
    n -> infinity law (accurate for the n >= 1000 of a sampler check): 1 - CDF from Anderson
    and Darling's (1952) series in Bessel K_{1/4} (to about 1e-12), and where that leaves
    under 1e-8 the tail of the law's first eigenterm, sqrt(2) erfc(pi sqrt(w2 / 2))
    (W^2 = sum_k Z_k^2 / (k pi)^2, the product over k >= 2 of (1 - 1/k^2)^(-1/2) being
    sqrt 2), within 2 % of the series there and decreasing: a p-value down to 1e-300.  NaN for
    a NaN w2 (the check's Holm step counts a NaN p-value as a rejection)."""
    if w2 != w2:
        return math.nan
    if not w2 > 0:
        return 1.0
    tail = math.sqrt(2) * math.erfc(math.pi * math.sqrt(w2 / 2))
    if tail < 1e-8:            # w2 > 3.4; the series would also need more terms beyond w2 ~ 50
        return tail
    j = np.arange(30)
    z = (4 * j + 1) ** 2 / (16 * w2)
    # Gamma(j + 1/2) / (Gamma(1/2) Gamma(j + 1)), by logs; exp(-z) K(z) = exp(-2 z) kve(z)
    coef = np.exp(special.gammaln(j + 0.5) - special.gammaln(0.5) - special.gammaln(j + 1))
    live = z < 350                       # beyond, exp(-2 z) underflows (and kve may be NaN)
    terms = np.where(live, coef * np.sqrt(4 * j + 1) * np.exp(-2 * np.where(live, z, 0.0))
                     * special.kve(0.25, np.where(live, z, 1.0)), 0.0)
    return float(min(max(1.0 - float(terms.sum() / (math.pi * math.sqrt(w2))), 0.0), 1.0))


def cramer_von_mises(u: np.ndarray, error: float) -> tuple[float, float]:
    """(N W^2, p) of the points u (N,) against the uniform law, every u allowed to be off by
    ``error`` from its exact value: by the triangle inequality in R^N the statistic's root
    part sqrt(N W^2 - 1/(12 N)) can then exceed the exact one by at most sqrt(N) * error, so
    that much is taken off before the p-value (conservative: the level holds).  N W^2 is the
    reported statistic (to about 1e-4: :func:`reference_estimators.cramer_von_mises_sum`
    brackets it without a sort), the p-value that of the reduced one from the bracket's
    lower end."""
    return cramer_von_mises_columns(np.asarray(u).reshape(-1, 1), [error])[0]


def cramer_von_mises_columns(u: np.ndarray, errors: list[float]) -> list[tuple[float, float]]:
    """:func:`cramer_von_mises` of each column of u (N, k), column j with ``errors[j]``, in one
    call to the core (strided columns read in place)."""
    return cramer_von_mises_from_sums(rest.cramer_von_mises_sum(u), u.shape[0], errors)


def cramer_von_mises_from_sums(sums: np.ndarray, n: int, errors: list[float]) -> list[tuple[float, float]]:
    """(N W^2, p) of :func:`cramer_von_mises` for each column of n points from the bracket
    (upper, slack) of its sum S = N W^2 - 1/(12 N)
    (:func:`reference_estimators.cramer_von_mises_sum`), column j allowed ``errors[j]``: the
    statistic from the upper end, the p-value from the lower end (conservative)."""
    out = []
    for (upper, slack), error in zip(np.asarray(sums).reshape(-1, 2), errors):
        w2 = upper + 1 / (12 * n)
        low = math.sqrt(max(upper - slack, 0.0)) if upper == upper else math.nan
        reduced = max(low - math.sqrt(n) * error, 0.0) ** 2 + 1 / (12 * n)
        out.append((float(w2), cvm_sf(reduced)))
    return out
