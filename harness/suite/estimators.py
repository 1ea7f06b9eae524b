"""Estimator cases of a suite (``[[case]]``: a catalogue integrand x technique, or a user's
estimator, harness.stats.estimator), as a case kind.

Per case, as its measurements ask: a bias verdict (check_technique's test on independent
batches, Holm-corrected across the suite's estimator cases at its family-wise alpha) and the
per-sample variance from the same batches; a convergence slope of the RMSE over geometric
budgets with a bootstrap interval; the efficiency 1/(V T) as a ratio against the case named
by ``baseline`` (default: uniform Monte Carlo on the same catalogue integrand), and per case
with T in seconds (this run's figure: its interval holds for this run's machine state only)
and in ticks of the reference clock timed beside each replica (harness.stats.timing.CLOCK:
the figure other runs reproduce within its interval); and RMSE against wall time.  A user's
estimator runs serially in the runner's thread (Python code holds the GIL: a parallel run
would time its contention, not the estimator).  A case with a precision target doubles its
bias test's samples (a new "look") until its interval is narrow enough.
"""
from __future__ import annotations

import base64
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

import reference_estimators as rest

from harness import stats
from harness.stats import distributions
from harness.suite.execute import JobResult
from harness.suite.kind import Outcome
from harness.suite.parse import Case, Suite
from harness.suite.plan import (
    Unit,
    bias_budget,
    bias_stream,
    case_key,
    convergence_budgets,
    core_case_id,
    efficiency_stream,
    estimator_units,
    tail_keeps,
    units_per_estimate,
)
from harness.suite.store import Store
from harness.suite.verdicts import family_rejections, mark_xfail
from harness.usercode import load_attr

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["EstimateJob", "CaseResult", "EstimatorKind", "results_table", "format_table"]


def estimator_of(case: Case, base: Path) -> stats.Estimator:
    """The case's estimator: the catalogue pair, or the user's callable loaded from ``base``
    (the suite file's folder) first."""
    if not case.estimator:
        f = rest.integrand(case.integrand)
        return stats.CatalogueEstimator(f, rest.technique(f, case.technique))
    return stats.Contributions(load_attr(case.estimator, base=base), case.dim, case.reference, case.label,
                               case.points, name=case.estimator)


@dataclass(frozen=True)
class EstimateJob:
    """A unit of an estimator case: the accumulator state of its chunk range ("state"; a unit of
    the bias test's batches with ``tail_keep`` > 0 also keeps its contributions' tails, from
    which the tail sample is merged: plan.tail_keeps), or, where those cannot give it exactly,
    the largest deviations above and below the median of the contributions of all the bias
    test's batches read again ("tail", one batch in memory at a time).  ``clock``: a unit of a
    replica the efficiency is measured from reads the reference clock on its thread just
    before it (its payload's "clock", s; not part of the unit's time)."""

    unit: Unit
    case: Case
    base: str          # the suite file's folder: where a user's estimator is loaded from
    seed: int
    core_case: int
    batches: int       # of the bias test: a tail unit reads the contributions of all of them
    clock: bool = False
    tail_keep: int = 0  # order statistics per side a state unit keeps of its contributions' tails

    @property
    def serial(self) -> bool:
        return bool(self.case.estimator)

    def run(self) -> JobResult:
        u = self.unit
        est = estimator_of(self.case, Path(self.base))
        clock = stats.reference_clock() if self.clock else None
        start = time.perf_counter()
        if u.kind == "state":
            payload = est.state(u.budget, u.chunk_begin, u.chunk_end, seed=self.seed, case_id=self.core_case,
                                replica=u.replica, tail_keep=self.tail_keep,
                                tail_median=u.replica == 0 and u.chunk_begin == 0)
            if clock is not None:
                payload = {**payload, "clock": clock}
            if "tails" in payload:
                payload["tails"] = _packed(payload["tails"])
        else:
            tails = stats.TailSample.for_count(u.budget * self.batches)
            for k in range(self.batches):
                y = est.values(u.budget, seed=self.seed, case_id=self.core_case, replica=k)
                if k == 0:  # the centre the state units' tails use: replica 0's first chunk's upper median
                    tails.center = rest.value_tails(y[:rest.CHUNK_SIZE], 0, median=True)["median"]
                tails.add(y)
            payload = tails.state()
        return JobResult(u, payload, time.perf_counter() - start)


