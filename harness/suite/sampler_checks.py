"""Sampler checks of a suite (``[[sampler]]``: a catalogue sampler, or a renderer's sampler
through its adapter), as a case kind.

Each measurement of a check (``chi_square``, ``mcmc``, ``weight``) is one stored unit.  The
p-values of all the suite's checks are Holm-corrected together at its family-wise alpha; a
deterministic failure (points outside the domain, a pdf that does not integrate to 1, ...)
always fails.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from typing import Any

import reference_estimators as rest

from harness.suite.execute import JobResult
from harness.suite.kind import Outcome
from harness.suite.parse import SamplerCase, Suite
from harness.suite.plan import Unit, sampler_key, sampler_spec, sampler_units
from harness.suite.store import Store
from harness.suite.verdicts import family_rejections, mark_xfail

__all__ = ["SamplerJob", "SamplerResult", "SamplerKind"]


@dataclass(frozen=True)
class SamplerJob:
    """One measurement of a sampler check; ``spec`` is the sampler's JSON (plan.sampler_spec)."""

    unit: Unit
    spec: str
    seed: int

    @property
    def serial(self) -> bool:
        """A user's sampler runs in the runner's thread (Python code holds the GIL)."""
        return bool(json.loads(self.spec)["target"])

    def run(self) -> JobResult:
        from harness.samplers import check_sampler, mcmc_crosscheck

        kind, spec = self.unit.kind, json.loads(self.spec)
        start = time.perf_counter()
        if spec.get("adapter"):  # a renderer's sampler, which may fail to produce samples
            from harness.adapters.mitsuba.checks import check_mitsuba_sampler, weight_consistency
            from harness.adapters.mitsuba.samplers import make_sampler

            check = weight_consistency if kind == "weight" else check_mitsuba_sampler
            r = check(make_sampler(spec["spec"]), sample_count=spec["samples"], seed=self.seed)
        elif spec["target"]:  # a user's sampler
            from pathlib import Path

            from harness.samplers.user import resolve_sampler
            from harness.usercode import load_attr

            user = resolve_sampler(load_attr(spec["target"], base=Path(spec["base"])), spec["params"],
                                   name=spec["target"])
            check = check_sampler if kind == "chi_square" else mcmc_crosscheck
            extra = {"total": spec["total"], "breaks": user.breaks} if kind == "chi_square" else {}
            r = check(user.sample, user.pdf, user.check_domain(spec["domain"]), seed=self.seed,
                      udim=spec["udim"],
                      sample_count=spec["samples"] if kind == "chi_square" else min(spec["samples"], 20_000),
                      **extra)
        elif kind == "chi_square":
            s = rest.sampler(spec["name"], **spec["params"])
            r = check_sampler(lambda u: s.sample(u)[0], s.pdf, spec["domain"], sample_count=spec["samples"],
                              seed=self.seed)
        else:
            s = rest.sampler(spec["name"], **spec["params"])
            r = mcmc_crosscheck(lambda u: s.sample(u)[0], s.pdf, spec["domain"],
                                sample_count=min(spec["samples"], 20_000), seed=self.seed)
        return JobResult(self.unit, r.to_payload(), time.perf_counter() - start)


@dataclass(frozen=True)
class SamplerResult:
    case: SamplerCase
    key: str
    checks: dict[str, dict[str, Any]]   # measurement -> stored payload (passed, pvalue, tests, failures)


class SamplerKind:
    """The suite's ``[[sampler]]`` tables."""

    name = "sampler"

    def __init__(self, suite: Suite):
        self.suite = suite
        self.sampler_of = {sampler_key(suite, sc): sc for sc in suite.samplers}

    def names(self) -> list[str]:
        return [f"sampler:{sc.label}@{sc.domain}#{sc.case_id}" for sc in self.suite.samplers]

    def register(self, store: Store) -> None:
        for key, sc in self.sampler_of.items():
            store.add_case(key, self.suite.name, f"sampler:{sc.label}", sc.domain,
                           {"seed": self.suite.seed, "samples": sc.samples})

    def plan(self, store: Store) -> list[SamplerJob]:
        return [SamplerJob(u, sampler_spec(self.suite, sc), self.suite.seed)
                for sc in self.suite.samplers for u in sampler_units(self.suite, sc)]

    def advance(self, store: Store) -> bool:
        return False

    def outcome(self, store: Store) -> Outcome:
        suite = self.suite
        results = [SamplerResult(sc, k, {u.kind: p for u, p in store.payloads(k).items()})
                   for k, sc in self.sampler_of.items()]
        verdicts, adjusted = _judge(results, suite.family_alpha)
        failures = [_failure(r, v, adj, suite.family_alpha) for r, v, adj in zip(results, verdicts, adjusted)]
        table = tuple({"sampler": r.case.label, "domain": r.case.domain, "n": r.case.samples,
                       **{f"{m}_pvalue": c["pvalue"] for m, c in r.checks.items()},
                       **{f"{m}_verdict": v[m] for m in r.checks}}
                      for r, v in zip(results, verdicts))
        text = ("sampler checks (chi-square and friends; MCMC cross-check):\n"
                + _format_table(results, verdicts, suite.family_alpha) if results else "")
        return Outcome(self.name, "sampler checks", tuple(self.names()), tuple(results), tuple(verdicts),
                       tuple(failures),
                       tuple(mark_xfail(_rows(suite, results, verdicts),
                                        {k: sc.xfail for k, sc in self.sampler_of.items()})), table, text,
                       tuple(sc.xfail for sc in suite.samplers))


