"""The verdict vocabulary and the family-wise judging every kind of case shares.

A stored verdict is one word or phrase from this vocabulary, whatever kind of case it
belongs to; its figures (counts, p-values, positions) live beside it in the row's detail.

* bias tests: "unbiased", "biased", "biased (expected)" (a technique biased on purpose, found
  so), "bias missed" (a planted bias the test did not find), "inconclusive" (heavy tails: no
  level can be claimed), "invalid" (NaN, infinite or negative values: nothing is averaged);
* convergence: "as expected", "slower than expected", "not judged" (no rate is promised);
* sampler checks: "passed", "failed";
* precision targets: "reached", "not reached".

A CI run fails on any verdict in ``FAILING``.  Within a family of tests of one kind (the bias
tests of a suite's estimator cases, their convergence fits, its sampler checks, its render
bias tests, their convergence fits) the p-values are judged together by Holm's step-down at the
suite's family-wise alpha (:func:`family_rejections`).
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from harness.stats import holm

if TYPE_CHECKING:
    from harness.stats import ConvergenceResult

__all__ = ["FAILING", "PASSING", "family_rejections", "mark_xfail", "variance_row", "slope_row"]

FAILING = frozenset({"biased", "bias missed", "invalid", "slower than expected", "failed"})
PASSING = frozenset({"unbiased", "biased (expected)", "consistent", "as expected", "passed", "reached"})


def mark_xfail(rows: list[dict], reasons: dict[str, str]) -> list[dict]:
    """The measurement rows with the ``xfail`` reason of their case (case key -> reason, ""
    where none) in their detail, so the report shows a known finding as one."""
    for row in rows:
        reason = reasons.get(row["case_key"], "")
        if reason:
            row["detail"] = {**row.get("detail", {}), "xfail": reason}
    return rows


def family_rejections(pvalues: Sequence[float | None], alpha: float) -> tuple[list[bool | None],
                                                                             list[float | None]]:
    """Holm's step-down over the tests of one family at family-wise level ``alpha``: for each
    entry, whether its null hypothesis is rejected and its adjusted p-value (None where the
    entry is None, i.e. not tested).  Holds the family-wise error rate for any dependence
    between the tests."""
    tested = [i for i, p in enumerate(pvalues) if p is not None]
    rejected: list[bool | None] = [None] * len(pvalues)
    adjusted: list[float | None] = [None] * len(pvalues)
    if tested:
        rej, adj = holm([pvalues[i] for i in tested], alpha)
        for i, r, a in zip(tested, rej, adj):
            rejected[i], adjusted[i] = bool(r), float(a)
    return rejected, adjusted


def variance_row(base: dict, variance: tuple[float, float, int], detail: dict | None = None) -> dict:
    """The stored row of a per-sample variance (value, its standard error, n) with its 95 %
    normal interval; ``base`` the case's keys, ``detail`` what the kind adds."""
    v, se, n = variance
    row = {**base, "measurement": "variance", "value": v, "lo": v - 1.96 * se, "hi": v + 1.96 * se, "n": n}
    return {**row, "detail": detail} if detail else row


def slope_row(base: dict, measurement: str, fit: ConvergenceResult, verdict: str, detail: dict) -> dict:
    """The stored row of a convergence fit: the slope with its 95 % interval, n, p and the
    verdict; its detail the expected slope, the bound and z, and what the kind adds."""
    lo, hi = fit.confidence_interval()
    return {**base, "measurement": measurement, "value": fit.slope, "lo": lo, "hi": hi, "n": fit.n,
            "pvalue": fit.pvalue, "verdict": verdict,
            "detail": {"expected": fit.expected, "bound": fit.expected + fit.tolerance, "z": fit.statistic,
                       **detail}}
