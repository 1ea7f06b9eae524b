"""The outcome of a sampler check (:class:`SamplerCheck`): its verdict, the p-values of its
tests, its deterministic failures, and what the report plots (residuals, marginals), for
:func:`harness.samplers.check.check_sampler`, ``mcmc_crosscheck`` and the Mitsuba adapter."""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from harness.stats.results import ConfidenceInterval, Failure, check_confidence_level

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["SamplerCheck"]


@dataclass(frozen=True)
class SamplerCheck:
    """Outcome of :func:`check_sampler` (also of ``mcmc_crosscheck`` and of the Mitsuba
    adapter's ``check_mitsuba_sampler``).  ``passed`` is False when a deterministic check
    failed (``failures``), the Holm-combined statistical tests reject at ``alpha``, or the
    check could not reach a verdict (``inconclusive`` holds why, e.g. an MCMC chain too short
    for its autocorrelation time; its ``pvalue`` is then 1: nothing was rejected).  ``pvalue``
    is the smallest Holm-adjusted p-value of the tests (a valid p-value of the whole check);
    ``n`` the number of samples drawn."""

    passed: bool
    pvalue: float                 # smallest Holm-adjusted p-value of the statistical tests
    alpha: float
    n: int
    tests: pd.DataFrame           # test, statistic, df, pvalue, detects, adjusted
    failures: list[Failure]
    normalization: tuple[float, float]   # integral of the pdf over the domain, its error bound
    residuals: dict[str, np.ndarray] = field(default_factory=dict)  # standardised, per grid; NaN: pooled cell
    # per axis "s0", "s1": observed and expected counts at <= 128 bins (for plots)
    marginals: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    inconclusive: str = ""        # why no verdict could be reached ("" where one was)

    @property
    def verdict(self) -> str:
        """"passed", "failed", or "inconclusive" (no failure and no rejection, but no verdict
        either: ``inconclusive`` says why)."""
        if self.passed:
            return "passed"
        undecided = self.inconclusive and not self.failures and self.pvalue > self.alpha
        return "inconclusive" if undecided else "failed"

    @property
    def statistic(self) -> float:
        """NaN: the check combines several tests by Holm; their statistics are in ``tests``."""
        return math.nan

    def confidence_interval(self, confidence_level: float = 0.95) -> ConfidenceInterval:
        """The integral of the claimed pdf over the domain (``normalization``): the cubature's
        value ± its error bound.  The bound is deterministic (the change of the last
        refinement, an overestimate at steps and singularities; the ~1e-16 rounding of the
        sum is not in it), so the interval is the same at every ``confidence_level``
        (validated only).  It is the figure the normalisation check judges; NaN ends where no
        cubature was done (``mcmc_crosscheck``)."""
        check_confidence_level(confidence_level)
        total, err = self.normalization
        return ConfidenceInterval(total - err, total + err)

    def to_payload(self) -> dict[str, Any]:
        """JSON-able form a suite stores: passed, pvalue, inconclusive (the reason, "" where
        a verdict was reached), tests (records), failures (plain dicts), normalization, and
        for the report's heatmaps and marginal plots the residuals (rounded to 2 decimals,
        pooled cells None) and marginals (rounded to 2 decimals)."""
        return {"passed": self.passed, "pvalue": self.pvalue, "inconclusive": self.inconclusive,
                "tests": json.loads(self.tests.to_json(orient="records")),
                "failures": json.loads(json.dumps([f.to_dict() for f in self.failures], default=float)),
                "normalization": [float(v) for v in self.normalization],
                "residuals": {g: np.where(np.isnan(v), None, np.round(v, 2)).tolist()
                              for g, v in self.residuals.items()},
                "marginals": {a: {k: np.round(v, 2).tolist() for k, v in m.items()}
                              for a, m in self.marginals.items()}}

    def __str__(self) -> str:
        total, err = self.normalization
        head = (f"{self.verdict.upper()}: {self.n} samples, alpha = {self.alpha}, "
                f"Holm-adjusted p = {self.pvalue:.3g}")
        if math.isfinite(total):
            head += f"; pdf integrates to {total:.6f} ± {err:.1e}"
        lines = [head, self._why()] + [f"  {f}" for f in self.failures]
        lines.append(self.tests.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
        return "\n".join(lines)

    def _why(self) -> str:
        if self.passed:
            return f"no deterministic failure and no test rejects at alpha = {self.alpha}"
        if self.verdict == "inconclusive":
            return f"inconclusive: {self.inconclusive}"
        parts = []
        if self.failures:
            parts.append("failed deterministic checks: " + ", ".join(f.check for f in self.failures))
        rejected = self.tests[self.tests["adjusted"] <= self.alpha]
        if len(rejected):
            parts.append(f"rejected at alpha = {self.alpha} by " + ", ".join(
                f"{t} (adjusted p = {a:.3g})" for t, a in zip(rejected["test"], rejected["adjusted"])))
        return "; ".join(parts)
