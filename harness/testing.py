"""Assertion helpers for users' own tests: each raises AssertionError with the measurement,
its interval, the sample count, alpha and what was expected, so pytest shows why."""
from __future__ import annotations

import numbers
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from scipy import stats as sps

from harness import stats
from harness.samplers.check import check_sampler
from harness.samplers.result import SamplerCheck
from harness.stats import validate
from harness.usercode import callable_name

__all__ = ["HarnessWarning", "assert_unbiased", "assert_biased", "assert_converges", "assert_sampler",
           "assert_rare"]


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


def assert_converges(integrand: Any, technique: Any = None, budgets: Sequence[int] | None = None, *,
                     dim: int | None = None, reference: float | None = None, rate: float = -0.5,
                     tolerance: float = 0.05, replicas: int = 32, seed: int = 0) -> stats.ConvergenceResult:
    """Fails when the RMSE's log-log slope is measurably worse than ``rate`` (one-sided p of
    "slope <= rate + tolerance" under 0.025, from the permutation test of
    harness.stats.slope_permutation: verdict "slower than expected").  The estimator is a
    catalogue integrand with its technique, or a contributions callable with ``dim`` and
    ``reference``:
    ``assert_converges(my_estimator, budgets=[256, 1024, 4096], dim=2, reference=0.349)``."""
    c = stats.convergence_rate(integrand, technique, budgets, replicas, dim=dim, reference=reference,
                               seed=seed, expected=rate, tolerance=tolerance)
    if not c.passed:
        raise AssertionError(f"expected RMSE ~ n^{rate:+.2f} or faster, got {c}\n"
                             f"{c.table.to_string(index=False)}")
    return c


def assert_sampler(sample: Callable[[np.ndarray], Any], pdf: Callable[[np.ndarray], Any], domain: Any, *,
                   sample_count: int = 1_000_000, alpha: float = 0.01, seed: int = 0, udim: int | None = None,
                   total: float | None = None) -> SamplerCheck:
    """Fails when check_sampler finds that ``sample`` does not draw what ``pdf`` claims on
    ``domain`` (false-alarm rate alpha; a deterministic failure always fails); the message is
    the check's explanation: which tests rejected, the failures with counts and examples, and
    the tests table.  ``total``: see check_sampler (samplers that may produce no sample)."""
    r = check_sampler(sample, pdf, domain, sample_count=sample_count, seed=seed, alpha=alpha, udim=udim,
                      total=total)
    if not r.passed:
        raise AssertionError(f"expected the samples of {callable_name(sample)} to follow the pdf "
                             f"{callable_name(pdf)} on the {domain}, got {r}")
    return r


def assert_rare(count: int, n: int, p: float, *, alpha: float = 0.01) -> float:
    """pbrt's CHECK_RARE as a test: an event that should happen with probability at most p
    happened ``count`` times in n trials; fails when that is too many at false-alarm rate
    alpha (one-sided binomial test).  Returns the p-value."""
    n = validate.count(n, "n")
    validate.integer_in(count, "count", 0, n)
    if isinstance(p, bool) or not isinstance(p, numbers.Real) or not 0 <= p <= 1:
        raise ValueError(f"'p' must be a probability in [0, 1], got {p!r}")
    validate.level(alpha, "alpha")
    pvalue = float(sps.binom.sf(count - 1, n, p))
    if pvalue < alpha:
        raise AssertionError(f"{count} events in {n} trials where at most a rate of {p:g} is allowed "
                             f"(binomial p-value {pvalue:.3g} < alpha = {alpha})")
    return pvalue
