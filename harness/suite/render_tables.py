"""Verdicts, failure texts, stored rows and the table of a suite's render cases.

Bias verdicts are Holm-corrected over the suite's render cases at its family-wise alpha;
convergence verdicts over those expected to be unbiased.  Efficiency is a ratio against the
first configuration of the same estimand (one scene and one reference); relMSE at equal time is
interpolated between measured budgets, never extrapolated.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from harness import stats
from harness.stats import images as ist
from harness.suite.parse import Suite
from harness.suite.verdicts import family_rejections, slope_row, variance_row

if TYPE_CHECKING:
    from harness.suite.renders import RenderResult

__all__ = ["judge", "failures", "render_rows", "render_table", "equal_time_relmse"]


def judge(results: list[RenderResult], alpha: float) -> list[dict[str, str]]:
    """Per case: the bias verdict ("unbiased", "biased", "biased (expected)", "bias missed",
    "inconclusive" where a side of the whole image was untestable and nothing rejected,
    "invalid" for NaN/Inf/negative pixels, "not measured") and the convergence verdict ("as
    expected", "slower than expected" where the relMSE's slope is measurably worse than
    spp^-1/2 (one-sided, Holm over the cases expected unbiased), "not judged" for cases biased on
    purpose and fits with too few replicas (the case's notes say so), "not measured")."""
    bias_rej, _ = family_rejections([r.bias.pvalue if r.bias is not None else None for r in results], alpha)
    conv_rej, _ = family_rejections([r.convergence.pvalue if r.convergence is not None and r.case.expect ==
                                     "unbiased" and not r.convergence.inconclusive else None
                                     for r in results], alpha)
    out = []
    for r, rej, crej in zip(results, bias_rej, conv_rej):
        if r.faults.total:
            bias = "invalid"
        elif rej is None:
            bias = "not measured"
        elif not rej and r.bias.inconclusive:
            bias = "inconclusive"
        elif r.case.expect == "biased":
            bias = "biased (expected)" if rej else "bias missed"
        else:
            bias = "biased" if rej else "unbiased"
        if r.convergence is None:
            conv = "not measured"
        elif crej is None:
            conv = "not judged"
        else:
            conv = "slower than expected" if crej else "as expected"
        out.append({"bias": bias, "convergence": conv})
    return out


def failures(results: list[RenderResult], verdicts: list[dict[str, str]], alpha: float) -> list[str]:
    """Why each case fails ("" if it passes): a wrong bias verdict, invalid pixels, or a
    convergence measurably slower than spp^-1/2; with the figures a reader needs."""
    out = []
    for r, v in zip(results, verdicts):
        problems = []
        if v["bias"] in ("invalid", "bias missed", "biased"):
            b = r.bias
            what = "unbiased" if r.case.expect == "unbiased" else "biased"
            verdict = f"invalid ({r.faults.total} bad pixels)" if v["bias"] == "invalid" else v["bias"]
            text = f"bias: {verdict}; expected {what}"
            if b is not None:
                text += (f"; p = {b.pvalue:.3g} at family-wise alpha {alpha:.3g} (Holm over {len(results)} "
                         f"configurations), {b.replicas} replicas x {b.spp} spp; {b.scales_text()}; most "
                         f"significant {b.worst_scale.name} at (row, col, channel) {b.worst_pixel} t = "
                         f"{b.worst_t:+.2f}; image-mean bias {b.bias_mean:+.3g} ± {b.bias_mean_se:.2g}")
            if r.faults.total:
                text += f"; {r.faults}"
            problems.append(text)
        if v["convergence"] == "slower than expected":
            c = r.convergence
            lo, hi = c.confidence_interval()
            problems.append(f"convergence: sqrt(relMSE) slope {c.slope:+.2f} [{lo:+.2f}, {hi:+.2f}], "
                            f"expected {c.expected:+.2f} or faster (one-sided p = {c.pvalue:.3g}, Holm at "
                            f"alpha {alpha:.3g})\n{c.table.to_string(index=False)}")
        out.append("\n".join(problems))
    return out


def _estimand(r: RenderResult) -> tuple[str, str]:
    """Cases compared with each other: one scene and one reference (exact, or the same
    rendered reference, so the same path depth)."""
    return r.case.scene, r.reference


def _baselines(results: list[RenderResult]) -> dict[tuple[str, str], RenderResult]:
    """The first case of each estimand is the baseline of its efficiency ratios."""
    base: dict[tuple[str, str], RenderResult] = {}
    for r in results:
        if r.efficiency is not None:
            base.setdefault(_estimand(r), r)
    return base


def equal_time_relmse(results: list[RenderResult]) -> dict[str, tuple[float, float]]:
    """relMSE of each case at the longest time every case of its estimand reached: (time s,
    relMSE), interpolated linearly in log relMSE against log time between the two measured
    budgets around that time.  Budgets are taken in spp order with their median times made
    non-decreasing (timing noise of small renders), and nothing is extrapolated: a case whose
    smallest budget already takes longer gets NaN."""
    out: dict[str, tuple[float, float]] = {}
    by_estimand: dict[tuple[str, str], list[RenderResult]] = {}
    for r in results:
        if r.errors is not None and len(r.errors) >= 2 and (r.errors["relmse"] > 0).all():
            by_estimand.setdefault(_estimand(r), []).append(r)
    for group in by_estimand.values():
        t_star = min(float(r.errors["seconds"].max()) for r in group)
        for r in group:
            e = r.errors.sort_values("spp")
            t = np.maximum.accumulate(e["seconds"].to_numpy())
            lt, le = np.log(t), np.log(e["relmse"].to_numpy())
            x = math.log(t_star)
            if x < lt[0]:
                out[r.key] = (t_star, math.nan)
                continue
            i = int(np.clip(np.searchsorted(lt, x), 1, len(lt) - 1))
            w = (x - lt[i - 1]) / (lt[i] - lt[i - 1]) if lt[i] > lt[i - 1] else 1.0
            out[r.key] = (t_star, float(math.exp(le[i - 1] + min(w, 1.0) * (le[i] - le[i - 1]))))
    return out


def _ratio(r: RenderResult,
           base: dict[tuple[str, str], RenderResult]) -> tuple[RenderResult, float, float, float]:
    """The case's baseline and its efficiency ratio against it with a 95 % interval."""
    b0 = base[_estimand(r)]
    if b0 is r:
        return b0, 1.0, 1.0, 1.0
    ratio, (lo, hi) = stats.efficiency_ratio(r.efficiency, b0.efficiency)
    return b0, ratio, lo, hi


def render_rows(suite: Suite, results: list[RenderResult],
                verdicts: list[dict[str, str]]) -> list[dict[str, Any]]:
    """Measurement rows for the store (same columns as the estimator cases')."""
    rows: list[dict[str, Any]] = []
    base = _baselines(results)
    equal = equal_time_relmse(results)
    for r, v in zip(results, verdicts):
        common = {"case_key": r.key, "suite": suite.name, "integrand": r.case.scene,
                  "technique": r.case.label}
        if r.bias is not None:
            b = r.bias
            rows.append({**common, "measurement": "bias", "value": b.bias_mean,
                         "lo": b.bias_mean - 1.96 * b.bias_mean_se, "hi": b.bias_mean + 1.96 * b.bias_mean_se,
                         "n": b.replicas * b.spp, "pvalue": b.pvalue, "alpha": suite.family_alpha,
                         "verdict": v["bias"],
                         "detail": {"scales": [{"scale": sc.name, "pvalue": sc.pvalue, "alpha": sc.alpha,
                                                "count": sc.count, "low_untested": sc.low_untested,
                                                "high_untested": sc.high_untested} for sc in b.scales],
                                    "worst_scale": b.worst_scale.name, "worst_pixel": list(b.worst_pixel),
                                    "worst_t": b.worst_t, "excluded": b.excluded,
                                    "inconclusive": b.inconclusive,
                                    "pvalue_counts": b.pvalue_counts(),
                                    "replicas": b.replicas, "spp": b.spp, "reference": r.reference,
                                    "faults": r.faults.to_dict(), "notes": r.notes}})
        if r.variance is not None:
            rows.append(variance_row(common, r.variance, {"per": "sample, mean over pixels and channels"}))
        if r.convergence is not None:
            c = r.convergence
            columns = {k: c.table[k].tolist() for k in ("rmse", "rmse_lo", "rmse_hi", "seconds")}
            rows.append(slope_row(common, "convergence", c, v["convergence"],
                                  {"budgets": c.table["n"].tolist(), **columns, "error": "sqrt(relMSE)"}))
        if r.efficiency is not None:
            e = r.efficiency
            b0, ratio, lo, hi = _ratio(r, base)
            rows.append({**common, "measurement": "efficiency", "value": ratio, "lo": lo, "hi": hi,
                         "n": e.n, "detail": {"baseline": b0.case.label, "log10_value": e.log10_value,
                                              "seconds": e.seconds, "spp": e.budget,
                                                            "definition": "1/(relMSE T)"}})
        if r.errors is not None:
            top = r.errors.iloc[-1]
            rows.append({**common, "measurement": "relmse", "value": top["relmse"],
                         "lo": top["relmse"] - 1.96 * top["relmse_se"],
                         "hi": top["relmse"] + 1.96 * top["relmse_se"], "n": int(top["replicas"]),
                         "detail": {"spp": int(top["spp"]), "seconds": top["seconds"],
                                    "reference_noise": r.reference_noise, "epsilon": ist.RELMSE_EPSILON}})
            rows.append({**common, "measurement": "error_vs_time", "value": float(top["relmse"]),
                         "n": int(r.errors["replicas"].sum()),
                         "detail": {"rows": r.errors.to_dict("records")}})
        if r.key in equal:
            t_star, e_star = equal[r.key]
            rows.append({**common, "measurement": "equal_time_relmse", "value": e_star,
                         "n": int(r.errors["replicas"].sum()), "detail": {"seconds": t_star}})
    return rows


def render_table(results: list[RenderResult], verdicts: list[dict[str, str]]) -> list[dict[str, Any]]:
    """One row per render case: the figures with their uncertainty and the verdicts."""
    base = _baselines(results)
    equal = equal_time_relmse(results)
    out = []
    for r, v in zip(results, verdicts):
        row: dict[str, Any] = {"scene": r.case.scene, "configuration": r.case.label, "reference": (
            "exact" if r.reference == "exact" else r.reference if r.case.reference_config is not None
            else f"{r.case.reference_spp} spp")}
        if r.bias is not None:
            row.update({"spp x R": f"{r.bias.spp} x {r.bias.replicas}", "p": r.bias.pvalue, "bias": v["bias"],
                        "worst |t|": abs(r.bias.worst_t)})
        elif v["bias"] != "not measured":
            row["bias"] = v["bias"]
        if r.errors is not None:
            top = r.errors.iloc[-1]
            row["relMSE (top spp)"] = f"{top['relmse']:.3g} ± {top['relmse_se']:.2g} @ {int(top['spp'])}"
        if r.convergence is not None:
            c = r.convergence
            lo, hi = c.confidence_interval()
            row["slope [95% CI]"] = f"{c.slope:+.2f} [{lo:+.2f}, {hi:+.2f}]"
        if r.efficiency is not None:
            b0, ratio, lo, hi = _ratio(r, base)
            row["1/(relMSE·T) vs first [95% CI]"] = ("1 (baseline)" if b0 is r else
                                                     f"{ratio:.3g} [{lo:.3g}, {hi:.3g}]")
        if r.key in equal:
            t_star, e_star = equal[r.key]
            row["relMSE @ equal time"] = f"{e_star:.3g} @ {t_star * 1e3:.3g} ms"
        out.append(row)
    return out
