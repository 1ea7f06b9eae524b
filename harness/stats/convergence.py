"""The convergence rate of an estimator's RMSE over budgets (:class:`ConvergenceResult`): a
log-log slope fitted to replicas (:class:`~harness.stats.replicas.Replicates`) at geometric
budgets, judged against the promised rate by a permutation test
(:mod:`harness.stats.slope_permutation`).

Every figure comes with its uncertainty and the number of estimates it came from.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from harness.stats import distributions
from harness.stats.estimator import estimator
from harness.stats.replicas import Replicates, judgeable, replicate
from harness.stats.results import ConfidenceInterval, Failure, check_confidence_level
from harness.stats.slope_permutation import SlopePermutationTest
from harness.stats.validate import finite, sizes

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["ConvergenceResult", "convergence_rate", "fit_convergence"]


# An RMSE this many ulp of the estimates is rounding (of the contributions and of their sum),
# not Monte Carlo error: 2.3e-13 relative, which a Monte Carlo error reaches only beyond ~1e24
# samples per unit of relative standard deviation
_ROUNDING_ULPS = 1024


# --- convergence rate ------------------------------------------------------------------------
@dataclass(frozen=True)
class ConvergenceResult:
    """RMSE against the exact reference at geometric budgets, and the fitted log-log slope;
    a member of the result family (:mod:`harness.stats.results`).

    H0: the RMSE falls at least as fast as n^(``expected`` + ``tolerance``), i.e. slope <=
    expected + tolerance.  ``verdict`` is "slower than expected" when ``pvalue`` (one-sided,
    the permutation test of :mod:`harness.stats.slope_permutation`) is under ``alpha`` = (1 -
    ``confidence_level``) / 2 (0.025 at the default 95 %), else "as expected".  The interval
    inverts the same test, so it lies above the bound exactly when the test rejects;
    ``statistic`` is the normal quantile of the p-value.  ``n`` counts the replicas over all
    budgets; there are no deterministic ``failures`` (faulty contributions stop
    :meth:`Replicates.from_estimates`).  "inconclusive" (``inconclusive`` says why; it passes,
    and its ``pvalue`` is 1): a slope that is not a number, or replicas too few for the test
    to reject (:attr:`inconclusive`).
    """

    integrand: str
    technique: str
    table: pd.DataFrame       # n, rmse, rmse_lo, rmse_hi, seconds, replicas
    slope: float
    confidence_level: float
    expected: float
    tolerance: float
    test: SlopePermutationTest = field(repr=False, compare=False)   # the replicas' squared errors
    failures: list[Failure] = field(default_factory=list)
    rounding_floor: float = 0.0   # an RMSE at or below this is rounding: 1024 ulp of the largest estimate
    # each replica's error a mean over many values (an image's relMSE), not one estimate
    pooled: bool = False
    _memo: dict = field(default_factory=dict, repr=False, compare=False)   # computed once

    @property
    def at_rounding_level(self) -> bool:
        """The error at the largest budget is at the rounding level (a zero-variance technique):
        it cannot fall further, so no rate is judged ("as expected", p = 1)."""
        return bool(self.table["rmse"].iloc[-1] <= self.rounding_floor)

    @property
    def alpha(self) -> float:
        return (1 - self.confidence_level) / 2

    @property
    def n(self) -> int:
        return int(self.table["replicas"].sum())

    @property
    def inconclusive(self) -> str:
        """Why no rate is judged ("" where one is): a slope that is not a number; replicas too
        few for the test to reject at ``alpha``: so few arrangements (or draws of them) that
        no p-value falls below it (:attr:`SlopePermutationTest.smallest_pvalue`), or, for
        single estimates, so few that not even a flat RMSE (slope 0) would be rejected, by the
        law of that slope for normal estimates (a budget's mean square over R of them is
        Gamma(R/2): :func:`distributions.log_gamma_sum_sf`; 2 replicas over 3 budgets had
        passed a clamped estimator).  Decided by the design (replicas and budgets), never by
        the errors."""
        if "inconclusive" not in self._memo:
            self._memo["inconclusive"] = self._why_inconclusive()
        return self._memo["inconclusive"]

    def _why_inconclusive(self) -> str:
        if self.at_rounding_level:
            return ""
        if not math.isfinite(self.slope):
            return "the slope is not a number (an RMSE of 0 at some budget, or errors that are not numbers)"
        fewest, budgets = int(self.table["replicas"].min()), len(self.table)
        smallest = self.test.smallest_pvalue
        if smallest >= self.alpha:
            return (f"{fewest} replicas at a budget over {budgets} budgets: the test's smallest p-value, "
                    f"{smallest:.3g}, is not below alpha = {self.alpha:g}")
        if self.pooled:
            return ""
        shapes = self.table["replicas"].to_numpy(dtype=np.float64) / 2
        flat = -self.expected - self.tolerance    # a fitted slope of 0, against the bound
        if distributions.log_gamma_sum_sf(flat, self.test.weights, shapes) < self.alpha:
            return ""
        return (f"{fewest} replicas at a budget over {budgets} budgets: not even a flat RMSE "
                f"would be rejected at alpha = {self.alpha:g}; take more replicas or budgets")

    @property
    def verdict(self) -> str:
        if self.inconclusive:
            return "inconclusive"
        return "slower than expected" if self.pvalue < self.alpha else "as expected"

    @property
    def passed(self) -> bool:
        return self.verdict in ("as expected", "inconclusive")

    @property
    def statistic(self) -> float:
        """z of the slope against the bound: the normal quantile of ``pvalue``; NaN where the
        fit is inconclusive."""
        if self.inconclusive or self.at_rounding_level:
            return math.nan
        return float(-distributions.norm_ppf(min(self.pvalue, 1 - 2 ** -53)))   # finite at p = 1

    @property
    def pvalue(self) -> float:
        """One-sided p-value of H0 "slope <= expected + tolerance": small when the error falls
        measurably too slowly.  The permutation test's (exact wherever the errors have one
        shape at every budget, their law's tails whatever they are); for many cases at once,
        correct these with holm().  1 at the rounding level and where inconclusive."""
        if self.at_rounding_level or self.inconclusive:
            return 1.0
        if "p" not in self._memo:
            self._memo["p"] = self.test.pvalue_above(self.expected + self.tolerance, self.alpha)
        return self._memo["p"]

    def confidence_interval(self, confidence_level: float = 0.95) -> ConfidenceInterval:
        """Interval of the slope: the slopes b that the permutation test of H0 "the RMSE falls
        as n^b" does not reject on either side at (1 - ``confidence_level``) / 2 (its low end
        lies above the bound exactly when p < alpha at this level); (nan, nan) where the slope
        is not a number."""
        tail = (1 - check_confidence_level(confidence_level)) / 2
        if not math.isfinite(self.slope):
            return ConfidenceInterval(math.nan, math.nan)
        if tail not in self._memo:
            self._memo[tail] = ConfidenceInterval(*self.test.interval(self.slope, tail))
        return self._memo[tail]

    def __str__(self) -> str:
        lo, hi = self.confidence_interval(self.confidence_level)
        return (f"{self.verdict}: {self.integrand}/{self.technique}: RMSE ~ n^{self.slope:+.3f} "
                f"({100 * self.confidence_level:g} % CI [{lo:+.3f}, {hi:+.3f}]), "
                f"expected {self.expected:+.2f} or faster (tolerance {self.tolerance:g}), "
                f"one-sided p = {self.pvalue:.3g}, {self.n} replicas over {len(self.table)} budgets"
                + (f"; RMSE at the rounding level (<= {self.rounding_floor:.3g}): no rate to judge"
                   if self.at_rounding_level else "")
                + (f"; not judged: {self.inconclusive}" if self.inconclusive else ""))


def convergence_rate(integrand: Any, technique: Any = None, budgets: Sequence[int] | None = None,
                     replicas: int = 32, *, dim: int | None = None, reference: float | None = None,
                     seed: int = 0, case_id: int = 0, expected: float = -0.5, tolerance: float = 0.05,
                     confidence_level: float = 0.95, threads: int | None = None) -> ConvergenceResult:
    """Fit log RMSE = a + slope log n by least squares over ``budgets`` (replicas each), and
    test it against n^(``expected`` + ``tolerance``) (:func:`fit_convergence`).

    The estimator is a catalogue integrand with its technique, or a contributions callable
    with ``dim`` and ``reference`` (as for :func:`replicate`).
    Budgets should span at least a factor 16.  Zero-variance estimators give an RMSE at the
    rounding level and a slope near 0: ``at_rounding_level``, judged "as expected" (p = 1).
    """
    est = judgeable(estimator(integrand, technique, dim=dim, reference=reference))
    b = sizes(budgets, "budgets", 3)
    _check_fit(expected, tolerance, confidence_level)
    reps = [replicate(est, n=n, replicas=replicas, seed=seed, case_id=case_id + 7919 * i, threads=threads)
            for i, n in enumerate(b)]
    return fit_convergence(reps, expected=expected, tolerance=tolerance, confidence_level=confidence_level,
                           seed=seed)


def _check_fit(expected: Any, tolerance: Any, confidence_level: Any) -> None:
    """ValueError naming the first of a slope fit's settings that is not usable."""
    check_confidence_level(confidence_level)
    finite(expected, "expected")
    if finite(tolerance, "tolerance") < 0:
        raise ValueError(f"'tolerance' must be >= 0, got {tolerance!r}")


