"""Verdicts, failure texts, stored rows and the table of a suite's estimator cases.

Bias verdicts are Holm-corrected over the suite's estimator cases at its family-wise alpha,
convergence verdicts over the cases whose rate is promised; efficiency is a ratio against the
case named by ``baseline`` (default: uniform Monte Carlo on the same catalogue integrand).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from harness import stats
from harness.suite.parse import Suite
from harness.suite.verdicts import family_rejections, slope_row, variance_row

if TYPE_CHECKING:
    from harness.suite.estimators import CaseResult

__all__ = ["failure", "store_rows", "results_table", "format_table"]


# --- verdicts --------------------------------------------------------------------------------------
def _judge_convergence(results: list[CaseResult], alpha: float) -> list[str]:
    """Convergence verdict per case, Holm over the suite's judged cases at family-wise
    alpha: 'as expected', 'slower than expected', or 'not judged' where no rate is promised
    (infinite variance, heavy tails seen by the bias test, or an estimate that is skewed at the
    smallest budget: pre-asymptotic), the technique is biased on purpose (its error stops
    falling at the bias) or the fit is inconclusive (too few replicas: its notes say so)."""
    def pre_asymptotic(r: CaseResult) -> bool:
        b, smallest = r.bias, int(r.convergence.table.n.min())
        return b is not None and (bool(b.flags) or b.tail_index < 3 or not b.normal_at(smallest))

    judged = [r.convergence is not None and not r.estimator.biased and not r.convergence.inconclusive
              and r.estimator.finite_variance is not False and not pre_asymptotic(r) for r in results]
    # cases not judged enter the family with p = 1 (they count in Holm's m)
    rejected, _ = family_rejections([r.convergence.pvalue if ok else 1.0 for r, ok in zip(results, judged)],
                                    alpha)
    out = []
    for r, ok, rej in zip(results, judged, rejected):
        if r.convergence is None:
            out.append("not measured")
        elif not ok:
            out.append("not judged")
        else:
            out.append("slower than expected" if rej else "as expected")
    return out


def _judge_bias(results: list[CaseResult], alpha: float) -> list[str]:
    """Verdict per case with Holm's correction over the suite's bias tests (family-wise
    alpha): 'unbiased', 'biased', 'biased (expected)', 'bias missed', 'inconclusive',
    'invalid', 'not measured'."""
    # cases without a valid test enter the family with p = 1 (they count in Holm's m)
    rejected, _ = family_rejections([r.bias.pvalue if r.bias is not None and r.bias.verdict != "invalid"
                                     else 1.0 for r in results], alpha)
    out = []
    for r, rej in zip(results, rejected):
        if r.bias is None:
            out.append("not measured")
        elif r.bias.verdict == "invalid":
            out.append("invalid")
        elif r.bias.undecided or (rej and r.bias.no_level):
            out.append("inconclusive")
        elif rej:
            out.append("biased (expected)" if r.estimator.biased else "biased")
        else:
            out.append("bias missed" if r.estimator.biased else "unbiased")
    return out


def failure(r: CaseResult, verdicts: dict[str, str], alpha: float, family: int) -> str:
    """Why a case fails a CI run ("" if it passes), with the figures a reader needs."""
    problems = []
    b = r.bias
    if b is not None and verdicts["bias"] in ("biased", "bias missed", "invalid"):
        head = (f"bias: estimate {b.estimate:.10g} ± {b.stderr:.3g} (n = {b.n}), exact {b.reference:.10g}, "
                f"t = {b.statistic:+.2f}, p = {b.pvalue:.3g}, family-wise alpha = {alpha:.3g} "
                f"(Holm over {family} cases)")
        if math.isfinite(b.stderr):
            lo, hi = b.confidence_interval(1 - alpha)
            head += f", {100 * (1 - alpha):g} % CI [{lo:.10g}, {hi:.10g}]"
        expected = "biased (deliberately)" if r.estimator.biased else "unbiased"
        cause = f" ({b.tail_end})" if b.tail_end and verdicts["bias"] == "biased" else ""
        problems.append(f"{head}\n  verdict: {verdicts['bias']}{cause}; expected: {expected}"
                        + "".join(f"\n  {failure}" for failure in b.failures)
                        + (f"\n  flags: {'; '.join(b.flags)}" if b.flags else ""))
    c = r.convergence
    if verdicts["convergence"] == "slower than expected":
        problems.append(f"convergence: {c}; one-sided p = {c.pvalue:.3g}, family-wise alpha = {alpha:.3g} "
                        f"(Holm)\n{c.table.to_string(index=False)}")
    return "\n".join(problems)


# --- rows and tables --------------------------------------------------------------------------------
def store_rows(suite: Suite, results: list[CaseResult], table: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per case and measurement, for the store (and harness.load)."""
    rows = []
    for r, row in zip(results, table):
        base = {"case_key": r.key, "suite": suite.name, "integrand": r.case.integrand,
                "technique": r.case.technique, "alpha": suite.family_alpha}
        if r.bias is not None:
            b = r.bias
            lo, hi = b.confidence_interval(0.95) if math.isfinite(b.stderr) else (math.nan, math.nan)
            rows.append({**base, "measurement": "bias", "value": b.estimate - b.reference,
                         "lo": lo - b.reference, "hi": hi - b.reference, "n": b.n, "pvalue": b.pvalue,
                         "verdict": row["verdict"],
                         "detail": {"estimate": b.estimate, "stderr": b.stderr, "t": b.statistic,
                                    "flags": list(b.flags), "tail_end": b.tail_end,
                                    "counts": stats.failure_counts(b.failures)}})
        if r.case.target is not None and r.bias is not None:
            hw = r.target_half_width
            rows.append({**base, "measurement": "target_half_width", "value": hw, "n": r.bias.n,
                         "verdict": "reached" if hw <= r.case.target else "not reached",
                         "detail": {"target": r.case.target, "look": r.look + 1, "looks": r.case.looks}})
        if r.variance is not None:
            rows.append(variance_row(base, r.variance))
        if r.convergence is not None:
            rows.append(slope_row(base, "convergence_slope", r.convergence, row["convergence"],
                                  {"table": r.convergence.table.to_dict("list")}))
        if r.efficiency is not None:
            e = r.efficiency
            z = e.log10_half_width(0.95)
            said = {"verdict": e.verdict} if e.reason else {}   # "infinite variance", "unreliable"
            rows.append({**base, "measurement": "log10_efficiency", "value": e.log10_value,
                         "lo": e.log10_value - z, "hi": e.log10_value + z, "n": e.n, **said,
                         "detail": {"seconds": e.seconds, "reason": e.reason, "unit": "1/s",
                                    "interval": "this run's machine state"}})
            k = r.clock_efficiency
            if k is not None:
                zk = k.log10_half_width(0.95)
                rows.append({**base, "measurement": "log10_efficiency_clock", "value": k.log10_value,
                             "lo": k.log10_value - zk, "hi": k.log10_value + zk, "n": k.n, **said,
                             "detail": {"clock_ticks": k.seconds, "seconds": e.seconds, "reason": k.reason,
                                        "unit": "1/clock tick", "clock": dict(stats.CLOCK),
                                        "clock_seconds": e.seconds / k.seconds if k.seconds > 0 else None,
                                        "interval": "across runs (the machine's state cancels)"}})
            rows.append({**base, "measurement": "efficiency_ratio", "value": row["efficiency_ratio"],
                         "lo": row["ratio_lo"], "hi": row["ratio_hi"], "n": e.n, **said,
                         "detail": {"baseline": row["efficiency_baseline"], "reason": e.reason}})
        if r.error_vs_time is not None:
            top = r.error_vs_time.iloc[-1]
            rows.append({**base, "measurement": "rmse", "value": top["rmse"], "lo": top["rmse_lo"],
                         "hi": top["rmse_hi"], "n": int(top["n"]),
                         "detail": {"error_vs_time": r.error_vs_time.to_dict("list")}})
    return rows


