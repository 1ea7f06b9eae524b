"""Runs a suite: plan the work units, execute the missing ones, measure from what is stored.

Per case, as its measurements ask: a bias verdict (check_technique's test on independent
batches, Holm-corrected across the suite at its family-wise alpha) and the per-sample
variance from the same batches; a convergence slope of the RMSE over geometric budgets with
a bootstrap interval; the efficiency 1/(V T) as a ratio against uniform Monte Carlo on the
same integrand; and RMSE against wall time.  Units are stored as they finish (SQLite), so a
killed run resumes where it stopped, and a finished suite re-runs without computing anything.
"""
from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd
from scipy import stats as sps

import reference_estimators as rest
from reference_estimators import _core

from harness import stats
from harness.suite.execute import UnitJob, execute
from harness.suite.renders import RenderResult, judge_renders, render_rows, run_renders
from harness.suite.plan import Unit, bias_budget, bias_stream, case_key, convergence_budgets, plan, sampler_key, sampler_spec
from harness.suite.store import Store
from harness.suite.parse import Case, SamplerCase, Suite

__all__ = ["CaseResult", "SamplerResult", "RunSummary", "run_suite", "results_table", "format_table", "judge",
           "judge_convergence", "judge_samplers", "format_sampler_table", "bad_verdicts"]

_COMMIT_EVERY = 0.1  # seconds between commits: a kill loses at most this much finished work


@dataclass(frozen=True)
class CaseResult:
    case: Case
    technique: rest.Technique
    key: str
    bias: stats.UnbiasedResult | None
    convergence: stats.ConvergenceResult | None  # None if not asked for or zero variance
    efficiency: stats.Efficiency | None
    variance: tuple[float, float, int] | None    # per-contribution variance, its std. error, n
    error_vs_time: pd.DataFrame | None
    look: int = 0                                # precision targets: the look the bias test stopped at

    @property
    def target_half_width(self) -> float:
        """Half-width of the bias test's interval at level 1 - alpha / looks (targets only)."""
        b = self.bias
        if b is None or not math.isfinite(b.stderr):
            return math.nan
        return float(sps.t.ppf(1 - b.alpha / (2 * self.case.looks), b.df) * b.stderr)


@dataclass(frozen=True)
class SamplerResult:
    case: SamplerCase
    key: str
    checks: dict[str, dict[str, Any]]   # measurement -> stored payload (passed, pvalue, tests, failures)


@dataclass(frozen=True)
class RunSummary:
    results: list[CaseResult]
    units_planned: int
    units_run: int
    seconds: float
    db: Path
    samplers: list[SamplerResult] = dataclasses.field(default_factory=list)
    renders: list[RenderResult] = dataclasses.field(default_factory=list)


