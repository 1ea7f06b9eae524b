"""Replicas and what they measure: R independent estimates of one case at one budget
(:class:`Replicates`) and error against run time; the convergence rate of the RMSE over budgets
is :mod:`harness.stats.convergence`, the efficiency 1/(V T) of replicates
:mod:`harness.stats.efficiency`.

Every figure comes with its uncertainty and the number of estimates it came from.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

import reference_estimators as rest

from harness.stats import distributions
from harness.stats.estimator import Contributions, Estimator, estimator
from harness.stats.merge import chan_merge
from harness.stats.results import ConfidenceInterval, check_confidence_level, summed_counts
from harness.stats.timing import clock_time, median_time, reference_clock
from harness.stats.validate import count, sizes

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["Replicates", "replicate", "error_vs_time"]


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
        for normal, unbiased estimates; the slope test of ``convergence_rate`` does not need that)."""
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


def judgeable(est: Estimator) -> Estimator:
    """An estimator whose errors can be measured: it has an exact reference."""
    if not math.isfinite(est.reference):
        raise ValueError(f"{est.integrand}: errors need the exact value: give reference=")
    return est


# --- error against time ----------------------------------------------------------------------
def error_vs_time(integrand: Any, techniques: Sequence[Any], budgets: Sequence[int], replicas: int = 16, *,
                  dim: int | None = None, reference: float | None = None, seed: int = 0,
                  threads: int | None = None, confidence_level: float = 0.95) -> pd.DataFrame:
    """RMSE against the exact reference and mean wall time, per technique and budget.

    ``techniques`` are catalogue techniques of ``integrand``; or, with ``integrand`` None,
    contributions callables (or :class:`~harness.stats.estimator.Contributions`) of one
    integral, with ``dim`` and ``reference`` for the bare callables.  Columns: technique, n,
    rmse, rmse_lo, rmse_hi (chi-square interval), seconds (median per estimate), seconds_se,
    replicas; per technique a row per distinct budget, smallest first.  Plot rmse against
    seconds on log-log axes to see which technique reaches a given error first.
    """
    budgets = sizes(budgets, "budgets", 1)
    techniques = list(techniques)
    if not techniques:
        raise ValueError("'techniques' must name at least one technique, got none")
    rows = []
    if integrand is None:
        ests = [t if isinstance(t, Contributions) else estimator(t, dim=dim, reference=reference)
                for t in techniques]
    else:
        f = rest.integrand(integrand)
        ests = [estimator(f, t) for t in techniques]
    for i, est in enumerate(ests):
        judgeable(est)
        for j, n in enumerate(budgets):
            r = replicate(est, n=n, replicas=replicas, seed=seed, case_id=1000 * i + j, threads=threads)
            lo, hi = r.rmse_interval(confidence_level)
            secs, secs_se = r.time
            rows.append({"technique": r.technique, "n": r.n, "rmse": r.rmse, "rmse_lo": lo, "rmse_hi": hi,
                         "seconds": secs, "seconds_se": secs_se, "replicas": r.replicas})
    import pandas as pd  # deferred, as in harness.suite.kind.Outcome.frame
    return pd.DataFrame(rows)