def results_table(results: list[CaseResult], alpha: float) -> list[dict[str, Any]]:
    """One row per case: the figures with their uncertainty and n, and the verdicts."""
    # the baseline of a case: the one its ``baseline`` names; else, for catalogue cases, per
    # integrand: uniform MC where the suite has it, else the integrand's first case
    by_integrand: dict[str, CaseResult] = {}
    for r in results:
        current = by_integrand.get(r.case.integrand)
        if r.efficiency and not r.case.estimator and (
                current is None or (r.case.technique == "uniform" != current.case.technique)):
            by_integrand[r.case.integrand] = r
    by_name = {r.case.name: r for r in results}
    rows = []
    nan = math.nan
    for r, verdict, cverdict in zip(results, _judge_bias(results, alpha), _judge_convergence(results, alpha)):
        b, c, e, k = r.bias, r.convergence, r.efficiency, r.clock_efficiency
        ratio, (lo, hi) = (nan, (nan, nan))
        base = by_name[r.case.baseline] if r.case.baseline else (
            None if r.case.estimator else by_integrand.get(r.case.integrand))
        if e is not None and base is not None and base.efficiency is not None:
            ratio, (lo, hi) = stats.efficiency_ratio(e, base.efficiency)
        notes = _notes(r)
        base_name = "" if base is None else base.case.name if r.case.baseline else base.case.technique
        if base is not None and (r.case.baseline or base.case.technique != "uniform"):
            notes += f"{'; ' if notes else ''}baseline {base_name}"
        elif e is not None and base is None:
            notes += f"{'; ' if notes else ''}1/(V·T) = 10^{e.log10_value:.3g} (no baseline)"
        rows.append({
            "integrand": r.case.integrand, "technique": r.case.technique, "n": b.n if b else r.case.samples,
            "estimate": b.estimate if b else nan, "stderr": b.stderr if b else nan,
            "exact": r.estimator.reference,
            "z": b.statistic if b else nan, "pvalue": b.pvalue if b else nan, "verdict": verdict,
            "slope": c.slope if c else nan,
            "slope_lo": c.confidence_interval().low if c else nan,
            "slope_hi": c.confidence_interval().high if c else nan,
            "convergence": cverdict, "slope_pvalue": c.pvalue if c else nan,
            "log10_efficiency": e.log10_value if e else nan,
            "efficiency_baseline": base_name,
            "efficiency_ratio": ratio, "ratio_lo": lo, "ratio_hi": hi,
            "seconds_per_estimate": e.seconds if e else nan,
            "log10_efficiency_clock": k.log10_value if k else nan,
            "clock_lo": k.log10_value - k.log10_half_width() if k else nan,
            "clock_hi": k.log10_value + k.log10_half_width() if k else nan,
            "clock_ticks_per_estimate": k.seconds if k else nan,
            "notes": notes,
        })
    return rows