def run_suite(suite: Suite, db: str | Path, *, threads: int | None = None, dask: str | None = None,
              progress: Callable[[int, int], None] | None = None) -> RunSummary:
    """Runs what is missing from ``db`` for ``suite`` and measures every case from the store.
    ``progress(done, total)`` is called as units finish."""
    start = time.perf_counter()
    threads = threads or suite.threads or rest._core.hardware_threads()
    store = Store(db)
    try:
        case_of = {case_key(suite, c): c for c in suite.cases}
        for key, c in case_of.items():
            store.add_case(key, suite.name, c.integrand, c.technique,
                           {"seed": suite.seed, "case_id": c.case_id, "samples": c.samples})
        looks = {k: 0 for k, c in case_of.items() if c.target is not None}

        sampler_of = {sampler_key(suite, sc): sc for sc in suite.samplers}
        for key, sc in sampler_of.items():
            store.add_case(key, suite.name, f"sampler:{sc.label}", sc.domain, {"seed": suite.seed, "samples": sc.samples})

        def job(u: Unit) -> UnitJob:
            if u.case_key in sampler_of:
                return (u.key, sampler_spec(sampler_of[u.case_key]), "", suite.seed, 0)
            c = case_of[u.case_key]
            return (u.key, c.integrand, c.technique, suite.seed, _core_case(c, u.stream))

        done, last, ran, total = 0, time.perf_counter(), 0, 0
        planned: set[tuple] = set()

        def sink(key: tuple, payload: dict[str, Any], seconds: float) -> None:
            nonlocal done, last
            store.put(key, payload, seconds)
            done += 1
            if time.perf_counter() - last > _COMMIT_EVERY:
                store.commit()
                last = time.perf_counter()
            if progress:
                progress(done, total)

        while True:  # one pass, plus one per further look of cases with a precision target
            units = plan(suite, looks)
            planned |= {u.key for us in units.values() for u in us}
            stored = store.stored_keys(units)
            missing = [u for us in units.values() for u in us if u.key not in stored]
            total, done = len(planned), len(planned) - len(missing)
            ran += execute(missing, job, sink, threads=threads, dask=dask) if missing else 0
            store.commit()
            grown = False
            for key, look in looks.items():
                c = case_of[key]
                r = _measure(suite, c, store.payloads(key), look)
                if look + 1 < c.looks and (r.bias is None or not r.target_half_width <= c.target):
                    looks[key] = look + 1
                    grown = True
            if not grown:
                break
        results = [_measure(suite, c, store.payloads(k), looks.get(k, 0)) for k, c in case_of.items()]
        samplers = [SamplerResult(sc, k, {key[6]: p for key, p in store.payloads(k).items()})
                    for k, sc in sampler_of.items()]
        core_total = total
        renders, r_total, r_ran = run_renders(
            suite, store, progress=(lambda d, t: progress(core_total + d, core_total + t)) if progress else None)
        store.put_measurements(_measurement_rows(suite, results) + _sampler_rows(suite, samplers)
                               + render_rows(suite, renders, judge_renders(renders, suite.alpha)))
        return RunSummary(results, total + r_total, ran + r_ran, time.perf_counter() - start, Path(db), samplers,
                          renders)
    finally:
        store.close()


def _core_case(case: Case, stream: int) -> int:
    """The core's case_id field of a stream: case position and purpose, disjoint for all."""
    return (case.case_id << 8) | stream


def _states_by_estimate(payloads: dict[tuple, dict]) -> dict[tuple[int, int, int], list[dict]]:
    """State payloads grouped by (stream, budget, replica), in chunk order."""
    groups: dict[tuple[int, int, int], list[tuple[int, dict]]] = {}
    for k, p in payloads.items():
        if k[6] == "state":
            groups.setdefault((k[1], k[2], k[3]), []).append((k[4], p))
    return {g: [p for _, p in sorted(v, key=lambda x: x[0])] for g, v in groups.items()}


