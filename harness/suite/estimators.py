"""Estimator cases of a suite (``[[case]]``: a catalogue integrand x technique, or a user's
estimator, harness.stats.estimator), as a case kind.

Per case, as its measurements ask: a bias verdict (check_technique's test on independent
batches, Holm-corrected across the suite's estimator cases at its family-wise alpha) and the
per-sample variance from the same batches; a convergence slope of the RMSE over geometric
budgets with a permutation-test interval; the efficiency 1/(V T) as a ratio against the case named
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
from harness.stats.results import summed_counts
from harness.suite.estimator_tables import failure, format_table, results_table, store_rows
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
from harness.suite.verdicts import mark_xfail
from harness.usercode import load_attr

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["EstimateJob", "CaseResult", "EstimatorKind"]


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
        failures = [failure(r, v, suite.family_alpha, len(results)) for r, v in zip(results, verdicts)]
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
                       tuple(mark_xfail(store_rows(suite, results, table),
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
        faults = summed_counts(e.issues for e in batches)
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