def _judge(results: list[SamplerResult], alpha: float) -> tuple[list[dict[str, str]], list[dict[str, float]]]:
    """Verdict per sampler check ('passed', 'failed' or 'inconclusive': an MCMC chain too
    short for its autocorrelation time, which fails no run; deterministic failures always fail)
    and its Holm-adjusted p-value, Holm over all of the suite's checks at family-wise alpha."""
    flat = [(i, m, c) for i, r in enumerate(results) for m, c in r.checks.items()]
    pvalues = [c["pvalue"] for _, _, c in flat]
    rejected, adjusted = family_rejections(pvalues, alpha)
    verdicts: list[dict[str, str]] = [{} for _ in results]
    adj_of: list[dict[str, float]] = [{} for _ in results]
    for (i, m, c), rej, adj in zip(flat, rejected, adjusted):
        failed = rej or c["failures"]
        verdicts[i][m] = "failed" if failed else "inconclusive" if c.get("inconclusive") else "passed"
        adj_of[i][m] = adj
    return verdicts, adj_of


def _failure(r: SamplerResult, verdicts: dict[str, str], adjusted: dict[str, float], alpha: float) -> str:
    """Why a sampler check fails ("" if it passes): each failed measurement with its p-value,
    its deterministic failures and its sub-tests."""
    problems = []
    for m, c in r.checks.items():
        if verdicts[m] != "failed":
            continue
        tests = "\n".join(f"    {t['test']}: statistic {t['statistic']:.4g}, p {t['pvalue']:.3g}, "
                          f"detects {t['detects']}" for t in c["tests"])
        fails = "".join(f"\n  {f['check']}: {f['count']} ({f['detail']}), e.g. {f['examples'][:2]}"
                        for f in c["failures"])
        problems.append(f"{m}: p = {c['pvalue']:.3g} (Holm-adjusted over the suite: {adjusted[m]:.3g}), "
                        f"family-wise alpha = {alpha:.3g}, {r.case.samples} samples on the {r.case.domain}; "
                        f"expected: the sampler draws what its pdf claims{fails}\n{tests}")
    return "\n".join(problems)


def _rows(suite: Suite, results: list[SamplerResult], verdicts: list[dict[str, str]]) -> list[dict[str, Any]]:
    rows = []
    for r, v in zip(results, verdicts):
        for m, c in r.checks.items():
            rows.append({"case_key": r.key, "suite": suite.name, "integrand": f"sampler:{r.case.label}",
                         "technique": r.case.domain, "measurement": m, "value": c["pvalue"],
                         "n": r.case.samples, "pvalue": c["pvalue"], "alpha": suite.family_alpha,
                         "verdict": v[m],
                         "detail": {"tests": c["tests"], "failures": c["failures"],
                                    "normalization": c["normalization"], "residuals": c.get("residuals", {}),
                                    "marginals": c.get("marginals", {})}})
    return rows


def _format_table(results: list[SamplerResult], verdicts: list[dict[str, str]], alpha: float) -> str:
    """Sampler checks as aligned text: p-values (within-check Holm), suite verdicts (Holm)."""
    width = max([34] + [len(r.case.label) for r in results])
    lines = [f"{'sampler':{width}s} {'domain':10s} {'n':>7s}  {'chi-square p':>12s}  {'mcmc p':>8s}  "
             f"{'weight':>8s}  verdict (Holm, α={alpha:.3g})"]
    for r, v in zip(results, verdicts):
        cs, mc = r.checks.get("chi_square"), r.checks.get("mcmc")
        verdict = next((w for w in ("failed", "inconclusive") if w in v.values()), "passed")
        notes = "; ".join([f"{f['check']}: {f['count']}" for c in r.checks.values() for f in c["failures"]]
                          + [c["inconclusive"] for c in r.checks.values() if c.get("inconclusive")])
        p_cs = f"{cs['pvalue']:.3g}" if cs else "—"
        p_mc = f"{mc['pvalue']:.3g}" if mc else "—"
        w = r.checks.get("weight")
        weight = "—" if w is None else ("ok" if not w["failures"] else "mismatch")
        lines.append(f"{r.case.label:{width}s} {r.case.domain:10s} {r.case.samples:7.0e}  {p_cs:>12s}  "
                     f"{p_mc:>8s}  {weight:>8s}  {verdict}{'  ' + notes if notes else ''}")
    return "\n".join(lines)