def fit_convergence(reps: Sequence[Replicates], *, expected: float = -0.5, tolerance: float = 0.05,
                    confidence_level: float = 0.95, seed: int = 0, pooled: bool = False) -> ConvergenceResult:
    """The slope fit of convergence_rate, from replicates at 3 or more distinct budgets;
    ``expected`` and ``tolerance`` finite.

    The slope is the least-squares slope of log RMSE (the root of each budget's mean squared
    error over its replicas) on log n; its p-value and interval come from the permutation test
    of :mod:`harness.stats.slope_permutation` (arrangements drawn from ``seed``), exact where
    the replicas' errors have one shape at every budget whatever their tails.  ``pooled``:
    each replica's error is itself a mean over many values (an image's relMSE over its
    pixels): the same test, judged from the arrangements there are rather than the power a
    flat RMSE of single estimates would meet (:attr:`ConvergenceResult.inconclusive`).
    Measured at the bound (benchmarks/convergence_calibration.py): see the module docstring
    of :mod:`harness.stats.slope_permutation`."""
    _check_fit(expected, tolerance, confidence_level)
    budgets = [r.n for r in reps]
    sizes(budgets, "budgets", 3)
    sc = min(r._scale for r in reps)  # one power-of-two scale for all budgets: the slope does not change
    squares = [(r.estimates * sc - r.reference * sc) ** 2 for r in reps]
    test = SlopePermutationTest(squares, budgets, seed)
    slope = float(test.slope(np.concatenate(squares)))
    zero = [float(np.mean(sq)) == 0 for sq in squares]
    if any(zero) and not all(zero):   # no log of its RMSE: the floor had made a slope of +126
        slope = math.nan
    import pandas as pd  # deferred, as in harness.suite.kind.Outcome.frame
    rows = []
    for r in reps:
        lo, hi = r.rmse_interval(confidence_level)
        rows.append({"n": r.n, "rmse": r.rmse, "rmse_lo": lo, "rmse_hi": hi, "seconds": r.time[0],
                     "replicas": r.replicas})
    largest = max(max(float(np.max(np.abs(r.estimates))), abs(r.reference)) for r in reps)
    return ConvergenceResult(reps[0].integrand, reps[0].technique, pd.DataFrame(rows), slope,
                             confidence_level, expected, tolerance, test,
                             rounding_floor=_ROUNDING_ULPS * np.finfo(float).eps * largest,
                             pooled=bool(pooled))
