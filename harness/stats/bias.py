"""Is an estimator unbiased: H0 E[Y] = I tested by a skewness-corrected Student's t, with a
level that holds for skewed, heavy-tailed, clamped, rare-event and zero-variance contributions
alike (``check_unbiased`` states under which conditions, and says "inconclusive" outside them).

Every figure comes with its uncertainty and the sample count it came from.  Random numbers
come from the core's chunked PCG32 streams, so every result is reproducible from its seed.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

import reference_estimators as rest

from harness.stats import distributions
from harness.stats.merge import merge_moments
from harness.stats.results import ConfidenceInterval, Failure, failures_from_counts, summed_counts, t_interval
from harness.stats.tails import Side, TailEnd, TailSample
from harness.stats.validate import count, finite, integer_in, level
from harness.usercode import array_result, call, callable_name

__all__ = ["UnbiasedResult", "check_unbiased", "check_technique", "judge_batches", "batch_points"]

_EPS = 2.0**-52
_PIECE = 1 << 20              # rows of uniforms handed to a contributions callable at once
_UNBIASED_STREAM = 0xC4EC     # case_id of check_unbiased's streams (pieces add to it)
_MAX_EXAMPLES = 8             # first faulty contributions kept by check_unbiased
_FAULTS_FLAG = "contributions with faults"
_HEAVY_INDEX = 2.0     # tail index below which the variance is infinite: no level without an end
_MAX_SKEW = 0.5        # skewness of the estimate beyond which no normal approximation is claimed
_END_LEVEL = 0.1       # the truncation check runs at this fraction of alpha
_TOWARD_END = 0.8      # share of alpha on the side a clamp or truncation would bias the mean to
# what each of the core's issue counts means (reference_estimators.ERROR_ISSUES, "negative")
ISSUE_DETAIL = {
    "nan": "NaN contributions", "posinf": "+inf contributions", "neginf": "-inf contributions",
    "negative": "negative contributions of a non-negative integrand",
    "outside_domain": "sampled points outside the sampler's own domain",
    "zero_pdf": "sampled points where the claimed pdf is 0",
    "bad_pdf": "pdf values NaN, infinite or negative",
    "bound_violation": "rejection bound violated: f(x) > c p(x)",
}


@dataclass(frozen=True)
class UnbiasedResult:
    """Outcome of :func:`check_unbiased` (and of :func:`check_technique`), a member of the
    result family (:mod:`harness.stats.results`).  Unpacks like ``(statistic, pvalue)``.

    ``verdict`` is "consistent" (no evidence of bias at level ``alpha``), "biased" (bias found
    at level ``alpha``; ``tail_end`` says how a clamp or truncation explains it), "inconclusive"
    (the data would have rejected, but the variance is infinite, or a few contributions
    dominate the estimate: ``no_level``, so no level can be claimed) or "invalid" (the
    contributions contained NaN, infinities or other faults: ``failures`` says which, with
    counts and first examples; nothing else was computed).  ``passed`` is True for
    "consistent" and "inconclusive": a CI run does not fail on them.  When every contribution
    is equal and differs from the reference (zero hits of a rare event), the verdict is
    "inconclusive" with no statistic (``undecided``; t NaN, p 1) and the rule-of-three bound
    in ``flags``: an unseen spread is no evidence of bias.
    """

    verdict: str
    statistic: float          # Student t of the estimate against the reference (before Hall's correction)
    pvalue: float             # skewness-corrected, see check_unbiased
    df: int                   # n - 1 for i.i.d. contributions, batches - 1 for replicas
    estimate: float           # mean of all contributions
    stderr: float             # of all contributions (i.i.d.), else from the spread of the batch means
    reference: float
    n: int
    alpha: float
    batches: int
    variance: float           # per-contribution sample variance
    tail_index: float         # of the heavier side of Y; < 2: variance infinite, < 3: unreliable
    skewness: float           # of the estimate (the mean), which the p-value is corrected for
    flags: tuple[str, ...]    # why the variance or the normal approximation is not trusted
    no_level: bool = False    # a heavy tail that does not end, or skewness beyond 0.5: small p "inconclusive"
    failures: list[Failure] = field(default_factory=list)
    tail_end: str = ""        # how a heavy tail ends ("clamped at 200 ..."), where it explains the bias

    @classmethod
    def invalid(cls, counts: Mapping[str, int], examples: Sequence[Mapping[str, Any]], *, reference: float,
                n: int, alpha: float, batches: int) -> UnbiasedResult:
        """The "invalid" result: faulty contributions, counted by issue (``counts``, the
        core's issue names, see ``ISSUE_DETAIL``) with their first ``examples`` (dicts with
        an ``"issue"`` key); every figure NaN."""
        nan = math.nan
        return cls("invalid", nan, nan, batches - 1, nan, nan, reference, n, alpha, batches, nan, nan, nan,
                   (_FAULTS_FLAG,), failures=failures_from_counts(counts, examples, ISSUE_DETAIL))

    @property
    def passed(self) -> bool:
        return self.verdict in ("consistent", "inconclusive")

    @property
    def undecided(self) -> bool:
        """No test could be made: every contribution was equal, and not to the reference (a rare
        value never drawn, or a wrong constant); ``flags`` gives the rule-of-three bound."""
        return self.verdict == "inconclusive" and math.isnan(self.statistic)

    def with_pvalue(self, pvalue: float) -> UnbiasedResult:
        """The same result judged with another p-value (one corrected for several looks)."""
        verdict = "consistent" if pvalue >= self.alpha else ("inconclusive" if self.no_level else "biased")
        return dataclasses.replace(self, pvalue=pvalue, verdict=verdict)

    def normal_at(self, n: int) -> bool:
        """Whether an estimate of n contributions is close enough to normal for normal theory:
        its skewness, scaled from this one's as 1 / sqrt(n), within +-0.5 (the bias test's
        bound).  False below that: the error at n is pre-asymptotic (rare large values)."""
        return not math.isfinite(self.skewness) or abs(self.skewness) * math.sqrt(self.n / n) <= _MAX_SKEW

    @property
    def bias(self) -> float:
        """estimate - reference."""
        return self.estimate - self.reference

    def confidence_interval(self, confidence_level: float = 0.95) -> ConfidenceInterval:
        """Student-t interval for E[Y] with ``df`` degrees of freedom
        (NaN ends for an "invalid" result; too narrow where ``no_level``)."""
        return t_interval(self.estimate, self.stderr, self.df, confidence_level)

    def __iter__(self):
        return iter((self.statistic, self.pvalue))

    def __str__(self) -> str:
        if self.verdict == "invalid":
            return (f"invalid: {'; '.join(self.flags)} in n = {self.n} (reference {self.reference:.10g}, "
                    f"alpha = {self.alpha}): " + "; ".join(str(f) for f in self.failures))
        lo, hi = self.confidence_interval(1 - self.alpha)
        said = self.verdict + (f", {self.tail_end}" if self.tail_end and self.verdict == "biased" else "")
        s = (f"{said}: estimate {self.estimate:.10g} ± {self.stderr:.3g} (n = {self.n}), "
             f"reference {self.reference:.10g}, t = {self.statistic:+.2f}, p = {self.pvalue:.3g}, "
             f"alpha = {self.alpha}, {100 * (1 - self.alpha):g} % CI [{lo:.10g}, {hi:.10g}]")
        if self.flags:
            s += "; " + "; ".join(self.flags)
        return s


def check_unbiased(contributions: Callable[[np.ndarray], np.ndarray], dim: int, reference: float, *,
                   sample_count: int, seed: int = 0, alpha: float = 0.01,
                   batches: int = 64) -> UnbiasedResult:
    """Test H0: E[Y] = reference for a user's estimator.

    ``contributions`` maps canonical uniforms of shape (N, dim) in (0, 1) to per-sample
    estimates Y of shape (N,); it is called on blocks of at most 2^20 rows (``batch_points``).
    The ``sample_count`` contributions come in ``batches`` batches, each from its own PCG32
    stream.

    The test.  Student's t of the estimate against the reference, with the standard error of
    all n contributions (n - 1 degrees of freedom: the t of ``scipy.stats.ttest_1samp``), made
    robust to skewness by Hall's (1992) cubic transformation, which removes the first-order
    effect of the estimate's skewness (that of all contributions / sqrt(n)) on t.  Rare large
    contributions make a plain t-test reject too often on the low side; the correction holds
    the level for compound-Poisson estimators down to about 20 effective hits.  There is no
    switch between procedures: the p-value is always this one.

    When alpha holds, and when "inconclusive" is said instead.  "biased" needs p < alpha and
    the normal approximation to hold, judged from the shape of the sample, never from t:

    - the estimate's skewness within +-0.5 (else a few contributions dominate it: "estimate
      skewed"); and
    - on each side, a tail index >= 2 (moment estimator of Dekkers, Einmahl & de Haan over the
      largest sqrt(n) deviations from the median), or a tail that is seen to end
      (:meth:`harness.stats.tails.Side.end`): a clamp (an atom at the maximum above continuous
      values) or a truncation (the top spacings compressed against a bound).  A tail that
      ends has a finite variance whatever its index below the end, so a clamp or truncation of
      a heavy tail is proved ("biased, clamped at 25 (400 contributions equal it)").

    Where the upper tail is clamped or truncated, four fifths of alpha go to the lower side,
    the side an end biases the mean to (the end is found from the top order statistics, not
    from the mean, so the split holds alpha).  Under these conditions the test holds alpha;
    where they fail a small p gives "inconclusive" with the reason in ``flags``, so the
    false-alarm rate stays at or below alpha on infinite-variance estimators too.
    ``benchmarks/unbiased_calibration.py`` measures it over 200 seeds per estimator of the
    calibration zoo (Pareto tails of index 1.1 to 2.5, lognormal sigma = 3, 1/(2 sqrt x),
    rare events, clamped and truncated tails by design) at n = 1e5 and 1e6, beside
    scipy.stats.ttest_1samp on the same contributions; tests/stats/test_stats.py checks it.

    Power.  Where the test can claim a level it is the t-test's, or more where a clamp or
    truncation splits alpha: a bias of 3.5 sigma / sqrt(n) (sigma the standard deviation of
    one contribution) is detected about 80 % of the time at alpha = 0.01.  Heavy tails that
    do not end (index < 2) give "inconclusive", where a plain t-test's false alarms run to
    10-70 %.
    """
    n = count(sample_count, "sample_count")
    integer_in(dim, "dim", 1)
    level(alpha, "alpha")
    integer_in(batches, "batches", 8, n)
    reference = finite(reference, "reference")
    name = callable_name(contributions)

    parts: list[list[tuple[int, float, float, float]]] = [[] for _ in range(batches)]
    issues: list[dict[str, int]] = []
    examples: list[dict[str, Any]] = []
    tails = TailSample.for_count(n)
    max_abs = 0.0
    for k, first, u in batch_points(n, dim, seed=seed, batches=batches):
        rows = u.shape[0]
        y = call(contributions, name, u, what=f"contributions of shape ({rows},)")   # errors name it
        y = array_result(y, (rows,), name, f"uniforms of shape {u.shape}, {u.dtype}")
        est = rest.accumulate(y)
        issues.append(est.issues)
        for ex in est.examples:
            if len(examples) < _MAX_EXAMPLES:
                examples.append({**ex, "index": int(ex["index"]) + first})
        good = y[np.isfinite(y)]
        if good.size == 0:
            continue
        tails.add(good)
        max_abs = max(max_abs, float(np.max(np.abs(good))))
        # a batch's pieces as (n, mean, stderr, skewness): _decide merges them in scaled units,
        # where the standard error stays finite for contributions near 1e+-300
        parts[k].append((est.n, est.mean, est.stderr, est.skewness))
    counts = summed_counts(issues)
    if counts:
        return UnbiasedResult.invalid(counts, examples, reference=reference, n=n, alpha=alpha,
                                      batches=batches)
    return _decide(parts, tails, max_abs, reference, alpha)


def batch_points(n: int, dim: int, *, seed: int, batches: int) -> Iterator[tuple[int, int, np.ndarray]]:
    """The uniforms check_unbiased hands to ``contributions``: (batch, index of the first row in
    the whole sample, uniforms of shape (rows, dim)), batch after batch, in pieces of at most
    2^20 rows, each piece from its own PCG32 stream."""
    sizes = np.full(batches, n // batches)
    sizes[: n % batches] += 1
    first = 0
    for k, size in enumerate(sizes):
        for piece, start in enumerate(range(0, int(size), _PIECE)):
            rows = min(_PIECE, int(size) - start)
            u = rest.points(rows, dim, seed=seed, case_id=_UNBIASED_STREAM + piece, replica=k)
            yield k, first + start, u
        first += int(size)


def _sample_skewness(x: np.ndarray) -> float:
    """The biased sample skewness m3 / m2^1.5 of ``x``, computed as scipy.stats.skew computes it
    (same bits; NaN where the spread is at the rounding level of the mean), without importing
    scipy.stats (harness.stats.distributions says why)."""
    mean = np.mean(x)
    d = x - mean
    m2, m3 = np.mean(d**2), np.mean(d**2 * d)
    with np.errstate(all="ignore"):
        return float(np.nan if m2 <= (np.finfo(np.float64).eps * mean) ** 2 else m3 / m2**1.5)


def _decide(parts: list[list[tuple[int, float, float, float]]], tails: TailSample, max_abs: float,
            reference: float, alpha: float, *, iid: bool = True) -> UnbiasedResult:
    """The verdict from batches, each a list of (n, mean, stderr, skewness) pieces, and the
    tails, as documented in check_unbiased.  Works in units of 2^e ~ max |Y|, so that
    contributions near 1e+-300 (or beyond 2^1023) square without over- or underflow (the
    scaling is exact).  ``iid``: the pieces' standard errors and skewness describe i.i.d.
    contributions (else only the batch means count)."""
    e = math.frexp(max_abs)[1] if max_abs > 0 else 0
    sc = math.ldexp(1.0, -e)
    ref = float(np.ldexp(reference, -e))
    batch_moments = [merge_moments(_piece_moments(ni, mi * sc, se * sc, g1) for ni, mi, se, g1 in pieces)
                     for pieces in parts]
    sizes_a = np.array([b[0] for b in batch_moments])
    means_a = np.array([b[1] for b in batch_moments])
    batches = means_a.size
    total, _, m2_all, m3_all = merge_moments(batch_moments)
    estimate = float(np.sum(sizes_a * means_a) / total)
    variance = m2_all / (total - 1)
    # i.i.d. contributions: the standard error and the skewness of the estimate from all n of
    # them (Student's t with n - 1 degrees of freedom, as scipy.stats.ttest_1samp); otherwise
    # only the batch means (independent replicas) count, with batches - 1
    if iid:
        stderr, df = math.sqrt(variance / total), total - 1
    else:
        stderr, df = float(np.std(means_a, ddof=1)) / math.sqrt(batches), batches - 1
    if stderr == 0:
        skew = 0.0
    elif iid and m2_all > 0:
        skew = float(m3_all / total / (m2_all / total) ** 1.5 / math.sqrt(total))
    else:
        skew = _sample_skewness(means_a) / math.sqrt(batches)
    flags: list[str] = []
    sides = {"upper": tails.up, "lower": tails.down}
    seen = {name: s.end(alpha * _END_LEVEL) for name, s in sides.items()}
    ends = {name: _biasing(seen[name], s, upper=name == "upper") for name, s in sides.items()}
    heavy = [name for name, s in sides.items() if s.tail_index() < _HEAVY_INDEX and seen[name] is None]
    tail = tails.tail_index()
    if heavy:
        flags.append(f"heavy tail: tail index {tail:.2f} < 2 (variance infinite) and no end seen")
    skewed = abs(skew) > _MAX_SKEW
    if skewed:
        flags.append(f"estimate skewed ({skew:+.2f}, beyond +-{_MAX_SKEW}): a few large contributions "
                     "dominate it, no normal approximation holds (sample more)")
    rounding = 16 * _EPS * max_abs * sc
    verdict = ""
    weight_low = 0.5
    if iid and math.sqrt(variance) <= rounding and abs(estimate - ref) > rounding:
        # every contribution equal, and not to the reference: a rare value never drawn, or a
        # wrong constant.  An unseen spread proves nothing, so no level can be claimed.
        t, p, verdict = math.nan, 1.0, "inconclusive"   # t NaN: no statistic (see ``undecided``)
        flags.append(_unseen(total, float(np.ldexp(estimate, e)), reference, alpha))
    elif stderr <= rounding:
        # (near) zero variance: the estimate is exact up to rounding, or it is wrong
        t = 0.0 if abs(estimate - ref) <= rounding else math.copysign(math.inf, estimate - ref)
        p = 1.0 if t == 0 else 0.0
    else:
        t = (estimate - ref) / stderr
        if (ends["upper"] is None) != (ends["lower"] is None):
            # a clamp (or a heavy tail's truncation) on one side can only move the mean away from it
            weight_low = _TOWARD_END if ends["upper"] is not None else 1 - _TOWARD_END
        p = _skew_corrected_p(t, skew, df, weight_low)
    no_level = bool(heavy) or skewed
    verdict = verdict or ("consistent" if p >= alpha else ("inconclusive" if no_level else "biased"))
    # the end that explains a bias found: of the upper tail for a deficit, of the lower for an excess
    end = (ends["upper"] if t < 0 else ends["lower"]) if verdict == "biased" else None
    with np.errstate(over="ignore"):  # a variance beyond 1.8e308 is inf, not an error
        variance = float(np.ldexp(variance, 2 * e))
    return UnbiasedResult(verdict, t, p, df, float(np.ldexp(estimate, e)),
                          float(np.ldexp(stderr, e)), reference, total, alpha, batches, variance, tail, skew,
                          tuple(flags), no_level, tail_end=_in_units(end, tails, t < 0) if end else "")


def _piece_moments(n: int, mean: float, stderr: float, skewness: float) -> tuple[int, float, float, float]:
    """(n, mean, M2, M3) of a piece from its summary (sample variance n stderr^2, skewness g1)."""
    if n < 2 or not stderr > 0:
        return n, mean, 0.0, 0.0
    m2 = stderr * stderr * n * (n - 1)
    return n, mean, m2, (skewness * n * (m2 / n) ** 1.5 if math.isfinite(skewness) else 0.0)


def _biasing(end: TailEnd | None, side: Side, *, upper: bool) -> TailEnd | None:
    """``end`` if it is a side's end that would bias the mean: a clamp of the upper side (an
    atom at the maximum above continuous values: a firefly clamp; at the bottom an atom is where
    zeros and misses sit), or a truncation of a heavy tail (tail index < 3: light and bounded
    tails are compressed at their top by nature)."""
    if end is None or (end.kind == "clamp" and not upper):
        return None
    return end if end.kind == "clamp" or side.tail_index() < 3 else None


def _in_units(end: TailEnd, tails: TailSample, upper: bool) -> str:
    """The end's description in the contributions' units (its value is a deviation from the centre)."""
    value = tails.center + end.value if upper else tails.center - end.value
    return str(TailEnd(end.kind, value, end.count, end.pvalue))


def _skew_corrected_p(t: float, skew: float, df: int, weight_low: float) -> float:
    """p-value of t after Hall's (1992) cubic transformation, which removes the first-order
    effect of the estimate's skewness ``skew`` on Student's t (monotone in t), with the
    rejection region split ``weight_low`` : 1 - ``weight_low`` between the lower and the upper
    side (0.5: the usual two-sided test)."""
    g = skew
    x = g * t / 3
    with np.errstate(over="ignore"):          # |t| beyond 1e150: T is +-inf, p 0
        hall = t * (1 + x + x * x / 3) + g / 6   # = t + g t^2 / 3 + g^2 t^3 / 27 + g / 6, no inf - inf
    low, high = float(distributions.t_cdf(hall, df)), float(distributions.t_sf(hall, df))
    return min(1.0, low / weight_low, high / (1 - weight_low))


def _unseen(n: int, value: float, reference: float, alpha: float) -> str:
    """Why n equal contributions cannot decide: the rule of three's bound (at level alpha) on
    the probability of any other value, and the values that could make up the difference."""
    q = -math.log(alpha) / n   # P(no other value in n draws) = (1 - q)^n <= alpha beyond this
    gap = reference - value
    return (f"all {n} contributions equal {value:.10g}, not the reference {reference:.10g}: a value not "
            f"drawn in {n} samples has probability < {q:.2g} (rule of three at alpha = {alpha:g}), and "
            f"values of {gap / q:+.3g} or beyond at that probability would make up the difference of "
            f"{gap:+.3g}; no bias can be claimed or excluded: sample more (the bound falls as 1/n)")


def check_technique(integrand: str | rest.Integrand, technique: str | rest.Technique, sample_count: int, *,
                    seed: int = 0, case_id: int = 0, alpha: float = 0.01, batches: int = 64,
                    threads: int | None = None) -> UnbiasedResult:
    """check_unbiased for a technique of the core, run in C++: the batches are independent
    replicas of ``sample_count / batches`` contributions each, so stratified and Sobol'
    estimators are tested correctly too (their replicas, not their samples, are independent).
    Same verdicts, false-alarm rate and power as check_unbiased; the tails are those of all
    the replicas' contributions (computed a second time, one replica at a time)."""
    f = rest.integrand(integrand)
    t = rest.technique(f, technique)
    n = count(sample_count, "sample_count")
    level(alpha, "alpha")
    integer_in(batches, "batches", 8, n)
    size = n // batches
    ests = [rest.integrate(f, t, size, seed=seed, case_id=case_id, replica=k, threads=threads)
            for k in range(batches)]
    counts = summed_counts(e.issues for e in ests)
    if counts:
        first = next(e for e in ests if e.issues)
        return UnbiasedResult.invalid(counts, first.examples, reference=f.reference, n=n, alpha=alpha,
                                      batches=batches)
    tails = TailSample.for_count(n)
    for k in range(batches):  # one replica's contributions in memory at a time
        tails.add(rest.contributions(f, t, size, seed=seed, case_id=case_id, replica=k, threads=threads))
    return judge_batches(ests, tails, f.reference, alpha, iid=t.iid)


def judge_batches(estimates: Sequence[rest.Estimate], tails: TailSample, reference: float, alpha: float, *,
                  iid: bool) -> UnbiasedResult:
    """The verdict of check_technique from independent batch estimates (replicas) and the
    tail sample of their contributions; for non-iid point sets only the batch means count."""
    max_abs = max(max(abs(e.min), abs(e.max)) for e in estimates)
    return _decide([[(e.n, e.mean, e.stderr, e.skewness) if iid else (e.n, e.mean, 0.0, 0.0)]
                    for e in estimates], tails, max_abs, reference, alpha, iid=iid)