def _measure(suite: Suite, case: Case, payloads: dict[tuple, dict], look: int = 0) -> CaseResult:
    f = rest.integrand(case.integrand)
    t = rest.technique(f, case.technique)
    key = case_key(suite, case)
    wanted = set(case.measurements)
    states = _states_by_estimate(payloads)

    def estimate(stream: int, budget: int, replica: int) -> rest.Estimate:
        raw = _core.estimate_from_state(_core.merge_states(states[(stream, budget, replica)]))
        return rest.Estimate.from_core(raw, integrand=f.name, technique=t.name, reference=f.reference,
                                       nonnegative=f.nonnegative, iid=t.iid)

    bias = variance = conv = eff = evt = None
    if wanted & {"bias", "variance"}:
        b, stream = bias_budget(suite, case, look), bias_stream(look)
        batches = [estimate(stream, b, k) for k in range(suite.batches)]
        faults = {k: v for e in batches for k, v in e.issues.items()}
        if "bias" in wanted:
            tail = next(p for k, p in payloads.items() if k[6] == "tail" and k[1] == stream)
            tails = stats.TailSample.from_tops(tail["upper"], tail["lower"])
            bias = (stats.judge_batches(batches, tails, f.reference, suite.alpha, iid=t.iid) if not faults else
                    stats.UnbiasedResult("invalid", math.nan, math.nan, suite.batches - 1, math.nan, math.nan,
                                         f.reference, b * suite.batches, suite.alpha, suite.batches, math.nan,
                                         math.nan, math.nan, flags=("contributions with faults",), counts=faults,
                                         examples=next(e for e in batches if e.issues).examples))
            if case.looks > 1 and bias.verdict != "invalid":
                # alpha spent over the looks a target may take (Bonferroni: any dependence, any
                # stopping rule): the final look's p-value times the number of looks
                p = min(1.0, bias.pvalue * case.looks)
                verdict = "consistent" if p >= suite.alpha else ("inconclusive" if bias.heavy_tail else "biased")
                bias = dataclasses.replace(bias, pvalue=p, verdict=verdict)
        if "variance" in wanted and not faults and t.iid:
            reps = stats.Replicates.from_estimates(f, t, b, batches)
            rel = math.sqrt(max(reps.sample_kurtosis - 1, 0.0) / (reps.replicas * b))
            variance = (reps.sample_variance, reps.sample_variance * rel, reps.replicas * b)
    budgets = convergence_budgets(suite, case)
    reps_by_budget = {}
    for i, b in enumerate(budgets):
        if (1 + i, b, 0) in states:
            reps_by_budget[b] = stats.Replicates.from_estimates(
                f, t, b, [estimate(1 + i, b, r) for r in range(suite.replicas)])
    if reps_by_budget:
        top = reps_by_budget[max(reps_by_budget)]
        if top.rmse > 0 and "efficiency" in wanted:
            eff = stats.efficiency(top)
        if "convergence" in wanted and len(reps_by_budget) >= 3 and top.rmse > 0:
            conv = stats.fit_convergence(list(reps_by_budget.values()), seed=suite.seed)
        if "error_vs_time" in wanted:
            evt = pd.DataFrame([{"n": r.n, "rmse": r.rmse, "rmse_lo": r.rmse_interval()[0],
                                 "rmse_hi": r.rmse_interval()[1], "seconds": r.time[0], "seconds_se": r.time[1],
                                 "replicas": r.replicas} for r in reps_by_budget.values()])
    return CaseResult(case, t, key, bias, conv, eff, variance, evt, look)


def _measurement_rows(suite: Suite, results: list[CaseResult]) -> list[dict[str, Any]]:
    """One row per case and measurement, for the store (and harness.load)."""
    table = results_table(results, suite.alpha)
    rows = []
    for r, row in zip(results, table.to_dict("records")):
        base = {"case_key": r.key, "suite": suite.name, "integrand": r.case.integrand, "technique": r.case.technique,
                "alpha": suite.alpha}
        if r.bias is not None:
            lo, hi = r.bias.confidence_interval(0.95) if math.isfinite(r.bias.stderr) else (math.nan, math.nan)
            rows.append({**base, "measurement": "bias", "value": r.bias.estimate - r.bias.reference, "lo": lo - r.bias.reference,
                         "hi": hi - r.bias.reference, "n": r.bias.n, "pvalue": r.bias.pvalue, "verdict": row["verdict"],
                         "detail": {"estimate": r.bias.estimate, "stderr": r.bias.stderr, "t": r.bias.statistic,
                                    "flags": list(r.bias.flags), "counts": r.bias.counts}})
        if r.case.target is not None and r.bias is not None:
            hw = r.target_half_width
            rows.append({**base, "measurement": "target_half_width", "value": hw, "n": r.bias.n,
                         "verdict": "reached" if hw <= r.case.target else "not reached",
                         "detail": {"target": r.case.target, "look": r.look + 1, "looks": r.case.looks}})
        if r.variance is not None:
            v, se, n = r.variance
            rows.append({**base, "measurement": "variance", "value": v, "lo": v - 1.96 * se, "hi": v + 1.96 * se, "n": n})
        if r.convergence is not None:
            c = r.convergence
            rows.append({**base, "measurement": "convergence_slope", "value": c.slope, "lo": c.slope_interval[0],
                         "hi": c.slope_interval[1], "n": int(c.table["replicas"].sum()), "pvalue": c.pvalue,
                         "verdict": row["convergence"],
                         "detail": {"expected": c.expected, "table": c.table.to_dict("list")}})
        if r.efficiency is not None:
            e = r.efficiency
            z = 1.96 * e.log_se / math.log(10)
            rows.append({**base, "measurement": "log10_efficiency", "value": e.log10_value, "lo": e.log10_value - z,
                         "hi": e.log10_value + z, "n": e.n * e.replicas, "detail": {"seconds": e.seconds}})
            rows.append({**base, "measurement": "efficiency_ratio", "value": row["efficiency_ratio"],
                         "lo": row["ratio_lo"], "hi": row["ratio_hi"], "n": e.n * e.replicas,
                         "detail": {"baseline": row["efficiency_baseline"]}})
        if r.error_vs_time is not None:
            top = r.error_vs_time.iloc[-1]
            rows.append({**base, "measurement": "rmse", "value": top["rmse"], "lo": top["rmse_lo"], "hi": top["rmse_hi"],
                         "n": int(top["n"]), "detail": {"error_vs_time": r.error_vs_time.to_dict("list")}})
    return rows


