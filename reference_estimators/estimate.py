"""The result of one Monte Carlo estimate: the figure, its uncertainty, its sample count,
and everything that went wrong while it was computed."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from scipy import special

__all__ = ["Estimate", "ERROR_ISSUES"]

# Issues that make an estimate untrustworthy (a negative contribution is one only when the
# integrand is known to be non-negative).
ERROR_ISSUES = ("nan", "posinf", "neginf", "outside_domain", "zero_pdf", "bad_pdf", "bound_violation")
_EPS = 2.0**-52


@dataclass(frozen=True)
class Estimate:
    """Mean of per-sample contributions Y with its standard error.

    For non-independent contributions (stratified or Sobol' points, ``iid`` False) ``stderr``
    is NaN: the error of such an estimate is measured over replicas.
    ``n`` counts the contributions that entered the moments; ``drawn`` counts all samples.
    They differ only when samples were excluded (NaN or infinite contributions, points
    outside the sampler's domain, zero or invalid pdf values): ``counts`` and ``examples``
    then say which, and ``ok`` is False.  Nothing is excluded silently.
    """

    mean: float
    stderr: float
    variance: float            # of one contribution Y (inf if it overflows a double)
    log10_variance: float      # finite even where ``variance`` over- or underflows
    n: int
    drawn: int
    seconds: float             # wall time of the whole call
    skewness: float
    kurtosis: float            # non-excess: 3 for a normal distribution
    min: float
    max: float
    counts: dict[str, int]
    examples: tuple[dict[str, Any], ...]
    threads: int = 1
    chunks: int = 0
    busy: tuple[float, ...] = ()  # seconds each thread spent in chunks, the calling thread first
    candidates: int = 0        # samplers' candidate draws (rejection: > drawn)
    # the estimator's path through the core ("general", or the polar path's: "polar", "polar:
    # u0s drawn in the sampler", "polar: MIS pair in one loop", the last two where some block
    # took that loop (blocks of whole generator rows: 8 or 16 samples); empty for estimates not
    # made by integrate), and the blocks of it that went back to the general path to report
    # what they held (a speed diagnostic, not kept with a stored state)
    kernel: str = ""
    redone_blocks: int = 0
    integrand: str | None = None
    technique: str | None = None
    reference: float | None = None
    nonnegative: bool = False  # the integrand is known to be >= 0
    iid: bool = True           # independent contributions (random points)

    @classmethod
    def from_core(cls, raw: dict[str, Any], **context: Any) -> "Estimate":
        names = {f for f in cls.__dataclass_fields__}
        values = {k: v for k, v in raw.items() if k in names}
        values["examples"] = tuple(raw["examples"])
        if not context.get("iid", True):
            # One randomised point set: its samples' spread says nothing about its error.
            values["stderr"] = math.nan
        return cls(**values, **context)

    # --- verdicts on the computation itself -------------------------------------------------
    @property
    def issues(self) -> dict[str, int]:
        """Non-zero counts of problems (negatives only for non-negative integrands)."""
        keys = ERROR_ISSUES + (("negative",) if self.nonnegative else ())
        return {k: self.counts[k] for k in keys if self.counts.get(k, 0)}

    @property
    def ok(self) -> bool:
        """True when no sample was excluded and nothing impossible was seen."""
        return not self.issues

    # --- uncertainty ---------------------------------------------------------------------------
    @property
    def rounding_error(self) -> float:
        """Bound on the floating-point error of ``mean``: 16 ulp of the largest contribution.

        The sum itself is compensated; what remains is the rounding inside each contribution
        (a few ulp each, possibly all of one sign).  Matters only for (near) zero-variance
        estimators, where ``stderr`` alone would turn a 1-ulp difference into a huge z-score.
        """
        return 16 * _EPS * max(abs(self.min), abs(self.max)) if self.n else math.nan

    @property
    def total_error(self) -> float:
        """Standard error and rounding bound combined in quadrature."""
        return math.hypot(self.stderr, self.rounding_error)

    def confidence_interval(self, confidence_level: float = 0.95) -> tuple[float, float]:
        """Normal-theory interval for E[Y] from ``n`` contributions.

        Valid when the variance is finite and ``n`` is large (the CLT); check
        ``variance_reliable`` first, heavy tails make the interval too narrow.
        """
        if not 0 < confidence_level < 1:
            raise ValueError(f"confidence_level must be in (0, 1), got {confidence_level}")
        half = special.ndtri(0.5 + confidence_level / 2) * self.total_error
        return (self.mean - half, self.mean + half)

    def z_score(self, reference: float | None = None) -> float:
        """(mean - reference) / total_error; reference defaults to the integrand's exact value."""
        ref = self.reference if reference is None else reference
        if ref is None:
            raise ValueError("z_score needs a reference value: this estimate has none")
        err = self.total_error
        if math.isnan(err):
            return math.nan  # no error estimate (non-independent contributions): use replicas
        return (self.mean - ref) / err if err > 0 else (0.0 if self.mean == ref
                                                        else math.copysign(math.inf, self.mean - ref))

    @property
    def variance_rel_error(self) -> float:
        """Relative standard error of ``variance``, sqrt((kurtosis - (n-3)/(n-1)) / n).

        Large values (or a kurtosis that keeps growing with n) mean the variance is infinite
        or not yet measurable: then neither ``stderr`` nor the efficiency can be trusted.
        """
        if self.n < 4 or not math.isfinite(self.kurtosis):
            return math.nan if self.variance != 0 else 0.0
        return math.sqrt(max(self.kurtosis - (self.n - 3) / (self.n - 1), 0.0) / self.n)

    @property
    def variance_reliable(self) -> bool:
        """The variance is known to 20 % or better (1 sigma) from the sample's own kurtosis."""
        rel = self.variance_rel_error
        return rel == 0.0 or (math.isfinite(rel) and rel <= 0.2)

    # --- efficiency (background, eq. 5) ---------------------------------------------------
    @property
    def log10_efficiency(self) -> float:
        """log10 of 1 / (V[F] T[F]) with V[F] = variance / n the estimator's variance and
        T[F] = ``seconds``; units 1 / (f^2 s).  Stays finite where the value would overflow."""
        if not (self.seconds > 0 and self.n > 0):
            return math.nan
        return math.log10(self.n) - self.log10_variance - math.log10(self.seconds)

    @property
    def efficiency(self) -> float:
        """1 / (V[F] T[F]) (background eq. 5); inf for a zero-variance estimator."""
        le = self.log10_efficiency
        if math.isnan(le):
            return le
        return math.inf if le > 308 else (0.0 if le < -323 else 10.0**le)

    def __str__(self) -> str:
        head = f"{self.mean:.10g} ± {self.stderr:.3g} (n = {self.n})"
        if self.issues:
            head += " [" + ", ".join(f"{k}: {v}" for k, v in self.issues.items()) + "]"
        return head
