"""Runs a suite's cases on the reference core and tabulates the measurements.

Per case: a bias verdict (check_technique: batch means of independent replicas, Holm-
corrected across the suite at its family-wise alpha), a convergence slope of the RMSE over
geometric budgets with a bootstrap interval, and the efficiency 1/(V T) as a ratio against
uniform Monte Carlo on the same integrand, with an interval.  Results live in memory for
now; storage grows around this without changing what a case is.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import pandas as pd

import reference_estimators as rest

from . import stats
from .suite import Case, Suite

__all__ = ["CaseResult", "run_suite", "results_table", "format_table", "judge", "bad_verdicts"]


@dataclass(frozen=True)
class CaseResult:
    case: Case
    bias: stats.UnbiasedResult
    convergence: stats.ConvergenceResult | None  # None for zero-variance estimators
    efficiency: stats.Efficiency | None
    technique: rest.Technique


def run_suite(suite: Suite, *, threads: int | None = None,
              progress: Callable[[int, int, Case], None] | None = None) -> Iterator[CaseResult]:
    """Yields one CaseResult per case, in suite order; ``progress(done, total, case)`` after each."""
    threads = threads if threads is not None else suite.threads
    for i, case in enumerate(suite.cases):
        t = rest.technique(case.integrand, case.technique)
        bias = stats.check_technique(case.integrand, t, case.samples, seed=suite.seed, case_id=case.case_id,
                                     alpha=suite.alpha, batches=suite.batches, threads=threads)
        conv = eff = None
        if bias.verdict != "invalid" and bias.stderr > 0:
            budgets = _budgets(case.samples, suite.budgets)
            conv = stats.convergence_rate(case.integrand, t, budgets, suite.replicas, seed=suite.seed,
                                          case_id=(case.case_id + 1) << 20, threads=threads)
            top = stats.replicate(case.integrand, t, budgets[-1], suite.replicas, seed=suite.seed,
                                  case_id=((case.case_id + 1) << 20) + 7919 * (len(budgets) - 1), threads=threads)
            eff = stats.efficiency(top)
        if progress:
            progress(i + 1, len(suite.cases), case)
        yield CaseResult(case, bias, conv, eff, t)


def _budgets(samples: int, budgets: tuple[int, ...] | None) -> list[int]:
    """The suite's budgets, or five geometric ones from samples/1024 to samples/16."""
    if budgets:
        return list(budgets)
    top = max(samples // 16, 64)
    return [max(top >> (2 * k), 16) for k in range(4, -1, -1)]


def judge(results: list[CaseResult], alpha: float) -> list[str]:
    """Verdict per case with Holm's correction over the suite's bias tests (family-wise
    alpha): 'unbiased', 'biased', 'biased (expected)', 'bias missed', 'inconclusive',
    'invalid'."""
    p = [r.bias.pvalue if r.bias.verdict != "invalid" else 1.0 for r in results]
    rejected, _ = stats.holm(p, alpha) if results else ([], [])
    out = []
    for r, rej in zip(results, rejected):
        if r.bias.verdict == "invalid":
            out.append("invalid")
        elif rej and r.bias.heavy_tail:
            out.append("inconclusive")
        elif rej:
            out.append("biased (expected)" if r.technique.biased else "biased")
        else:
            out.append("bias missed" if r.technique.biased else "unbiased")
    return out


def results_table(results: list[CaseResult], alpha: float) -> pd.DataFrame:
    """One row per case: the figures with their uncertainty and n, and the verdicts."""
    # baseline per integrand: uniform MC where the suite has it, else the integrand's first case
    baseline: dict[str, CaseResult] = {}
    for r in results:
        current = baseline.get(r.case.integrand)
        if r.efficiency and (current is None or (r.case.technique == "uniform" != current.case.technique)):
            baseline[r.case.integrand] = r
    rows = []
    for r, verdict in zip(results, judge(results, alpha)):
        b, c, e = r.bias, r.convergence, r.efficiency
        ratio, (lo, hi) = (math.nan, (math.nan, math.nan))
        base = baseline.get(r.case.integrand)
        if e is not None and base is not None:
            ratio, (lo, hi) = stats.efficiency_ratio(e, base.efficiency)
        rows.append({
            "integrand": r.case.integrand, "technique": r.case.technique, "n": b.n,
            "estimate": b.estimate, "stderr": b.stderr, "exact": b.reference,
            "z": b.statistic, "pvalue": b.pvalue, "verdict": verdict,
            "slope": c.slope if c else math.nan,
            "slope_lo": c.slope_interval[0] if c else math.nan, "slope_hi": c.slope_interval[1] if c else math.nan,
            "slope_worse": bool(c and c.worse_than_expected),
            "log10_efficiency": e.log10_value if e else math.nan,
            "efficiency_baseline": base.case.technique if base else "",
            "efficiency_ratio": ratio, "ratio_lo": lo, "ratio_hi": hi,
            "seconds_per_estimate": e.seconds if e else math.nan,
            "notes": _notes(r) + ("" if base is None or base.case.technique == "uniform" else
                                  f"{'; ' if _notes(r) else ''}baseline {base.case.technique}"),
        })
    return pd.DataFrame(rows)


def _notes(r: CaseResult) -> str:
    notes = list(r.bias.flags)
    if r.bias.counts:
        notes.append(f"faults: {r.bias.counts}")
    if r.technique.finite_variance is False:
        notes.append("infinite variance (analytic)")
    if r.convergence is None and r.bias.verdict != "invalid":
        notes.append("zero variance")
    elif r.convergence and r.convergence.worse_than_expected:
        notes.append(f"converges slower than n^{r.convergence.expected:+.1f}")
    return "; ".join(notes)


def format_table(df: pd.DataFrame, alpha: float) -> str:
    """The table as aligned text."""
    def interval(v, lo, hi, fmt):
        return "—" if not math.isfinite(v) else f"{v:{fmt}} [{lo:{fmt}}, {hi:{fmt}}]"

    columns = {
        "integrand": (df["integrand"], "<"),
        "technique": (df["technique"], "<"),
        "n": (df["n"].map(lambda n: f"{n:.0e}" if n >= 10**5 else str(n)), ">"),
        "estimate ± stderr": ([f"{m:.9g} ± {s:.2g}" for m, s in zip(df["estimate"], df["stderr"])], ">"),
        "exact": (df["exact"].map(lambda v: f"{v:.9g}"), ">"),
        "t": (df["z"].map(lambda z: f"{z:+.2f}" if math.isfinite(z) else str(z)), ">"),
        "p": (df["pvalue"].map(lambda p: f"{p:.2g}"), ">"),
        f"bias (Holm, α={alpha:g})": (df["verdict"], "<"),
        "RMSE slope [95% CI]": ([interval(v, lo, hi, "+.2f") for v, lo, hi in zip(df["slope"], df["slope_lo"], df["slope_hi"])], "<"),
        "1/(V·T) vs baseline [95% CI]": ([interval(v, lo, hi, ".3g") for v, lo, hi in
                                         zip(df["efficiency_ratio"], df["ratio_lo"], df["ratio_hi"])], "<"),
        "notes": (df["notes"], "<"),
    }
    cells = {k: [str(v) for v in vals] for k, (vals, _) in columns.items()}
    width = {k: max(len(k), *(len(v) for v in cells[k])) for k in cells}
    lines = ["  ".join(f"{k:{a}{width[k]}}" for k, (_, a) in columns.items()).rstrip()]
    for i in range(len(df)):
        lines.append("  ".join(f"{cells[k][i]:{a}{width[k]}}" for k, (_, a) in columns.items()).rstrip())
    return "\n".join(lines)


def bad_verdicts(df: pd.DataFrame) -> pd.DataFrame:
    """Rows a CI run must fail on: unbiased techniques found biased, planted bias missed,
    faults in the contributions."""
    return df[df["verdict"].isin(["biased", "bias missed", "invalid"])]