def judge_samplers(samplers: list[SamplerResult], alpha: float) -> list[dict[str, str]]:
    """Verdict per sampler check, Holm over all of the suite's checks at family-wise alpha:
    'passed' or 'failed' (deterministic failures always fail)."""
    flat = [(i, m, c) for i, r in enumerate(samplers) for m, c in r.checks.items()]
    rejected, adjusted = stats.holm([c["pvalue"] for _, _, c in flat], alpha) if flat else ([], [])
    out: list[dict[str, str]] = [{} for _ in samplers]
    for (i, m, c), rej, adj in zip(flat, rejected, adjusted):
        out[i][m] = "failed" if (rej or c["failures"]) else "passed"
        out[i][m + "_adjusted"] = f"{adj:.3g}"
    return out


def _sampler_rows(suite: Suite, samplers: list[SamplerResult]) -> list[dict[str, Any]]:
    rows = []
    for r, v in zip(samplers, judge_samplers(samplers, suite.alpha)):
        for m, c in r.checks.items():
            rows.append({"case_key": r.key, "suite": suite.name, "integrand": f"sampler:{r.case.label}",
                         "technique": r.case.domain, "measurement": m, "value": c["pvalue"], "n": r.case.samples,
                         "pvalue": c["pvalue"], "alpha": suite.alpha, "verdict": v[m],
                         "detail": {"tests": c["tests"], "failures": c["failures"], "normalization": c["normalization"],
                                    "residuals": c.get("residuals", {}), "marginals": c.get("marginals", {})}})
    return rows


def format_sampler_table(samplers: list[SamplerResult], alpha: float) -> str:
    """Sampler checks as aligned text: p-values (within-check Holm), suite verdicts (Holm)."""
    width = max([34] + [len(r.case.label) for r in samplers])
    lines = [f"{'sampler':{width}s} {'domain':10s} {'n':>7s}  {'chi-square p':>12s}  {'mcmc p':>8s}  {'weight':>8s}  verdict (Holm, α={alpha:g})"]
    for r, v in zip(samplers, judge_samplers(samplers, alpha)):
        cs, mc = r.checks.get("chi_square"), r.checks.get("mcmc")
        verdict = "failed" if "failed" in v.values() else "passed"
        notes = "; ".join(f"{f['check']}: {f['count']}" for c in r.checks.values() for f in c["failures"])
        p_cs = f"{cs['pvalue']:.3g}" if cs else "—"
        p_mc = f"{mc['pvalue']:.3g}" if mc else "—"
        w = r.checks.get("weight")
        weight = "—" if w is None else ("ok" if not w["failures"] else "mismatch")
        lines.append(f"{r.case.label:{width}s} {r.case.domain:10s} {r.case.samples:7.0e}  {p_cs:>12s}  {p_mc:>8s}  {weight:>8s}  "
                     f"{verdict}{'  ' + notes if notes else ''}")
    return "\n".join(lines)