def _notes(r: CaseResult) -> str:
    notes = list(r.bias.flags) if r.bias else []
    if r.convergence is not None and r.convergence.inconclusive:
        notes.append(f"convergence not judged: {r.convergence.inconclusive}")
    if r.bias and r.bias.tail_end:
        notes.append(r.bias.tail_end)
    if r.bias and r.bias.failures:
        notes.append(f"faults: {stats.failure_counts(r.bias.failures)}")
    if r.estimator.finite_variance is False:
        notes.append("infinite variance (analytic)")
    if r.bias and r.bias.stderr == 0:
        notes.append("zero variance")
    if r.efficiency is not None and r.efficiency.reason:
        zero = "0, " if r.efficiency.value == 0 else ""
        notes.append(f"efficiency {zero}no interval: {r.efficiency.reason}")
    if r.efficiency is not None and r.clock_efficiency is None:
        notes.append("no reference-clock readings stored: efficiency in 1/s only (this run's machine state)")
    if r.case.target is not None:
        hw = r.target_half_width
        reached = hw <= r.case.target
        notes.append(f"target ±{r.case.target:g} {'reached' if reached else 'NOT reached'} at "
                     f"n = {r.bias.n if r.bias else 0} (±{hw:.3g}, look {r.look + 1} of {r.case.looks}, "
                     f"alpha/{r.case.looks} per look)")
    return "; ".join(notes)


def format_table(table: list[dict[str, Any]], alpha: float) -> str:
    """The table (:func:`results_table`) as aligned text."""
    def interval(v, lo, hi, fmt):
        if not math.isfinite(v):
            return "—"
        return f"{v:{fmt}} [{lo:{fmt}}, {hi:{fmt}}]" if math.isfinite(lo) else f"{v:{fmt}} (no interval)"

    def slope(r):
        slower = " slower!" if r["convergence"] == "slower than expected" else ""
        return interval(r["slope"], r["slope_lo"], r["slope_hi"], "+.2f") + slower

    columns = {
        "integrand": (lambda r: r["integrand"], "<"),
        "technique": (lambda r: r["technique"], "<"),
        "n": (lambda r: f"{r['n']:.0e}" if r["n"] >= 10**5 else str(r["n"]), ">"),
        "estimate ± stderr": (lambda r: f"{r['estimate']:.9g} ± {r['stderr']:.2g}", ">"),
        "exact": (lambda r: f"{r['exact']:.9g}", ">"),
        "t": (lambda r: f"{r['z']:+.2f}" if math.isfinite(r["z"]) else str(r["z"]), ">"),
        "p": (lambda r: f"{r['pvalue']:.2g}", ">"),
        f"bias (Holm, α={alpha:.3g})": (lambda r: r["verdict"], "<"),
        "RMSE slope [95% CI]": (slope, "<"),
        "1/(V·T) vs baseline [95% CI]": (
            lambda r: interval(r["efficiency_ratio"], r["ratio_lo"], r["ratio_hi"], ".3g"), "<"),
        "log10 1/(V·T_clock) [95% CI]": (
            lambda r: interval(r["log10_efficiency_clock"], r["clock_lo"], r["clock_hi"], ".3f"), "<"),
        "notes": (lambda r: r["notes"], "<"),
    }
    cells = {k: [str(cell(r)) for r in table] for k, (cell, _) in columns.items()}
    width = {k: max(len(k), *(len(v) for v in cells[k])) for k in cells}
    lines = ["  ".join(f"{k:{a}{width[k]}}" for k, (_, a) in columns.items()).rstrip()]
    for i in range(len(table)):
        lines.append("  ".join(f"{cells[k][i]:{a}{width[k]}}" for k, (_, a) in columns.items()).rstrip())
    return "\n".join(lines)
