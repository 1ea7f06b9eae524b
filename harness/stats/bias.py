"""Measurements: is an estimator unbiased, how fast does it converge, how efficient is it.

Every figure comes with its uncertainty and the sample count it came from; every test states
its false-alarm rate and what it can detect.  Random numbers come from the core's chunked
PCG32 streams, so every result here is reproducible from its seed.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

import reference_estimators as rest

__all__ = [
    "UnbiasedResult", "check_unbiased", "check_technique", "judge_batches", "TailSample", "holm",
    "Replicates", "replicate", "ConvergenceResult", "convergence_rate", "fit_convergence",
    "Efficiency", "efficiency", "efficiency_ratio", "error_vs_time",
]

_EPS = 2.0**-52
_PIECE = 1 << 20              # rows of uniforms handed to a contributions callable at once
_UNBIASED_STREAM = 0xC4EC     # case_id of check_unbiased's streams (pieces add to it)


# --- is it unbiased? -------------------------------------------------------------------------
@dataclass(frozen=True)
class UnbiasedResult:
    """Outcome of :func:`check_unbiased`.  Unpacks like ``(statistic, pvalue)``.

    ``verdict`` is "consistent" (no evidence of bias), "biased" (``rejected``: bias found at
    level ``alpha``) or "inconclusive" (the data would have rejected, but the variance is
    infinite or unreliable or the batch means are far from normal, so no level can be
    claimed).  "invalid" means the contributions contained NaN or infinities (``counts``).
    """

    verdict: str
    statistic: float          # Student t of the batch means against the reference
    pvalue: float
    df: int
    estimate: float           # mean of all contributions
    stderr: float             # from the spread of the batch means
    reference: float
    n: int
    alpha: float
    batches: int
    variance: float           # per-contribution sample variance
    tail_index: float         # of the heavier side of Y; < 3: variance unreliable or infinite
    batch_skewness: float
    flags: tuple[str, ...]    # why the variance or the normal approximation is not trusted
    heavy_tail: bool = False  # tail index < 3: no level can be claimed, a small p is "inconclusive"
    counts: dict[str, int] = field(default_factory=dict)
    examples: tuple[dict[str, Any], ...] = ()

    @property
    def rejected(self) -> bool:
        return self.verdict == "biased"

    @property
    def variance_unreliable(self) -> bool:
        """The variance looks infinite or cannot be estimated from this sample."""
        return self.heavy_tail

    @property
    def bias(self) -> float:
        return self.estimate - self.reference

    def confidence_interval(self, confidence_level: float = 0.95) -> tuple[float, float]:
        """Student-t interval for E[Y] from the batch means (meaningless when flagged)."""
        if not 0 < confidence_level < 1:
            raise ValueError(f"confidence_level must be in (0, 1), got {confidence_level}")
        half = stats.t.ppf(0.5 + confidence_level / 2, self.df) * self.stderr
        return (self.estimate - half, self.estimate + half)

    def __iter__(self):
        return iter((self.statistic, self.pvalue))

    def __str__(self) -> str:
        lo, hi = self.confidence_interval(1 - self.alpha)
        s = (f"{self.verdict}: estimate {self.estimate:.10g} ± {self.stderr:.3g} (n = {self.n}), "
             f"reference {self.reference:.10g}, t = {self.statistic:+.2f}, p = {self.pvalue:.3g}, alpha = {self.alpha}, "
             f"{100 * (1 - self.alpha):g} % CI [{lo:.10g}, {hi:.10g}]")
        if self.flags:
            s += "; " + "; ".join(self.flags)
        if self.counts:
            s += f"; {self.counts}"
        return s


def check_unbiased(contributions: Callable[[np.ndarray], np.ndarray], dim: int, reference: float, *,
                   sample_count: int, seed: int = 0, alpha: float = 0.01, batches: int = 64) -> UnbiasedResult:
    """Test H0: E[Y] = reference for a user's estimator.

    ``contributions`` maps canonical uniforms of shape (N, dim) in (0, 1) to per-sample
    estimates Y of shape (N,); it is called on blocks of at most 2^20 rows.  The
    ``sample_count`` contributions are split into ``batches`` batches, each from its own
    PCG32 stream, and H0 is tested by Student's t on the batch means (``batches - 1``
    degrees of freedom): near-normal even for skewed contributions, since each batch mean
    averages ``sample_count / batches`` of them.

    False alarms.  "biased" is said only when p < alpha *and* the data support the normal
    approximation: the contributions' tail index, estimated on both sides from the largest
    sqrt(n) deviations from the median (moment estimator of Dekkers, Einmahl & de Haan), is >= 3, and the batch means' skewness is below 1 in
    magnitude.  Otherwise a small p gives "inconclusive".  So on unbiased estimators with
    heavy tails or infinite variance (1/(2 sqrt x) under uniform sampling: tail index 2;
    Pareto tails of index 3/2) the test says "inconclusive", never "biased" more often than
    alpha; tests/test_stats.py measures this over 200 seeds per estimator.

    Power.  With 64 batches and alpha = 0.01, a bias of 3.5 sigma / sqrt(n) (sigma the
    standard deviation of one contribution) is detected 80 % of the time: with n = 1e6 and
    sigma = 1, a bias of 0.0035.  Heavy-tailed biased estimators get "inconclusive".
    """
    n = _count(sample_count, "sample_count")
    if not (isinstance(dim, (int, np.integer)) and dim >= 1):
        raise ValueError(f"'dim' must be a positive integer, got {dim!r}")
    if not (0 < alpha < 1):
        raise ValueError(f"'alpha' must be in (0, 1), got {alpha!r}")
    if not (isinstance(batches, (int, np.integer)) and 8 <= batches <= n):
        raise ValueError(f"'batches' must be an integer in [8, sample_count], got {batches!r}")
    if not math.isfinite(reference):
        raise ValueError(f"'reference' must be finite, got {reference!r}")

    sizes = np.full(batches, n // batches)
    sizes[: n % batches] += 1
    parts: list[list[tuple[int, float, float]]] = []
    counts: dict[str, int] = {}
    examples: list[dict[str, Any]] = []
    tails = TailSample.for_count(n)
    max_abs = 0.0
    for k, size in enumerate(sizes):
        sums = []
        for piece, start in enumerate(range(0, size, _PIECE)):
            rows = min(_PIECE, size - start)
            u = rest.points(rows, dim, seed=seed, case_id=_UNBIASED_STREAM + piece, replica=k)
            y = np.asarray(contributions(u), dtype=np.float64)
            if y.shape != (rows,):
                raise ValueError(f"'contributions' must return shape ({rows},) for uniforms of shape "
                                 f"({rows}, {dim}), returned {y.shape}")
            est = rest.accumulate(y)
            for key, v in est.issues.items():
                counts[key] = counts.get(key, 0) + v
            for ex in est.examples:
                if len(examples) < 8:
                    examples.append({**ex, "index": int(ex["index"]) + int(sizes[:k].sum()) + start})
            finite = y[np.isfinite(y)]
            if finite.size == 0:
                continue
            tails.add(finite)
            max_abs = max(max_abs, float(np.max(np.abs(finite))))
            sums.append((est.n, est.mean, est.stderr))
        # the batch's pieces as (n, mean, stderr): _decide merges them (Chan) in scaled units,
        # where the standard error stays finite for contributions near 1e+-300
        parts.append(sums)
    if counts:
        return UnbiasedResult("invalid", math.nan, math.nan, batches - 1, math.nan, math.nan, reference, n, alpha,
                              batches, math.nan, math.nan, math.nan,
                              flags=("contributions contained NaN or infinite values",), counts=counts,
                              examples=tuple(examples))

    return _decide(parts, tails, max_abs, reference, alpha)


class TailSample:
    """The largest deviations above and below a centre (the first values' median), kept
    across calls, for the tail estimates."""

    def __init__(self, keep: int):
        self.keep, self.center = keep, None
        self.upper, self.lower = np.empty(0), np.empty(0)

    @classmethod
    def for_count(cls, n: int) -> "TailSample":
        """Keeps sqrt(n) order statistics per side (at least 50, at most 20 000)."""
        return cls(min(max(int(math.sqrt(n)), 50), 20_000))

    def add(self, y: np.ndarray) -> None:
        if self.center is None:
            self.center = float(np.median(y))
        self.upper = self._top(np.concatenate([self.upper, self._top(y - self.center)]))
        self.lower = self._top(np.concatenate([self.lower, self._top(self.center - y)]))

    def _top(self, d: np.ndarray) -> np.ndarray:
        d = d[d > 0]
        m = min(self.keep + 1, d.size)
        return np.partition(d, d.size - m)[d.size - m:] if m else d

    @classmethod
    def from_tops(cls, upper: Sequence[float], lower: Sequence[float]) -> "TailSample":
        """A tail sample from stored largest deviations (see harness.suite.execute)."""
        t = cls(max(len(upper), len(lower)))
        t.upper, t.lower = np.asarray(upper, dtype=float), np.asarray(lower, dtype=float)
        return t

    def tail_index(self) -> float:
        """The smaller tail index of the two sides (inf for bounded or light tails)."""
        return min(_tail_index(np.sort(self.upper)[::-1]), _tail_index(np.sort(self.lower)[::-1]))


def _tail_index(desc: np.ndarray) -> float:
    """1 / gamma from the moment estimator of the extreme-value index gamma (Dekkers, Einmahl
    & de Haan 1989) on descending order statistics: valid for heavy (gamma > 0), light
    (gamma = 0) and bounded (gamma < 0) tails alike, unlike Hill's.  inf when gamma <= 0."""
    desc = desc[desc > 0]
    if desc.size < 21:
        return math.inf
    k = desc.size - 1
    logs = np.log(desc[:k]) - math.log(desc[k])
    m1, m2 = float(np.mean(logs)), float(np.mean(logs * logs))
    if m2 <= 0:
        return math.inf
    gamma = m1 + 1 - 0.5 / (1 - m1 * m1 / m2)
    return 1 / gamma if gamma > 0 else math.inf


def _decide(parts: list[list[tuple[int, float, float]]], tails: TailSample, max_abs: float, reference: float,
            alpha: float) -> UnbiasedResult:
    """The verdict from batches, each a list of (n, mean, stderr) pieces, and the tails, as
    documented in check_unbiased.  Works in units of 2^e ~ max |Y|, so that contributions
    near 1e+-300 square without over- or underflow (the scaling is exact)."""
    e = math.frexp(max_abs)[1] if max_abs > 0 else 0
    sc = math.ldexp(1.0, -e)
    ref = reference * sc
    means, sizes, m2 = [], [], []
    for pieces in parts:
        nk, mk, s2 = 0, 0.0, 0.0
        for ni, mi, se in pieces:
            mi, vi = mi * sc, (se * sc) ** 2 * ni if ni > 1 else 0.0
            delta = mi - mk
            tot = nk + ni
            s2 += vi * (ni - 1) + delta * delta * nk * ni / tot
            mk += delta * ni / tot
            nk = tot
        means.append(mk)
        sizes.append(nk)
        m2.append(s2)
    means_a, sizes_a = np.array(means), np.array(sizes)
    batches = means_a.size
    total = int(sizes_a.sum())
    estimate = float(np.sum(sizes_a * means_a) / total)
    variance = (float(np.sum(m2)) + float(np.sum(sizes_a * (means_a - estimate) ** 2))) / (total - 1)
    spread = float(np.std(means_a, ddof=1))
    stderr = spread / math.sqrt(batches)
    flags: list[str] = []
    tail = tails.tail_index()
    heavy = tail < 3
    if heavy:
        flags.append(f"heavy tail: tail index {tail:.2f} < 3 (variance infinite or unreliable)")
    skew = float(stats.skew(means_a)) if spread > 0 else 0.0
    skewed = abs(skew) > 1
    if skewed:
        flags.append(f"batch means skewed ({skew:+.2f})" + ("" if heavy else ": Chebyshev p-value instead of Student's t"))
    rounding = 16 * _EPS * max_abs * sc
    if spread == 0 or stderr <= rounding:
        # (near) zero variance: the estimate is exact up to rounding, or it is wrong
        t = 0.0 if abs(estimate - ref) <= rounding else math.copysign(math.inf, estimate - ref)
        p = 1.0 if t == 0 else 0.0
    else:
        t = (estimate - ref) / stderr
        # Skewed batch means with a finite variance: Chebyshev, P(|t| >= k) <= 1/k^2, needs
        # no normality; the factor 4 allows the standard error to be underestimated by 2x.
        p = min(1.0, 4 / (t * t)) if skewed and not heavy else float(2 * stats.t.sf(abs(t), batches - 1))
    verdict = "consistent" if p >= alpha else ("inconclusive" if heavy else "biased")
    unscale = math.ldexp(1.0, e)
    return UnbiasedResult(verdict, t, p, batches - 1, estimate * unscale, stderr * unscale, reference, total, alpha,
                          batches, variance * unscale * unscale, tail, skew, tuple(flags), heavy)


def check_technique(integrand: str | rest.Integrand, technique: str | rest.Technique, sample_count: int, *,
                    seed: int = 0, case_id: int = 0, alpha: float = 0.01, batches: int = 64,
                    threads: int | None = None) -> UnbiasedResult:
    """check_unbiased for a technique of the core, run in C++: the batches are independent
    replicas of ``sample_count / batches`` contributions each, so stratified and Sobol'
    estimators are tested correctly too (their replicas, not their samples, are independent).
    Same verdicts, false-alarm rate and power as check_unbiased; the tail index is estimated
    from the contributions of the first replica."""
    f = rest.integrand(integrand)
    t = rest.technique(f, technique)
    n = _count(sample_count, "sample_count")
    if not (isinstance(batches, (int, np.integer)) and 8 <= batches <= n):
        raise ValueError(f"'batches' must be an integer in [8, sample_count], got {batches!r}")
    size = n // batches
    ests = [rest.integrate(f, t, size, seed=seed, case_id=case_id, replica=k, threads=threads) for k in range(batches)]
    counts: dict[str, int] = {}
    for e in ests:
        for key, v in e.issues.items():
            counts[key] = counts.get(key, 0) + v
    if counts:
        first = next(e for e in ests if e.issues)
        return UnbiasedResult("invalid", math.nan, math.nan, batches - 1, math.nan, math.nan, f.reference, n, alpha,
                              batches, math.nan, math.nan, math.nan, flags=("contributions with faults",),
                              counts=counts, examples=first.examples)
    tails = TailSample.for_count(size)
    tails.add(rest.contributions(f, t, size, seed=seed, case_id=case_id, replica=0, threads=threads))
    return judge_batches(ests, tails, f.reference, alpha, iid=t.iid)


def judge_batches(estimates: Sequence[rest.Estimate], tails: TailSample, reference: float, alpha: float, *,
                  iid: bool) -> UnbiasedResult:
    """The verdict of check_technique from independent batch estimates (replicas) and the
    tail sample of their contributions; for non-iid point sets only the batch means count."""
    max_abs = max(max(abs(e.min), abs(e.max)) for e in estimates)
    return _decide([[(e.n, e.mean, e.stderr if iid else 0.0)] for e in estimates], tails, max_abs, reference, alpha)


# --- multiple testing ----------------------------------------------------------------------
def holm(pvalues: Sequence[float], alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """Holm-Bonferroni step-down: which hypotheses to reject at family-wise level alpha,
    and the adjusted p-values (reject where adjusted <= alpha).  Holds the family-wise
    error rate for any dependence between the tests (Holm 1979).  Written out because
    scipy offers only false-discovery-rate control (false_discovery_control)."""
    p = np.asarray(pvalues, dtype=float)
    if p.ndim != 1 or np.any(~((p >= 0) & (p <= 1))):
        raise ValueError(f"'pvalues' must be a 1-D sequence of values in [0, 1], got {pvalues!r}")
    if not (0 < alpha < 1):
        raise ValueError(f"'alpha' must be in (0, 1), got {alpha!r}")
    m = p.size
    order = np.argsort(p, kind="stable")
    adjusted_sorted = np.maximum.accumulate(np.minimum((m - np.arange(m)) * p[order], 1.0))
    adjusted = np.empty(m)
    adjusted[order] = adjusted_sorted
    return adjusted <= alpha, adjusted


# --- replicas ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Replicates:
    """R independent estimates of one case at one budget, with their wall times.

    Their spread measures the error of any technique, stratified and Sobol' included;
    for independent samples the pooled per-sample variance (``sample_variance``, from all
    R * n contributions) measures it more precisely.
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

    @classmethod
    def from_estimates(cls, f: rest.Integrand, t: rest.Technique, n: int,
                       ests: Sequence[rest.Estimate]) -> "Replicates":
        """Replicates from independent estimates of one case at budget n."""
        bad = {k: v for e in ests for k, v in e.issues.items()}
        if bad:
            raise ValueError(f"{f.name}/{t.name}: contributions with faults {bad}; first: {ests[0].examples[:3]}")
        # pooled per-sample variance over all replicas (Chan's merge); kurtosis as the replicas' mean
        tot, mean, m2 = 0, 0.0, 0.0
        for e in ests:
            delta = e.mean - mean
            new = tot + e.n
            m2 += e.variance * (e.n - 1) + delta * delta * tot * e.n / new
            mean += delta * e.n / new
            tot = new
        var = m2 / (tot - 1)
        kurt = float(np.mean([e.kurtosis for e in ests]))
        return cls(f.name, t.name, int(n), f.reference, np.array([e.mean for e in ests]),
                   np.array([e.seconds for e in ests]), var if t.iid else math.nan, kurt, t.iid, t.evaluations)

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

    def rmse_interval(self, confidence_level: float = 0.95) -> tuple[float, float]:
        """Interval for the RMSE from the chi-square law of R squared normal errors (exact
        for normal, unbiased estimates; the bootstrap in ``convergence_rate`` does not need that)."""
        r = self.replicas
        a = 1 - confidence_level
        ss = float(np.sum(self.scaled_errors ** 2))
        sc = self._scale
        return math.sqrt(ss / stats.chi2.ppf(1 - a / 2, r)) / sc, math.sqrt(ss / stats.chi2.ppf(a / 2, r)) / sc

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
        """Wall time of one estimate (s): the median over replicas and its standard error
        (1.2533 x 1.4826 MAD / sqrt(R)).  The median, because a replica that shared its core
        with something else is an outlier of the machine, not of the technique."""
        med = float(np.median(self.seconds))
        mad = float(np.median(np.abs(self.seconds - med)))
        return med, 1.2533 * 1.4826 * mad / math.sqrt(self.replicas)


def replicate(integrand: str | rest.Integrand, technique: str | rest.Technique, n: int, replicas: int, *,
              seed: int = 0, case_id: int = 0, threads: int | None = None) -> Replicates:
    """``replicas`` independent estimates with n contributions each (replica r uses the
    streams of (seed, case_id, r, chunk): independent randomisations of any point set)."""
    f = rest.integrand(integrand)
    t = rest.technique(f, technique)
    r = _count(replicas, "replicas")
    if r < 2:
        raise ValueError(f"'replicas' must be >= 2 to measure a spread, got {replicas}")
    ests = [rest.integrate(f, t, n, seed=seed, case_id=case_id, replica=k, threads=threads) for k in range(r)]
    return Replicates.from_estimates(f, t, n, ests)


# --- convergence rate ------------------------------------------------------------------------
@dataclass(frozen=True)
class ConvergenceResult:
    """RMSE against the exact reference at geometric budgets, and the fitted log-log slope.

    ``worse_than_expected`` is True when the whole ``confidence_level`` interval of the slope
    lies above ``expected`` + ``tolerance``: the error falls measurably slower than it should.
    """

    integrand: str
    technique: str
    table: pd.DataFrame       # n, rmse, rmse_lo, rmse_hi, seconds, replicas
    slope: float
    slope_interval: tuple[float, float]
    confidence_level: float
    expected: float
    tolerance: float
    slope_se: float = math.nan  # standard deviation of the bootstrap slopes

    @property
    def worse_than_expected(self) -> bool:
        return self.slope_interval[0] > self.expected + self.tolerance

    @property
    def pvalue(self) -> float:
        """One-sided p-value of H0 "slope <= expected + tolerance" (normal approximation with
        the bootstrap standard error): small when the error falls measurably too slowly.  For
        many cases at once, correct these with holm()."""
        if not self.slope_se > 0:
            return 1.0 if self.slope <= self.expected + self.tolerance else 0.0
        return float(stats.norm.sf((self.slope - self.expected - self.tolerance) / self.slope_se))

    def __str__(self) -> str:
        lo, hi = self.slope_interval
        s = (f"{self.integrand}/{self.technique}: RMSE ~ n^{self.slope:+.3f} "
             f"({100 * self.confidence_level:g} % CI [{lo:+.3f}, {hi:+.3f}], expected {self.expected:+.2f})")
        return s + (" -- WORSE THAN EXPECTED" if self.worse_than_expected else "")


def convergence_rate(integrand: str | rest.Integrand, technique: str | rest.Technique, budgets: Sequence[int],
                     replicas: int = 32, *, seed: int = 0, case_id: int = 0, expected: float = -0.5,
                     tolerance: float = 0.05, confidence_level: float = 0.95, bootstrap: int = 400,
                     threads: int | None = None) -> ConvergenceResult:
    """Fit log RMSE = a + slope log n by least squares over ``budgets`` (replicas each).

    The slope's interval comes from a bootstrap over replicas within each budget (percentile,
    ``bootstrap`` resamples from a generator seeded by ``seed``), so it needs no normality.
    Budgets should span at least a factor 16.  Zero-variance estimators give RMSE at the
    rounding level and a slope near 0; compare with ``expected`` accordingly.
    """
    b = sorted({_count(x, "budgets") for x in budgets})
    if len(b) < 3:
        raise ValueError(f"'budgets' needs at least 3 distinct sizes, got {list(budgets)!r}")
    reps = [replicate(integrand, technique, n, replicas, seed=seed, case_id=case_id + 7919 * i, threads=threads)
            for i, n in enumerate(b)]
    return fit_convergence(reps, expected=expected, tolerance=tolerance, confidence_level=confidence_level,
                           bootstrap=bootstrap, seed=seed)


def fit_convergence(reps: Sequence[Replicates], *, expected: float = -0.5, tolerance: float = 0.05,
                    confidence_level: float = 0.95, bootstrap: int = 400, seed: int = 0) -> ConvergenceResult:
    """The slope fit of convergence_rate, from replicates at increasing budgets."""
    sc = min(r._scale for r in reps)  # one power-of-two scale for all budgets: the slope does not change
    errors = [r.estimates * sc - r.reference * sc for r in reps]
    x = np.log([r.n for r in reps])
    x = x - x.mean()
    floor = np.finfo(float).tiny

    def slopes(sq: np.ndarray) -> np.ndarray:
        """Least-squares slopes of log RMSE on log n, one per row of mean squared errors."""
        y = 0.5 * np.log(np.maximum(sq, floor * floor))
        return (y - y.mean(axis=-1, keepdims=True)) @ x / (x @ x)

    slope = float(slopes(np.array([np.mean(e * e) for e in errors])))
    rng = np.random.default_rng(seed)
    # all bootstrap resamples at once: (bootstrap, budgets) mean squared errors
    boot_sq = np.stack([np.mean(e[rng.integers(0, e.size, (bootstrap, e.size))] ** 2, axis=1) for e in errors], axis=1)
    boot = slopes(boot_sq)
    a = 1 - confidence_level
    interval = (float(np.quantile(boot, a / 2)), float(np.quantile(boot, 1 - a / 2)))
    rows = []
    for r in reps:
        lo, hi = r.rmse_interval(confidence_level)
        rows.append({"n": r.n, "rmse": r.rmse, "rmse_lo": lo, "rmse_hi": hi, "seconds": r.time[0],
                     "replicas": r.replicas})
    return ConvergenceResult(reps[0].integrand, reps[0].technique, pd.DataFrame(rows), slope, interval,
                             confidence_level, expected, tolerance, float(np.std(boot, ddof=1)))


# --- efficiency ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Efficiency:
    """1 / (V[F] T[F]) (background eq. 5) of one estimate F, with a confidence interval.

    V from :attr:`Replicates.log10_estimator_variance`, T the median wall time of one estimate;
    their relative errors are combined on the log scale (independent, delta method).  Kept
    as log10, since 1/(V T) of an integrand near 1e300 is about 1e-590.  For techniques
    converging faster than n^-1/2 the efficiency grows with n: it belongs to budget ``n``.
    """

    technique: str
    log10_value: float
    log_se: float             # standard error of the natural log of the value
    n: int
    replicas: int
    log10_variance: float
    seconds: float

    @property
    def value(self) -> float:
        le = self.log10_value
        return math.inf if le > 308 else (0.0 if le < -323 else 10.0**le)

    def confidence_interval(self, confidence_level: float = 0.95) -> tuple[float, float]:
        z = stats.norm.ppf(0.5 + confidence_level / 2)
        return self.value * math.exp(-z * self.log_se), self.value * math.exp(z * self.log_se)


def efficiency(r: Replicates) -> Efficiency:
    lv, v_rel = r.log10_estimator_variance
    t, t_se = r.time
    if not (t > 0) or lv == -math.inf:
        return Efficiency(r.technique, math.inf if lv == -math.inf else math.nan, math.nan, r.n, r.replicas, lv, t)
    return Efficiency(r.technique, -lv - math.log10(t), math.hypot(v_rel, t_se / t), r.n, r.replicas, lv, t)


def efficiency_ratio(a: Efficiency, b: Efficiency, confidence_level: float = 0.95) -> tuple[float, tuple[float, float]]:
    """eff(a) / eff(b) with its interval (independent measurements, log-scale delta method)."""
    if not (math.isfinite(a.log10_value) and math.isfinite(b.log10_value)):
        return math.nan, (math.nan, math.nan)
    ratio = 10.0 ** (a.log10_value - b.log10_value)
    se = math.hypot(a.log_se, b.log_se)
    z = stats.norm.ppf(0.5 + confidence_level / 2)
    return ratio, (ratio * math.exp(-z * se), ratio * math.exp(z * se))


# --- error against time ----------------------------------------------------------------------
def error_vs_time(integrand: str | rest.Integrand, techniques: Sequence[str | rest.Technique],
                  budgets: Sequence[int], replicas: int = 16, *, seed: int = 0,
                  threads: int | None = None, confidence_level: float = 0.95) -> pd.DataFrame:
    """RMSE against the exact reference and mean wall time, per technique and budget.

    Columns: technique, n, rmse, rmse_lo, rmse_hi (chi-square interval), seconds (median per
    estimate), seconds_se, replicas.  Plot rmse against seconds on log-log axes to see which technique
    reaches a given error first.
    """
    rows = []
    f = rest.integrand(integrand)
    for i, t in enumerate(techniques):
        for j, n in enumerate(budgets):
            r = replicate(f, t, n, replicas, seed=seed, case_id=1000 * i + j, threads=threads)
            lo, hi = r.rmse_interval(confidence_level)
            secs, secs_se = r.time
            rows.append({"technique": r.technique, "n": r.n, "rmse": r.rmse, "rmse_lo": lo, "rmse_hi": hi,
                         "seconds": secs, "seconds_se": secs_se, "replicas": r.replicas})
    return pd.DataFrame(rows)


def _count(x: Any, name: str) -> int:
    if isinstance(x, bool) or not isinstance(x, (int, np.integer, float)) or x != int(x) or x <= 0:
        raise ValueError(f"'{name}' must be a positive whole number, got {x!r}")
    return int(x)