@dataclass(frozen=True)
class CaseResult:
    case: Case
    estimator: stats.Estimator
    key: str
    bias: stats.UnbiasedResult | None
    convergence: stats.ConvergenceResult | None  # None if not asked for or zero variance
    efficiency: stats.Efficiency | None          # T in seconds: this run's figure
    variance: tuple[float, float, int] | None    # per-contribution variance, its std. error, n
    error_vs_time: pd.DataFrame | None
    look: int = 0                                # precision targets: the look the bias test stopped at
    clock_efficiency: stats.Efficiency | None = None   # T in reference-clock ticks: across runs

    @property
    def target_half_width(self) -> float:
        """Half-width of the bias test's interval at level 1 - alpha / looks (targets only)."""
        b = self.bias
        if b is None or not math.isfinite(b.stderr):
            return math.nan
        return float(distributions.t_ppf(1 - b.alpha / (2 * self.case.looks), b.df) * b.stderr)


class EstimatorKind:
    """The suite's ``[[case]]`` tables."""

    name = "estimator"

    def __init__(self, suite: Suite):
        self.suite = suite
        self.case_of = {case_key(suite, c): c for c in suite.cases}
        self.looks = {k: 0 for k, c in self.case_of.items() if c.target is not None}
        self.full_tails: set[str] = set()   # cases whose tail sample the state units cannot give
        self.tail_samples: dict[tuple[str, int], stats.TailSample] = {}   # (case key, look): complete

    def names(self) -> list[str]:
        return [f"{c.name}#{c.case_id}" for c in self.suite.cases]

    def register(self, store: Store) -> None:
        for key, c in self.case_of.items():
            definition = {"seed": self.suite.seed, "case_id": c.case_id, "samples": c.samples}
            if c.estimator:
                definition.update(estimator=c.estimator, dim=c.dim, points=c.points, source=c.source)
            store.add_case(key, self.suite.name, c.integrand, c.technique, definition)

    def plan(self, store: Store) -> list[EstimateJob]:
        """The cases' units, interleaved: replica r of every case at one budget, then replica
        r + 1, ..., so a drift of the machine's speed during the run falls on every case alike
        instead of on whichever ran last (the efficiency compares their wall times).  The units
        of the replicas a case's efficiency is measured from read the reference clock."""
        jobs = []
        base = str(self.suite.path.parent)
        for i, (key, c) in enumerate(self.case_of.items()):
            timed = efficiency_stream(self.suite, c)
            look = self.looks.get(key, 0)
            tailed = bias_stream(look) if "bias" in c.measurements else None
            part_keep = tail_keeps(self.suite, c, look)[1]
            for u in estimator_units(self.suite, c, look, full_tail=key in self.full_tails):
                state = u.kind == "state"
                job = EstimateJob(u, c, base, self.suite.seed, core_case_id(c, u.stream), self.suite.batches,
                                  clock=state and (u.stream, u.budget) == timed,
                                  tail_keep=part_keep if state and u.stream == tailed else 0)
                jobs.append((u.stream, u.replica, i, u.chunk_begin, job))
        return [job for *_, job in sorted(jobs, key=lambda j: j[:4])]

    def advance(self, store: Store) -> bool:
        """Plans a tail unit for each case whose state units' tails cannot give its tail sample
        exactly; moves each case with an unreached precision target to its next look."""
        grown = False
        for key, c in self.case_of.items():
            if "bias" in c.measurements and key not in self.full_tails and \
                    self._tails(key, store.payloads(key)) is None:
                self.full_tails.add(key)
                grown = True
        for key, look in self.looks.items():
            c = self.case_of[key]
            payloads = store.payloads(key)
            tails = self._tails(key, payloads) if "bias" in c.measurements else None
            if "bias" in c.measurements and tails is None:
                continue   # its tail unit runs first
            r = _measure(self.suite, c, payloads, look, tails)
            if look + 1 < c.looks and (r.bias is None or not r.target_half_width <= c.target):
                self.looks[key] = look + 1
                grown = True
        return grown

    def _tails(self, key: str, payloads: dict[Unit, dict]) -> stats.TailSample | None:
        """The case's tail sample at its current look (kept once complete: its units do not
        change), or None where it is not yet stored or the state units cannot give it."""
        look = self.looks.get(key, 0)
        if (key, look) not in self.tail_samples:
            t = _tail_sample(self.suite, self.case_of[key], payloads, look)
            if t is None:
                return None
            self.tail_samples[(key, look)] = t
        return self.tail_samples[(key, look)]

    def outcome(self, store: Store) -> Outcome:
        suite = self.suite
        results = []
        for k, c in self.case_of.items():
            payloads = store.payloads(k)
            results.append(_measure(suite, c, payloads, self.looks.get(k, 0), self._tails(k, payloads)))
        table = results_table(results, suite.family_alpha)
        verdicts = [{"bias": row["verdict"], "convergence": row["convergence"]} for row in table]
        failures = [_failure(r, v, suite.family_alpha, len(results)) for r, v in zip(results, verdicts)]
        text = (format_table(table, suite.family_alpha) + "\nt: Student t of the estimate against the exact "
                f"value (over all contributions; over {suite.batches} replicas for stratified and Sobol' "
                "points), p corrected for the estimate's skewness; RMSE slope: log-log fit over budgets "
                "(expected -0.5 for Monte Carlo); 1/(V·T): efficiency (background eq. 5) against uniform MC "
                "on the same integrand (replicas interleaved: the machine's state cancels); "
                "log10 1/(V·T_clock): per case, T in ticks of the reference clock timed beside each "
                "replica, an interval that holds across runs (on this kind of CPU; README); "
                "1/(V·T) in 1/s, harness.load's log10_efficiency: "
                "an interval of this run's machine state only)."
                if results else "")
        return Outcome(self.name, "cases", tuple(self.names()), tuple(results), tuple(verdicts),
                       tuple(failures),
                       tuple(mark_xfail(_rows(suite, results, table),
                                        {k: c.xfail for k, c in self.case_of.items()})),
                       tuple(table), text,
                       tuple(c.xfail for c in suite.cases))


