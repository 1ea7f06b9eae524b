"""The convergence rate of an estimator's RMSE over budgets (:class:`ConvergenceResult`): a
log-log slope fitted to replicas (:class:`~harness.stats.replicas.Replicates`) at geometric
budgets, judged against the promised rate by the slope's own law.

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
from harness.stats.validate import count, finite

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["ConvergenceResult", "convergence_rate", "fit_convergence", "MIN_CONVERGENCE_REPLICAS"]


# An RMSE this many ulp of the estimates is rounding (of the contributions and of their sum),
# not Monte Carlo error: 2.3e-13 relative, which a Monte Carlo error reaches only beyond ~1e24
# samples per unit of relative standard deviation
_ROUNDING_ULPS = 1024


# --- convergence rate ------------------------------------------------------------------------
#: Replicas per budget below which a fit of pooled errors (an image's relMSE, judged by the
#: normal approximation with the bootstrap's spread) is not judged: the bootstrap over fewer
#: understates the slope's spread.  Simulated at the bound (slope -0.45, 3 budgets, 2000
#: seeds, relMSE over 3072 t(3) pixels; p < 0.05 / 0.01 / 0.001): 11 / 4.3 / 1.35 % at 4
#: replicas, 6.6 / 1.35 / 0.10 % at 16.  (Single estimates are judged by the slope's own law at
#: any count: :func:`_gamma_shapes`; with the normal approximation a correct uniform MC had
#: failed 34-52 of 1000 seeds at the stated 0.025 with 4 replicas, 2026-12-06.)
MIN_CONVERGENCE_REPLICAS = 16
#: Bootstrap resamples a slope's interval takes at least
MIN_BOOTSTRAP = 100


@dataclass(frozen=True)
class ConvergenceResult:
    """RMSE against the exact reference at geometric budgets, and the fitted log-log slope;
    a member of the result family (:mod:`harness.stats.results`).

    H0: the RMSE falls at least as fast as n^(``expected`` + ``tolerance``), i.e. slope <=
    expected + tolerance.  ``verdict`` is "slower than expected" when ``pvalue`` (one-sided,
    below) is under ``alpha`` = (1 - ``confidence_level``) / 2 (0.025 at the default 95 %),
    else "as expected".  For single estimates (``shapes``) the p-value, the interval and
    ``statistic`` (the normal quantile of p) all come from the slope's own law, so the interval
    lies above the bound exactly when the test rejects; for pooled errors (an image's relMSE)
    from the normal approximation with the bootstrap's spread and the percentile bootstrap.
    ``n`` counts the replica estimates over all budgets; there are no deterministic
    ``failures`` (faulty contributions stop :meth:`Replicates.from_estimates`).  "inconclusive"
    (``inconclusive`` says why; it passes, and its ``pvalue`` is 1: nothing is rejected): single
    estimates too few to reject even a flat RMSE, pooled errors with fewer than
    :data:`MIN_CONVERGENCE_REPLICAS` replicas at some budget, a slope that is not a number.
    """

    integrand: str
    technique: str
    table: pd.DataFrame       # n, rmse, rmse_lo, rmse_hi, seconds, replicas
    slope: float
    slope_se: float           # standard deviation of the bootstrap slopes
    bootstrap_slopes: np.ndarray
    confidence_level: float
    expected: float
    tolerance: float
    failures: list[Failure] = field(default_factory=list)
    rounding_floor: float = 0.0   # an RMSE at or below this is rounding: 1024 ulp of the largest estimate
    # per budget, the shape a of the Gamma(a, 1/a) law of its mean squared error over the
    # scale's (the slope's law: distributions.log_gamma_sum_sf); () for pooled errors (an
    # image's relMSE), judged by the normal approximation with the bootstrap's spread
    shapes: tuple[float, ...] = ()
    _memo: dict = field(default_factory=dict, repr=False, compare=False)   # the law's tails, computed once

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
        """Why no rate is judged ("" where one is): a slope that is not a number; single
        estimates so few that not even a flat RMSE (slope 0) would be rejected at ``alpha`` (a
        test without power: it had passed a clamped estimator with 2 replicas); pooled errors
        with fewer than :data:`MIN_CONVERGENCE_REPLICAS` replicas at some budget."""
        if self.at_rounding_level:
            return ""
        if not math.isfinite(self.slope):
            return "the slope is not a number (an RMSE of 0 at some budget)"
        fewest = int(self.table["replicas"].min())
        if self.shapes:
            if self._law_sf(0.0) < self.alpha:
                return ""
            return (f"{fewest} replicas at a budget over {len(self.table)} budgets: not even a flat RMSE "
                    f"would be rejected at alpha = {self.alpha:g}; take more replicas or budgets")
        if fewest >= MIN_CONVERGENCE_REPLICAS:
            return ""
        return (f"{fewest} replicas at a budget: a slope of pooled errors is judged from "
                f"{MIN_CONVERGENCE_REPLICAS} (the bootstrap understates the spread of fewer)")

    def _weights(self) -> np.ndarray:
        """The slope's weights on each budget's 0.5 log mean squared error."""
        x = np.log(self.table["n"].to_numpy(dtype=np.float64))
        x = x - x.mean()
        return 0.5 * x / (x @ x)

    def _law_sf(self, slope: float) -> float:
        """P(fitted slope >= ``slope``) under the bound, by the slope's law (``shapes``)."""
        key = ("sf", slope)
        if key not in self._memo:
            self._memo[key] = distributions.log_gamma_sum_sf(slope - self.expected - self.tolerance,
                                                             self._weights(), self.shapes)
        return self._memo[key]

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
        """z of the slope against the bound: the normal quantile of ``pvalue`` by the slope's
        law (``shapes``), else (slope - bound) / slope_se; NaN where it has no spread or the fit
        is inconclusive."""
        if self.inconclusive:
            return math.nan
        if self.shapes:
            return float(-distributions.norm_ppf(self._law_sf(self.slope)))
        if not self.slope_se > 0:
            return math.nan
        return (self.slope - self.expected - self.tolerance) / self.slope_se

    @property
    def pvalue(self) -> float:
        """One-sided p-value of H0 "slope <= expected + tolerance": small when the error falls
        measurably too slowly.  From the slope's own law where the replicas are single estimates
        (``shapes``: a weighted sum of logs of Gamma variables, whose right tail the normal
        approximation understated), else the normal approximation with the bootstrap standard
        error.  For many cases at once, correct these with holm().  1 at the rounding level and
        where inconclusive."""
        if self.at_rounding_level or self.inconclusive:
            return 1.0
        bound = self.expected + self.tolerance
        if self.shapes:
            return self._law_sf(self.slope)
        if not self.slope_se > 0:
            return 1.0 if self.slope <= bound else 0.0
        return float(distributions.norm_sf((self.slope - bound) / self.slope_se))

    def confidence_interval(self, confidence_level: float = 0.95) -> ConfidenceInterval:
        """Interval of the slope: by the slope's law where there are ``shapes`` (the slope less
        the law's upper and lower quantiles: its low end lies above the bound exactly when p <
        alpha at this level), else the percentile bootstrap's (resampling replicas within each
        budget)."""
        if not self.shapes or not math.isfinite(self.slope):
            return _percentile_interval(self.bootstrap_slopes, confidence_level)
        tail = (1 - check_confidence_level(confidence_level)) / 2
        key = ("interval", tail)
        if key not in self._memo:
            w = self._weights()
            self._memo[key] = ConfidenceInterval(
                self.slope - distributions.log_gamma_sum_isf(tail, w, self.shapes),
                self.slope - distributions.log_gamma_sum_isf(1 - tail, w, self.shapes))
        return self._memo[key]

    def __str__(self) -> str:
        lo, hi = self.confidence_interval(self.confidence_level)
        return (f"{self.verdict}: {self.integrand}/{self.technique}: RMSE ~ n^{self.slope:+.3f} "
                f"({100 * self.confidence_level:g} % CI [{lo:+.3f}, {hi:+.3f}]), "
                f"expected {self.expected:+.2f} or faster (tolerance {self.tolerance:g}), "
                f"one-sided p = {self.pvalue:.3g}, {self.n} replicas over {len(self.table)} budgets"
                + (f"; RMSE at the rounding level (<= {self.rounding_floor:.3g}): no rate to judge"
                   if self.at_rounding_level else "")
                + (f"; not judged: {self.inconclusive}" if self.inconclusive else ""))


def _percentile_interval(boot: np.ndarray, confidence_level: float) -> ConfidenceInterval:
    check_confidence_level(confidence_level)
    a = 1 - confidence_level
    return ConfidenceInterval(float(np.quantile(boot, a / 2)), float(np.quantile(boot, 1 - a / 2)))


def convergence_rate(integrand: Any, technique: Any = None, budgets: Sequence[int] | None = None,
                     replicas: int = 32, *, dim: int | None = None, reference: float | None = None,
                     seed: int = 0, case_id: int = 0, expected: float = -0.5, tolerance: float = 0.05,
                     confidence_level: float = 0.95, bootstrap: int = 400,
                     threads: int | None = None) -> ConvergenceResult:
    """Fit log RMSE = a + slope log n by least squares over ``budgets`` (replicas each).

    The estimator is a catalogue integrand with its technique, or a contributions callable
    with ``dim`` and ``reference`` (as for :func:`replicate`).

    The slope's interval comes from a bootstrap over replicas within each budget (percentile,
    ``bootstrap`` resamples from a generator seeded by ``seed``); its p-value from the slope's
    own law (:func:`fit_convergence`).
    Budgets should span at least a factor 16.  Zero-variance estimators give an RMSE at the
    rounding level and a slope near 0: ``at_rounding_level``, judged "as expected" (p = 1).
    """
    est = judgeable(estimator(integrand, technique, dim=dim, reference=reference))
    b = _budgets(budgets)
    _check_fit(expected, tolerance, confidence_level, bootstrap)
    reps = [replicate(est, n=n, replicas=replicas, seed=seed, case_id=case_id + 7919 * i, threads=threads)
            for i, n in enumerate(b)]
    return fit_convergence(reps, expected=expected, tolerance=tolerance, confidence_level=confidence_level,
                           bootstrap=bootstrap, seed=seed)


def _check_fit(expected: Any, tolerance: Any, confidence_level: Any, bootstrap: Any) -> None:
    """ValueError naming the first of a slope fit's settings that is not usable."""
    check_confidence_level(confidence_level)
    finite(expected, "expected")
    if finite(tolerance, "tolerance") < 0:
        raise ValueError(f"'tolerance' must be >= 0, got {tolerance!r}")
    if count(bootstrap, "bootstrap") < MIN_BOOTSTRAP:
        raise ValueError(f"'bootstrap' must be at least {MIN_BOOTSTRAP} resamples, got {bootstrap!r}")


def _budgets(budgets: Any) -> list[int]:
    """At least 3 distinct budgets, sorted: whole numbers, from any sequence (an array too)."""
    try:
        given = [] if budgets is None else list(budgets)
    except TypeError:
        raise ValueError(f"'budgets' must be a sequence of sample counts, got {budgets!r}") from None
    b = sorted({count(x, "budgets") for x in given})
    if len(b) < 3:
        raise ValueError(f"'budgets' needs at least 3 distinct sizes, got {budgets!r}")
    return b


def fit_convergence(reps: Sequence[Replicates], *, expected: float = -0.5, tolerance: float = 0.05,
                    confidence_level: float = 0.95, bootstrap: int = 400, seed: int = 0,
                    pooled: bool = False) -> ConvergenceResult:
    """The slope fit of convergence_rate, from replicates at 3 or more distinct budgets;
    ``expected`` and ``tolerance`` finite, ``bootstrap`` at least :data:`MIN_BOOTSTRAP`.

    The p-value (:attr:`ConvergenceResult.pvalue`) comes from the slope's law where each
    replica is one estimate (normal by the central limit theorem): a budget's mean squared
    error over R replicas is its scale times Gamma(a, 1/a), a = R / 2, and the slope a
    weighted sum of their logs (:func:`_gamma_shapes`).  ``pooled``: each replica's error is
    itself a mean over many values (an image's relMSE over its pixels), nearly constant from
    replica to replica; the normal approximation with the bootstrap's spread judges it."""
    _check_fit(expected, tolerance, confidence_level, bootstrap)
    _budgets([r.n for r in reps])
    sc = min(r._scale for r in reps)  # one power-of-two scale for all budgets: the slope does not change
    errors = [r.estimates * sc - r.reference * sc for r in reps]
    x = np.log([r.n for r in reps])
    x = x - x.mean()
    floor = np.finfo(float).tiny

    def slopes(sq: np.ndarray) -> np.ndarray:
        """Least-squares slopes of log RMSE on log n, one per row of mean squared errors."""
        y = 0.5 * np.log(np.maximum(sq, floor))
        return (y - y.mean(axis=-1, keepdims=True)) @ x / (x @ x)

    slope = float(slopes(np.array([np.mean(e * e) for e in errors])))
    rng = np.random.default_rng(seed)
    # all bootstrap resamples at once: (bootstrap, budgets) mean squared errors
    boot_sq = np.stack([np.mean(e[rng.integers(0, e.size, (bootstrap, e.size))] ** 2, axis=1)
                        for e in errors], axis=1)
    boot = slopes(boot_sq)
    import pandas as pd  # deferred, as in harness.suite.kind.Outcome.frame
    rows = []
    for r in reps:
        lo, hi = r.rmse_interval(confidence_level)
        rows.append({"n": r.n, "rmse": r.rmse, "rmse_lo": lo, "rmse_hi": hi, "seconds": r.time[0],
                     "replicas": r.replicas})
    largest = max(max(float(np.max(np.abs(r.estimates))), abs(r.reference)) for r in reps)
    return ConvergenceResult(reps[0].integrand, reps[0].technique, pd.DataFrame(rows), slope,
                             float(np.std(boot, ddof=1)), boot, confidence_level, expected, tolerance,
                             rounding_floor=_ROUNDING_ULPS * np.finfo(float).eps * largest,
                             shapes=() if pooled else _gamma_shapes(errors))


def _gamma_shapes(errors: Sequence[np.ndarray]) -> tuple[float, ...]:
    """Per budget, the shape a = R alpha of the Gamma law of its replicas' mean squared error
    (divided by its mean): alpha = 1/2 for normal estimates (squares chi-square with one
    degree of freedom), smaller where their tails are heavier.  alpha is estimated from the
    squares' spread pooled over the budgets (the Dirichlet moment E[mean_r (e_r^2 / mean
    e^2)^2] = R (alpha + 1) / (R alpha + 1) of Gamma(alpha) squares, solved for alpha) and
    capped at 1/2: a lighter tail than the normal's is not credited (48 squares estimate it
    too roughly to lean on).  Simulated at the bound (slope -0.45, 20 000 seeds; p < 0.05 /
    0.01 / 0.001): normal estimates, 16 replicas over 3 budgets 4.5 / 0.97 / 0.10 %, 32 over 5
    4.3 / 0.76 / 0.10 %; estimates with t(5) errors (kurtosis 9), 16 over 3 budgets
    6.4 / 1.7 / 0.23 %, where the normal approximation had rejected normal estimates at
    7.2 / 2.3 / 0.52 %."""
    m, sizes = [], []
    for e in errors:
        sq = e * e
        mean = float(np.mean(sq))
        if mean > 0:
            m.append(float(np.mean((sq / mean) ** 2)))
            sizes.append(sq.size)
    alpha = 0.5
    if m:
        r, mm = float(np.mean(sizes)), float(np.mean(m))
        if mm > 1:
            alpha = min(alpha, (r - min(mm, r)) / (r * (mm - 1)) if mm < r else 0.0)
    alpha = max(alpha, 1e-3)
    return tuple(float(e.size) * alpha for e in errors)
