"""Efficiency 1/(V T) of one estimate (background eq. 5) and the ratio of two, from
:class:`~harness.stats.replicas.Replicates`: each figure with its interval, or the reason it has
none (infinite variance, an unreliable tail, no time or error to measure).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from harness.stats import distributions
from harness.stats.replicas import Replicates
from harness.stats.results import ConfidenceInterval, Failure, check_confidence_level
from harness.stats.timing import satterthwaite, time_blocks

__all__ = ["Efficiency", "efficiency", "efficiency_ratio"]

@dataclass(frozen=True)
class Efficiency:
    """1 / (V[F] T[F]) (background eq. 5) of one estimate F at ``budget`` samples, with a
    confidence interval; a member of the result family (:mod:`harness.stats.results`).

    V from :attr:`Replicates.log10_estimator_variance`, T the median wall time of one estimate,
    in seconds (``time_unit`` "s") or in ticks of the reference clock (``time_unit`` "clock",
    harness.stats.timing.CLOCK read beside each replica: the median time over the median
    reading, :func:`~harness.stats.timing.clock_time`).  What the interval claims differs:

    * in seconds, 1/(V·T) in 1/s is this run's figure, and its interval describes this run's
      machine state only: a run in another process, or at another time, differs by more (the
      median time moves by a few per cent from one process to the next;
      benchmarks/efficiency_coverage.py: 80/100 coverage across fresh runs for importance
      sampling);
    * in clock units, the machine's state cancels, as it does in a ratio of two interleaved
      techniques: the figure and its interval describe other runs too (on this machine type;
      another CPU has another ratio of the technique's speed to the clock's; measured: 94/100
      and 95/100 of fresh runs' intervals held the median of their 20, at 95 %).

    Their relative errors are combined on the log scale (independent, delta method), and the
    interval takes Student's t with their Welch-Satterthwaite degrees of freedom (``df``: the
    time's error comes from a few blocks of consecutive replicas).  Kept
    as log10, since 1/(V T) of an integrand near 1e300 is about 1e-590.  For techniques
    converging faster than n^-1/2 the efficiency grows with the budget: it belongs to ``budget``.

    An estimate, not a test: there is no null hypothesis, so ``pvalue``, ``statistic`` and
    ``alpha`` are NaN and ``passed`` is always True.  ``verdict`` says whether it could be
    measured: "measured" (finite value and standard error), "zero variance" (V = 0: the
    efficiency is unbounded, ``log10_value`` inf), "infinite variance" (the efficiency is 0,
    ``log10_value`` -inf, whatever a finite sample's spread suggests), "unreliable" (a tail
    index below 3: the variance exists but its error is unknown; a value, no interval) or
    "unmeasurable" (no positive time or error).  ``n`` = ``budget`` x ``replicas``, the
    samples the figure comes from.
    """

    technique: str
    log10_value: float
    log_se: float             # standard error of the natural log of the value
    budget: int               # samples (or spp) per estimate
    replicas: int
    log10_variance: float
    seconds: float
    failures: list[Failure] = field(default_factory=list)
    reason: str = ""          # why no interval: "infinite variance" or "unreliable (tail index ...)"
    df: float = math.inf      # degrees of freedom of log_se (Welch-Satterthwaite of variance and time)
    time_unit: str = "s"      # of ``seconds`` (T), so of the value: "s", or "clock" (reference-clock ticks)

    @classmethod
    def from_errors(cls, technique: str, log10_value: float, errors: Sequence[tuple[float, float]],
                    budget: int, replicas: int, log10_variance: float, seconds: float, *,
                    reason: str = "", time_unit: str = "s") -> Efficiency:
        """A measured efficiency whose log's standard error combines independent relative
        ``errors``, each (relative standard error, its degrees of freedom), with their
        Welch-Satterthwaite ``df``; no interval (log_se NaN) where ``reason`` says why."""
        log_se = math.nan if reason else math.hypot(*(e for e, _ in errors))
        return cls(technique, log10_value, log_se, budget, replicas, log10_variance, seconds, reason=reason,
                   df=satterthwaite(errors), time_unit=time_unit)

    @property
    def value(self) -> float:
        le = self.log10_value
        return math.inf if le > 308 else (0.0 if le < -323 else 10.0**le)

    @property
    def n(self) -> int:
        return self.budget * self.replicas

    @property
    def verdict(self) -> str:
        if self.reason:
            return self.reason.split(" (")[0]
        if self.log10_value == math.inf:
            return "zero variance"
        finite = math.isfinite(self.log10_value) and math.isfinite(self.log_se)
        return "measured" if finite else "unmeasurable"

    @property
    def passed(self) -> bool:
        return True

    @property
    def pvalue(self) -> float:
        return math.nan

    @property
    def statistic(self) -> float:
        return math.nan

    @property
    def alpha(self) -> float:
        return math.nan

    def log10_half_width(self, confidence_level: float = 0.95) -> float:
        """Half-width of the interval of log10 of the value: Student's t quantile with ``df``
        degrees of freedom (the time's error comes from a few blocks of replicas) x log_se."""
        check_confidence_level(confidence_level)
        return float(distributions.t_ppf(0.5 + confidence_level / 2, self.df) * self.log_se / math.log(10))

    def confidence_interval(self, confidence_level: float = 0.95) -> ConfidenceInterval:
        """Student-t interval of the log of the value, mapped back: value x 10^(+-half-width)."""
        h = self.log10_half_width(confidence_level)
        return ConfidenceInterval(float(self.value * 10.0 ** -h), float(self.value * 10.0 ** h))

    def __str__(self) -> str:
        lo, hi = self.confidence_interval()
        interval = f"95 % CI [{lo:.4g}, {hi:.4g}]" if math.isfinite(lo) else f"no interval: {self.reason}"
        clock = self.time_unit == "clock"
        unit, scope = ("clock ticks", "across runs") if clock else ("s", "this run's machine state")
        return (f"{self.verdict}: efficiency 1/(V T) of {self.technique} = 10^{self.log10_value:.4g} "
                f"({interval}, {scope}) at {self.budget} samples per estimate, "
                f"{self.replicas} replicas, V = 10^{self.log10_variance:.4g}, T = {self.seconds:.4g} {unit}")


def efficiency(r: Replicates, *, tail_index: float | None = None,
               finite_variance: bool | None = None, clock: bool = False) -> Efficiency:
    """The efficiency of one estimate at the replicates' budget (see :class:`Efficiency`), with
    T in seconds (this run's figure), or, ``clock`` True, in ticks of the reference clock timed
    beside each replica (a figure other runs reproduce; the replicates need ``clock`` times).
    ``finite_variance`` (default: the replicates') False, known analytically, or a
    contributions' ``tail_index`` below 2
    (from the bias test's tail sample): the variance is infinite, so the efficiency is 0 with
    no interval, however finite the replicas' spread looks; a tail index in [2, 3): a value
    without an interval (the variance's own error needs a fourth moment)."""
    lv, v_rel = r.log10_estimator_variance
    if clock and r.clock is None:
        raise ValueError(f"{r.integrand}/{r.technique}: clock=True needs the reference clock's time beside "
                         "each replica (replicate(..., clock=True), or Replicates(clock=...))")
    t, t_se = r.clock_time if clock else r.time
    unit = "clock" if clock else "s"
    finite_variance = r.finite_variance if finite_variance is None else finite_variance
    if finite_variance is False or (tail_index is not None and tail_index < 2):
        why = "analytic" if finite_variance is False else f"tail index {tail_index:.2f} < 2"
        return Efficiency(r.technique, -math.inf, math.nan, r.n, r.replicas, math.inf, t,
                          reason=f"infinite variance ({why})", time_unit=unit)
    if not (t > 0) or lv == -math.inf:
        return Efficiency(r.technique, math.inf if lv == -math.inf else math.nan, math.nan, r.n, r.replicas,
                          lv, t, time_unit=unit)
    unreliable = tail_index is not None and tail_index < 3
    reason = f"unreliable (tail index {tail_index:.2f} < 3)" if unreliable else ""
    errors = [(v_rel, r.replicas - 1), (t_se / t, time_blocks(r.replicas) - 1)]
    return Efficiency.from_errors(r.technique, -lv - math.log10(t), errors, r.n, r.replicas, lv, t,
                                  reason=reason, time_unit=unit)


def efficiency_ratio(a: Efficiency, b: Efficiency,
                     confidence_level: float = 0.95) -> tuple[float, ConfidenceInterval]:
    """eff(a) / eff(b) with its interval (independent measurements, log-scale delta method,
    Student's t with the Welch-Satterthwaite degrees of freedom of both time errors):
    0 without an interval where a's variance is infinite and b's is not; no interval where
    either is unreliable; NaN where b's is not finite and positive.  Both in the same time unit
    (seconds or clock ticks: ValueError otherwise)."""
    check_confidence_level(confidence_level)
    if a.time_unit != b.time_unit:
        raise ValueError(f"efficiencies in different time units: {a.technique} in {a.time_unit!r}, "
                         f"{b.technique} in {b.time_unit!r}; compare seconds with seconds, ticks with ticks")
    none = ConfidenceInterval(math.nan, math.nan)
    if not math.isfinite(b.log10_value):
        return math.nan, none
    if a.log10_value == -math.inf:
        return 0.0, none
    if not math.isfinite(a.log10_value):
        return math.nan, none
    ratio = 10.0 ** (a.log10_value - b.log10_value)
    se = math.hypot(a.log_se, b.log_se)
    if not math.isfinite(se):
        return ratio, none
    z = distributions.t_ppf(0.5 + confidence_level / 2, satterthwaite([(a.log_se, a.df), (b.log_se, b.df)]))
    return ratio, ConfidenceInterval(float(ratio * math.exp(-z * se)), float(ratio * math.exp(z * se)))