# --- measuring -----------------------------------------------------------------------------------
def _states_by_estimate(payloads: dict[Unit, dict]) -> dict[tuple[int, int, int], list[dict]]:
    """State payloads grouped by (stream, budget, replica), in chunk order (without the
    reference clock's reading)."""
    groups: dict[tuple[int, int, int], list[tuple[int, dict]]] = {}
    for u, p in payloads.items():
        if u.kind == "state":
            state = {k: v for k, v in p.items() if k not in ("clock", "tails")}
            groups.setdefault((u.stream, u.budget, u.replica), []).append((u.chunk_begin, state))
    return {g: [p for _, p in sorted(v, key=lambda x: x[0])] for g, v in groups.items()}


def _clock_of(payloads: dict[Unit, dict], stream: int, budget: int, replicas: int) -> list[float] | None:
    """Per replica of (stream, budget): the mean reference-clock reading of its units (each
    read the clock just before it), or None if any unit has none."""
    readings: dict[int, list[float]] = {}
    for u, p in payloads.items():
        if u.kind == "state" and u.stream == stream and u.budget == budget:
            readings.setdefault(u.replica, []).append(p.get("clock", math.nan))
    clock = [sum(readings.get(r, [math.nan])) / len(readings.get(r, [math.nan])) for r in range(replicas)]
    return clock if all(c > 0 for c in clock) else None


# A unit's tails are stored with each side's values below its peak as base64 of little-endian
# float64 (exact, and about 20x faster to write and read than JSON's decimal floats: with
# hundreds of values per unit they were a tenth of a run's time).
def _packed(tails: dict[str, Any]) -> dict[str, Any]:
    out = dict(tails)
    for side in ("upper", "lower"):
        below = np.asarray(tails[side]["below"], dtype="<f8")
        out[side] = {**tails[side], "below": base64.b64encode(below.tobytes()).decode("ascii")}
    return out


def _unpacked(tails: dict[str, Any]) -> dict[str, Any]:
    out = dict(tails)
    for side in ("upper", "lower"):
        below = np.frombuffer(base64.b64decode(tails[side]["below"]), dtype="<f8")
        out[side] = {**tails[side], "below": below.tolist()}
    return out


def _tail_sample(suite: Suite, case: Case, payloads: dict[Unit, dict], look: int) -> stats.TailSample | None:
    """The bias test's tail sample at look ``look``: from its tail unit where one is stored,
    else merged from its state units' tails (replica 0's first unit first: its median is the
    centre); None where those cannot give it exactly (or are not all stored)."""
    b, stream = bias_budget(suite, case, look), bias_stream(look)
    parts = []
    for u, p in payloads.items():
        if u.stream == stream and u.budget == b:  # not a tail stored for an earlier sample count
            if u.kind == "tail":
                return stats.TailSample.from_state(p)
            if u.kind == "state" and "tails" in p:
                parts.append(((u.replica, u.chunk_begin), _unpacked(p["tails"])))
    if len(parts) != suite.batches * units_per_estimate(b):
        return None
    keep, part_keep = tail_keeps(suite, case, look)
    return stats.TailSample.from_parts([t for _, t in sorted(parts, key=lambda x: x[0])], keep, part_keep)


