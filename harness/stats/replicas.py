"""Replicas and what they measure: R independent estimates of one case at one budget
(:class:`Replicates`), the convergence rate of the RMSE over budgets (:class:`ConvergenceResult`)
and error against run time; the efficiency 1/(V T) of replicates is :mod:`harness.stats.efficiency`.

Every figure comes with its uncertainty and the number of estimates it came from.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

import reference_estimators as rest

from harness.stats import distributions
from harness.stats.estimator import Contributions, Estimator, estimator
from harness.stats.merge import chan_merge
from harness.stats.results import ConfidenceInterval, Failure, check_confidence_level, summed_counts
from harness.stats.timing import clock_time, median_time, reference_clock
from harness.stats.validate import count, finite

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["Replicates", "replicate", "ConvergenceResult", "convergence_rate", "MIN_CONVERGENCE_REPLICAS",
           "fit_convergence", "error_vs_time"]


# An RMSE this many ulp of the estimates is rounding (of the contributions and of their sum),
# not Monte Carlo error: 2.3e-13 relative, which a Monte Carlo error reaches only beyond ~1e24
# samples per unit of relative standard deviation
_ROUNDING_ULPS = 1024


# --- replicas ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Replicates:
    """R independent estimates of one case at one budget, with their wall times.

    Their spread measures the error of any technique, stratified and Sobol' included;
    for independent samples the pooled per-sample variance (``sample_variance``, from all
    R * n contributions) measures it more precisely.  Built by :func:`replicate` (or
    :meth:`from_estimates`); by hand, give:

    * ``integrand``, ``technique``: names for tables; ``n``: contributions (or spp) per estimate;
    * ``reference``: the exact value the errors are measured against;
    * ``estimates``, ``seconds``: each replica's estimate and wall time (s), shape (R,);
    * ``sample_variance``: the variance of one contribution pooled over all R * n of them, or
      NaN where contributions are not independent (``iid`` False: stratified, Sobol', images);
    * ``sample_kurtosis``: their (non-excess) kurtosis, 3 for normal contributions: it sets
      the relative error sqrt((kurtosis - 1) / (R n)) of ``sample_variance``; NaN if unknown;
    * ``iid``: the variance of an estimate is ``sample_variance`` / n (else: the replicas' spread);
    * ``evaluations``: integrand evaluations per contribution (informational; 1 if unknown);
    * ``finite_variance``: whether the contributions' variance is known to be finite (False:
      infinite, so the efficiency is 0), None if unknown;
    * ``clock``: each replica's reference-clock time (s, harness.stats.timing.CLOCK), timed on
      its thread just before it, shape (R,); None if not timed.
    """

    integrand: str
    technique: str
    n: int
    reference: float
    estimates: np.ndarray     # (R,)
    seconds: np.ndarray       # (R,)
    sample_variance: float    # pooled per-contribution variance (iid techniques), else NaN
    sample_kurtosis: float
    iid: bool
    evaluations: int          # f evaluations per contribution
    finite_variance: bool | None = None   # known analytically (the catalogue's); None: unknown
    clock: np.ndarray | None = None       # (R,) reference-clock time beside each replica, or None

    @classmethod
    def from_estimates(cls, est: Estimator, n: int, ests: Sequence[rest.Estimate], *,
                       clock: Sequence[float] | None = None) -> Replicates:
        """Replicates from independent estimates of one case (any :class:`Estimator`) at budget n;
        ``clock``: the reference clock's time beside each of them (s), if it was timed."""
        bad = summed_counts(e.issues for e in ests)
        if bad:
            first = next(e for e in ests if e.issues)
            raise ValueError(f"{est.integrand}/{est.technique}: contributions with faults {bad}; "
                             f"first: {first.examples[:3]}")
        # pooled per-sample variance over all replicas (Chan's merge); kurtosis as the replicas' mean
        tot, _, m2 = chan_merge((e.n, e.mean, e.variance) for e in ests)
        var = m2 / (tot - 1)
        kurt = float(np.mean([e.kurtosis for e in ests]))
        return cls(est.integrand, est.technique, int(n), est.reference, np.array([e.mean for e in ests]),
                   np.array([e.seconds for e in ests]), var if est.iid else math.nan, kurt, est.iid,
                   est.evaluations, est.finite_variance,
                   None if clock is None else np.asarray(clock, dtype=np.float64))

    @property
    def replicas(self) -> int:
        return self.estimates.size

    @property
    def _scale(self) -> float:
        """A power of two that brings the estimates near 1 (exact), so that squared errors of
        estimates near 1e+-300 neither overflow nor underflow."""
        big = max(abs(self.reference), float(np.max(np.abs(self.estimates))))
        return math.ldexp(1.0, -math.frexp(big)[1]) if big > 0 else 1.0

    @property
    def scaled_errors(self) -> np.ndarray:
        """(estimates - reference) times ``_scale``."""
        sc = self._scale
        return self.estimates * sc - self.reference * sc

    @property
    def mean(self) -> float:
        return float(np.mean(self.estimates))

    @property
    def bias(self) -> tuple[float, float]:
        """Mean error against the reference and its standard error over replicas."""
        e, sc = self.scaled_errors, self._scale
        return float(np.mean(e)) / sc, float(np.std(e, ddof=1) / math.sqrt(self.replicas)) / sc

    @property
    def rmse(self) -> float:
        return float(math.sqrt(np.mean(self.scaled_errors ** 2))) / self._scale

    def rmse_interval(self, confidence_level: float = 0.95) -> ConfidenceInterval:
        """Interval for the RMSE from the chi-square law of R squared normal errors (exact
        for normal, unbiased estimates; the bootstrap in ``convergence_rate`` does not need that)."""
        check_confidence_level(confidence_level)
        r = self.replicas
        a = 1 - confidence_level
        ss = float(np.sum(self.scaled_errors ** 2))
        sc = self._scale
        return ConfidenceInterval(math.sqrt(ss / distributions.chi2_ppf(1 - a / 2, r)) / sc,
                                  math.sqrt(ss / distributions.chi2_ppf(a / 2, r)) / sc)

    @property
    def log10_estimator_variance(self) -> tuple[float, float]:
        """log10 V[F] of one estimate, and the relative standard error of V[F]: from the
        pooled per-sample variance (iid: V = sigma^2 / n, relative error
        sqrt((kurtosis - 1) / (R n))) or from the replicas' spread (relative error
        sqrt(2 / (R - 1)), normal estimates).  In log10 so that 1e+-600 survives."""
        sc = self._scale
        if self.iid and math.isfinite(self.sample_variance):
            v = self.sample_variance  # already pooled; may overflow for huge contributions
            if math.isfinite(v) and v > 0:
                rel = math.sqrt(max(self.sample_kurtosis - 1, 0.0) / (self.replicas * self.n))
                return math.log10(v) - math.log10(self.n), rel
        vs = float(np.var(self.estimates * sc, ddof=1))
        lv = math.log10(vs) - 2 * math.log10(sc) if vs > 0 else -math.inf
        return lv, math.sqrt(2 / (self.replicas - 1))

    @property
    def time(self) -> tuple[float, float]:
        """Wall time of one estimate (s) and its standard error: :func:`median_time`."""
        return median_time(self.seconds)

    @property
    def clock_time(self) -> tuple[float, float]:
        """Time of one estimate in reference-clock units and its standard error
        (:func:`~harness.stats.timing.clock_time`); NaN if the clock was not timed."""
        if self.clock is None:
            return math.nan, math.nan
        return clock_time(self.seconds, self.clock)


def replicate(integrand: Any, technique: Any = None, n: int | None = None, replicas: int | None = None, *,
              dim: int | None = None, reference: float | None = None, seed: int = 0, case_id: int = 0,
              threads: int | None = None, clock: bool = False) -> Replicates:
    """``replicas`` independent estimates with n contributions each (replica r uses the
    streams of (seed, case_id, r, chunk): independent randomisations of any point set);
    ``clock``: time the reference clock before each replica, for ``efficiency(..., clock=True)``.

    The estimator is a catalogue integrand with its technique, or a contributions callable
    u (N, dim) -> Y (N,) with ``dim`` and the exact ``reference`` (harness.stats.estimator):
    ``replicate(my_estimator, n=4096, replicas=32, dim=2, reference=0.349)``."""
    est = estimator(integrand, technique, dim=dim, reference=reference)
    if n is None or replicas is None:
        raise TypeError("replicate needs n (contributions per estimate) and replicas")
    n = count(n, "n")
    r = count(replicas, "replicas")
    if r < 2:
        raise ValueError(f"'replicas' must be >= 2 to measure a spread, got {replicas}")
    ests, ticks = [], []
    for k in range(r):
        if clock:
            ticks.append(reference_clock())
        ests.append(est.estimate(n, seed=seed, case_id=case_id, replica=k, threads=threads))
    return Replicates.from_estimates(est, n, ests, clock=ticks if clock else None)


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


def _judgeable(est: Estimator) -> Estimator:
    """An estimator whose errors can be measured: it has an exact reference."""
    if not math.isfinite(est.reference):
        raise ValueError(f"{est.integrand}: errors need the exact value: give reference=")
    return est


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
    est = _judgeable(estimator(integrand, technique, dim=dim, reference=reference))
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


# --- error against time ----------------------------------------------------------------------
def error_vs_time(integrand: Any, techniques: Sequence[Any], budgets: Sequence[int], replicas: int = 16, *,
                  dim: int | None = None, reference: float | None = None, seed: int = 0,
                  threads: int | None = None, confidence_level: float = 0.95) -> pd.DataFrame:
    """RMSE against the exact reference and mean wall time, per technique and budget.

    ``techniques`` are catalogue techniques of ``integrand``; or, with ``integrand`` None,
    contributions callables (or :class:`~harness.stats.estimator.Contributions`) of one
    integral, with ``dim`` and ``reference`` for the bare callables.  Columns: technique, n,
    rmse, rmse_lo, rmse_hi (chi-square interval), seconds (median per estimate), seconds_se,
    replicas.  Plot rmse against seconds on log-log axes to see which technique reaches a
    given error first.
    """
    rows = []
    if integrand is None:
        ests = [t if isinstance(t, Contributions) else estimator(t, dim=dim, reference=reference)
                for t in techniques]
    else:
        f = rest.integrand(integrand)
        ests = [estimator(f, t) for t in techniques]
    for i, est in enumerate(ests):
        _judgeable(est)
        for j, n in enumerate(budgets):
            r = replicate(est, n=n, replicas=replicas, seed=seed, case_id=1000 * i + j, threads=threads)
            lo, hi = r.rmse_interval(confidence_level)
            secs, secs_se = r.time
            rows.append({"technique": r.technique, "n": r.n, "rmse": r.rmse, "rmse_lo": lo, "rmse_hi": hi,
                         "seconds": secs, "seconds_se": secs_se, "replicas": r.replicas})
    import pandas as pd  # deferred, as in harness.suite.kind.Outcome.frame
    return pd.DataFrame(rows)
