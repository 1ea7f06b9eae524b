"""pytest plugin: ``pytest suites/ci.toml`` collects each case of a suite file as a test item.

The suite runs once per session (stored in the pytest cache, so a rerun only computes what
changed); each item then checks its case: no faults, the bias verdict expected for its
technique (Holm-corrected over the suite at the suite's alpha), and a convergence slope not
measurably worse than n^-1/2.  A failure shows the measurement, its interval, n, alpha and
what was expected.
"""
from __future__ import annotations

import math
import tomllib
from pathlib import Path

import pytest

from harness.suite.renders import render_failures
from harness.suite.run import RunSummary, judge, judge_convergence, judge_samplers, run_suite
from harness.suite.parse import Suite, SuiteError, load_suite


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("harness")
    group.addoption("--harness-db", default=None, help="results database for suite files (default: in the pytest cache)")
    group.addoption("--harness-threads", type=int, default=None, help="threads for suite files")


def pytest_collect_file(file_path: Path, parent: pytest.Collector):
    if file_path.suffix == ".toml" and _is_suite(file_path):
        return SuiteFile.from_parent(parent, path=file_path)
    return None


def _is_suite(path: Path) -> bool:
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError):
        return False
    return "suite" in data or "case" in data or "render" in data


class SuiteFile(pytest.File):
    def collect(self):
        try:
            suite = load_suite(self.path)
        except SuiteError as e:
            raise self.CollectError(str(e)) from None
        self.suite = suite
        self.summary: RunSummary | None = None
        for i, case in enumerate(suite.cases):
            yield CaseItem.from_parent(self, name=f"{case.integrand}/{case.technique}#{case.case_id}", index=i)
        for i, sc in enumerate(suite.samplers):
            yield SamplerItem.from_parent(self, name=f"sampler:{sc.label}@{sc.domain}#{sc.case_id}", index=i)
        for i, rc in enumerate(suite.renders):
            yield RenderItem.from_parent(self, name=f"render:{rc.scene}/{rc.label}#{rc.case_id}", index=i)

    def run(self) -> RunSummary:
        if self.summary is None:
            opt = self.config.getoption
            db = opt("--harness-db") or (self.config.cache.mkdir("harness") / f"{self.suite.name}.sqlite"
                                         if self.config.cache else Path(f"results/{self.suite.name}.sqlite"))
            self.summary = run_suite(self.suite, db, threads=opt("--harness-threads"))
        return self.summary


class CaseFailure(Exception):
    pass


class CaseItem(pytest.Item):
    def __init__(self, *, index: int, **kwargs):
        super().__init__(**kwargs)
        self.index = index

    def runtest(self) -> None:
        summary = self.parent.run()
        suite: Suite = self.parent.suite
        r = summary.results[self.index]
        verdict = judge(summary.results, suite.alpha)[self.index]
        problems = []
        b = r.bias
        if b is not None:
            head = (f"bias: estimate {b.estimate:.10g} ± {b.stderr:.3g} (n = {b.n}), exact {b.reference:.10g}, "
                    f"t = {b.statistic:+.2f}, p = {b.pvalue:.3g}, family-wise alpha = {suite.alpha} "
                    f"(Holm over {len(summary.results)} cases)")
            if math.isfinite(b.stderr):
                lo, hi = b.confidence_interval(1 - suite.alpha)
                head += f", {100 * (1 - suite.alpha):g} % CI [{lo:.10g}, {hi:.10g}]"
            expected = "biased (deliberately)" if r.technique.biased else "unbiased"
            if verdict in ("biased", "bias missed", "invalid"):
                problems.append(f"{head}\n  verdict: {verdict}; expected: {expected}"
                                + (f"\n  faults: {b.counts}, first: {b.examples[:3]}" if b.counts else "")
                                + (f"\n  flags: {'; '.join(b.flags)}" if b.flags else ""))
        c = r.convergence
        if judge_convergence(summary.results, suite.alpha)[self.index] == "slower than expected":
            problems.append(f"convergence: {c}; one-sided p = {c.pvalue:.3g}, family-wise alpha = {suite.alpha} "
                            f"(Holm)\n{c.table.to_string(index=False)}")
        if problems:
            raise CaseFailure("\n".join(problems))

    def repr_failure(self, excinfo, style=None):
        if isinstance(excinfo.value, CaseFailure):
            return f"{self.name}: {excinfo.value}"
        return super().repr_failure(excinfo, style)

    def reportinfo(self):
        return self.path, None, f"suite case {self.name}"


class SamplerItem(CaseItem):
    """A [[sampler]] table: its chi-square (and MCMC) checks must pass, Holm over the suite."""

    def runtest(self) -> None:
        summary = self.parent.run()
        suite: Suite = self.parent.suite
        r = summary.samplers[self.index]
        verdicts = judge_samplers(summary.samplers, suite.alpha)[self.index]
        problems = []
        for m, c in r.checks.items():
            if verdicts[m] == "failed":
                tests = "\n".join(f"    {t['test']}: statistic {t['statistic']:.4g}, p {t['pvalue']:.3g}, "
                                   f"detects {t['detects']}" for t in c["tests"])
                fails = "".join(f"\n  {f['check']}: {f['count']} ({f['detail']}), e.g. {f['examples'][:2]}"
                                for f in c["failures"])
                problems.append(f"{m}: p = {c['pvalue']:.3g} (Holm-adjusted over the suite: {verdicts[m + '_adjusted']}), "
                                f"family-wise alpha = {suite.alpha}, {r.case.samples} samples; expected: the sampler "
                                f"draws what its pdf claims{fails}\n{tests}")
        if problems:
            raise CaseFailure("\n".join(problems))


class RenderItem(CaseItem):
    """A [[render]] configuration: its expected bias verdict (per-pixel test, Holm over the
    suite's renders), no invalid pixels, and a relMSE not converging slower than spp^-1/2."""

    def runtest(self) -> None:
        summary = self.parent.run()
        why = render_failures(summary.renders, self.parent.suite.alpha)[self.index]
        if why:
            raise CaseFailure(why)