def _measure(suite: Suite, case: Case, payloads: dict[Unit, dict], look: int = 0,
             tails: stats.TailSample | None = None) -> CaseResult:
    """The case's measurements from its stored units; ``tails``: the bias test's tail sample
    (:func:`_tail_sample`), needed where the case measures bias."""
    est = estimator_of(case, suite.path.parent)
    key = case_key(suite, case)
    wanted = set(case.measurements)
    states = _states_by_estimate(payloads)

    def estimate(stream: int, budget: int, replica: int) -> rest.Estimate:
        return est.from_states(states[(stream, budget, replica)])

    bias = variance = conv = eff = clock_eff = evt = None
    if wanted & {"bias", "variance"}:
        b, stream = bias_budget(suite, case, look), bias_stream(look)
        batches = [estimate(stream, b, k) for k in range(suite.batches)]
        faults = {k: v for e in batches for k, v in e.issues.items()}
        if "bias" in wanted:
            if tails is None:
                raise RuntimeError(f"{case.name}: the bias test's tail sample is missing at look {look} "
                                   "(advance() plans its tail unit first)")
            if faults:
                first = next(e for e in batches if e.issues)
                bias = stats.UnbiasedResult.invalid(faults, first.examples, reference=est.reference,
                                                    n=b * suite.batches, alpha=suite.family_alpha,
                                                    batches=suite.batches)
            else:
                bias = stats.judge_batches(batches, tails, est.reference, suite.family_alpha, iid=est.iid)
            if case.looks > 1 and bias.verdict != "invalid" and not bias.undecided:
                # alpha spent over the looks a target may take (Bonferroni: any dependence, any
                # stopping rule): the final look's p-value times the number of looks
                bias = bias.with_pvalue(min(1.0, bias.pvalue * case.looks))
        if "variance" in wanted and not faults and est.iid:
            reps = stats.Replicates.from_estimates(est, b, batches)
            rel = math.sqrt(max(reps.sample_kurtosis - 1, 0.0) / (reps.replicas * b))
            variance = (reps.sample_variance, reps.sample_variance * rel, reps.replicas * b)
    budgets = convergence_budgets(suite, case)
    timed = efficiency_stream(suite, case)
    reps_by_budget = {}
    for i, b in enumerate(budgets):
        if (1 + i, b, 0) in states:
            clock = _clock_of(payloads, 1 + i, b, suite.replicas) if (1 + i, b) == timed else None
            reps_by_budget[b] = stats.Replicates.from_estimates(
                est, b, [estimate(1 + i, b, r) for r in range(suite.replicas)], clock=clock)
    if reps_by_budget:
        top = reps_by_budget[max(reps_by_budget)]
        if top.rmse > 0 and "efficiency" in wanted:
            tail = bias.tail_index if bias is not None and bias.verdict != "invalid" else None
            eff = stats.efficiency(top, tail_index=tail, finite_variance=est.finite_variance)
            if top.clock is not None:
                clock_eff = stats.efficiency(top, tail_index=tail, finite_variance=est.finite_variance,
                                             clock=True)
        if "convergence" in wanted and len(reps_by_budget) >= 3 and top.rmse > 0:
            conv = stats.fit_convergence(list(reps_by_budget.values()), seed=suite.seed)
        if "error_vs_time" in wanted:
            import pandas as pd  # deferred, as in kind.Outcome.frame
            evt = pd.DataFrame([{"n": r.n, "rmse": r.rmse, "rmse_lo": r.rmse_interval()[0],
                                 "rmse_hi": r.rmse_interval()[1], "seconds": r.time[0],
                                 "seconds_se": r.time[1], "replicas": r.replicas}
                                for r in reps_by_budget.values()])
    return CaseResult(case, est, key, bias, conv, eff, variance, evt, look, clock_eff)


# --- verdicts --------------------------------------------------------------------------------------
def _judge_convergence(results: list[CaseResult], alpha: float) -> list[str]:
    """Convergence verdict per case, Holm over the suite's judged cases at family-wise
    alpha: 'as expected', 'slower than expected', or 'not judged' where no rate is promised
    (infinite variance, heavy tails seen by the bias test, or an estimate that is skewed at the
    smallest budget: pre-asymptotic) or the technique is biased on purpose (its error stops
    falling at the bias)."""
    def pre_asymptotic(r: CaseResult) -> bool:
        b, smallest = r.bias, int(r.convergence.table.n.min())
        return b is not None and (bool(b.flags) or b.tail_index < 3 or not b.normal_at(smallest))

    judged = [r.convergence is not None and not r.estimator.biased
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


def _failure(r: CaseResult, verdicts: dict[str, str], alpha: float, family: int) -> str:
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
def _rows(suite: Suite, results: list[CaseResult], table: list[dict[str, Any]]) -> list[dict[str, Any]]:
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
            v, se, n = r.variance
            rows.append({**base, "measurement": "variance", "value": v, "lo": v - 1.96 * se,
                         "hi": v + 1.96 * se, "n": n})
        if r.convergence is not None:
            c = r.convergence
            lo, hi = c.confidence_interval()
            rows.append({**base, "measurement": "convergence_slope", "value": c.slope, "lo": lo, "hi": hi,
                         "n": c.n, "pvalue": c.pvalue,
                         "verdict": row["convergence"],
                         "detail": {"expected": c.expected, "bound": c.expected + c.tolerance,
                                    "z": c.statistic, "table": c.table.to_dict("list")}})
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