def judge_convergence(results: list[CaseResult], alpha: float) -> list[str]:
    """Convergence verdict per case, Holm over the suite's judged cases at family-wise
    alpha: 'as expected', 'slower than expected', or 'not judged' where no rate is promised
    (infinite variance, heavy tails or skewed batches seen by the bias test: pre-asymptotic)
    or the technique is biased on purpose (its error stops falling at the bias)."""
    judged = []
    for r in results:
        c, b = r.convergence, r.bias
        ok = (c is not None and not r.technique.biased and r.technique.finite_variance is not False
              and not (b is not None and b.flags))
        judged.append(ok)
    p = [r.convergence.pvalue if ok else 1.0 for r, ok in zip(results, judged)]
    rejected, _ = stats.holm(p, alpha) if results else ([], [])
    out = []
    for r, ok, rej in zip(results, judged, rejected):
        if r.convergence is None:
            out.append("not measured")
        elif not ok:
            out.append("not judged")
        else:
            out.append("slower than expected" if rej else "as expected")
    return out


def judge(results: list[CaseResult], alpha: float) -> list[str]:
    """Verdict per case with Holm's correction over the suite's bias tests (family-wise
    alpha): 'unbiased', 'biased', 'biased (expected)', 'bias missed', 'inconclusive',
    'invalid'."""
    p = [r.bias.pvalue if r.bias is not None and r.bias.verdict != "invalid" else 1.0 for r in results]
    rejected, _ = stats.holm(p, alpha) if results else ([], [])
    out = []
    for r, rej in zip(results, rejected):
        if r.bias is None:
            out.append("not measured")
        elif r.bias.verdict == "invalid":
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
    for r, verdict, cverdict in zip(results, judge(results, alpha), judge_convergence(results, alpha)):
        b, c, e = r.bias, r.convergence, r.efficiency
        ratio, (lo, hi) = (math.nan, (math.nan, math.nan))
        base = baseline.get(r.case.integrand)
        if e is not None and base is not None:
            ratio, (lo, hi) = stats.efficiency_ratio(e, base.efficiency)
        nan = math.nan
        rows.append({
            "integrand": r.case.integrand, "technique": r.case.technique, "n": b.n if b else r.case.samples,
            "estimate": b.estimate if b else nan, "stderr": b.stderr if b else nan,
            "exact": rest.integrand(r.case.integrand).reference,
            "z": b.statistic if b else nan, "pvalue": b.pvalue if b else nan, "verdict": verdict,
            "slope": c.slope if c else nan,
            "slope_lo": c.slope_interval[0] if c else nan, "slope_hi": c.slope_interval[1] if c else nan,
            "convergence": cverdict, "slope_pvalue": c.pvalue if c else nan,
            "log10_efficiency": e.log10_value if e else nan,
            "efficiency_baseline": base.case.technique if base else "",
            "efficiency_ratio": ratio, "ratio_lo": lo, "ratio_hi": hi,
            "seconds_per_estimate": e.seconds if e else nan,
            "notes": _notes(r) + ("" if base is None or base.case.technique == "uniform" else
                                  f"{'; ' if _notes(r) else ''}baseline {base.case.technique}"),
        })
    return pd.DataFrame(rows)


def _notes(r: CaseResult) -> str:
    notes = list(r.bias.flags) if r.bias else []
    if r.bias and r.bias.counts:
        notes.append(f"faults: {r.bias.counts}")
    if r.technique.finite_variance is False:
        notes.append("infinite variance (analytic)")
    if r.bias and r.bias.stderr == 0:
        notes.append("zero variance")
    if r.case.target is not None:
        hw = r.target_half_width
        reached = hw <= r.case.target
        notes.append(f"target ±{r.case.target:g} {'reached' if reached else 'NOT reached'} at n = {r.bias.n if r.bias else 0} "
                     f"(±{hw:.3g}, look {r.look + 1} of {r.case.looks}, alpha/{r.case.looks} per look)")

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
        "RMSE slope [95% CI]": ([interval(v, lo, hi, "+.2f") + (" slower!" if cv == "slower than expected" else "")
                                 for v, lo, hi, cv in zip(df["slope"], df["slope_lo"], df["slope_hi"], df["convergence"])], "<"),
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
    faults in the contributions, convergence measurably slower than n^-1/2."""
    return df[df["verdict"].isin(["biased", "bias missed", "invalid"]) | (df["convergence"] == "slower than expected")]

