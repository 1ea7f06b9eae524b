"""Assertion helpers for users' own tests: each raises AssertionError with the measurement,
its interval, the sample count, alpha and what was expected, so pytest shows why."""
from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence

import numpy as np
from scipy import stats as sps

import reference_estimators as rest

from harness import stats

__all__ = ["HarnessWarning", "assert_unbiased", "assert_biased", "assert_converges", "assert_rare"]


class HarnessWarning(UserWarning):
    """A check could not reach a verdict (e.g. the variance looks infinite)."""


def assert_unbiased(contributions: Callable[[np.ndarray], np.ndarray], dim: int, reference: float, *,
                    sample_count: int, alpha: float = 0.01, seed: int = 0) -> stats.UnbiasedResult:
    """Fails (false-alarm rate alpha) when check_unbiased finds a bias or faulty values;
    warns (HarnessWarning) when it is inconclusive."""
    r = stats.check_unbiased(contributions, dim, reference, sample_count=sample_count, seed=seed, alpha=alpha)
    if not r.passed:
        raise AssertionError(f"expected an unbiased estimator of {reference!r}, got {r}")
    if r.verdict == "inconclusive":
        warnings.warn(f"bias test inconclusive: {r}", HarnessWarning, stacklevel=2)
    return r


def assert_biased(contributions: Callable[[np.ndarray], np.ndarray], dim: int, reference: float, *,
                  sample_count: int, alpha: float = 0.01, seed: int = 0) -> stats.UnbiasedResult:
    """Fails when a bias that should be there is not found: a power check for a test suite
    (how often it fails for a real bias is the power, see harness.stats.zoo)."""
    r = stats.check_unbiased(contributions, dim, reference, sample_count=sample_count, seed=seed, alpha=alpha)
    if r.verdict != "biased":
        raise AssertionError(f"expected a detectable bias against {reference!r} at alpha = {alpha}, got {r}")
    return r


def assert_converges(integrand: str | rest.Integrand, technique: str | rest.Technique,
                     budgets: Sequence[int], *, rate: float = -0.5, tolerance: float = 0.05,
                     replicas: int = 32, seed: int = 0) -> stats.ConvergenceResult:
    """Fails when the RMSE's log-log slope is measurably worse than ``rate`` (its whole 95 %
    bootstrap interval above rate + tolerance: verdict "slower than expected", a one-sided
    test at level 0.025)."""
    c = stats.convergence_rate(integrand, technique, budgets, replicas, seed=seed, expected=rate,
                               tolerance=tolerance)
    if not c.passed:
        raise AssertionError(f"expected RMSE ~ n^{rate:+.2f} or faster, got {c}\n"
                             f"{c.table.to_string(index=False)}")
    return c


def assert_rare(count: int, n: int, p: float, *, alpha: float = 0.01) -> float:
    """pbrt's CHECK_RARE as a test: an event that should happen with probability at most p
    happened ``count`` times in n trials; fails when that is too many at false-alarm rate
    alpha (one-sided binomial test).  Returns the p-value."""
    if not (0 <= p <= 1 and n > 0 and 0 <= count <= n):
        raise ValueError(f"need 0 <= p <= 1, n > 0 and 0 <= count <= n, got p = {p}, n = {n}, "
                         f"count = {count}")
    pvalue = float(sps.binom.sf(count - 1, n, p))
    if pvalue < alpha:
        raise AssertionError(f"{count} events in {n} trials where at most a rate of {p:g} is allowed "
                             f"(binomial p-value {pvalue:.3g} < alpha = {alpha})")
    return pvalue
