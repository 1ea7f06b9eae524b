"""pytest plugin: ``pytest suites/ci.toml`` collects each case of a suite file as a test item.

Suite files are collected when named on the command line or when they match the ini option
``harness_suites`` (glob patterns relative to the rootdir; default ``suites/*.toml``).

The suite runs once per session (stored in the pytest cache, so a rerun only computes what
changed); each item then checks its case, whatever its kind (estimator, sampler check,
render): no faults, the bias verdict expected for it (Holm-corrected over the suite at the
suite's alpha), sampler checks passing, and a convergence slope not measurably worse than
n^-1/2.  A failure shows the measurement, its interval, n, alpha and what was expected.  A
case with an ``xfail`` reason is reported as xfailed while it fails, and fails (strict) once
it passes.
"""
from __future__ import annotations

import tomllib
from pathlib import Path, PurePosixPath

import pytest

from harness.adapters.base import RenderError
from harness.suite.execute import ClusterError
from harness.suite.parse import SuiteError, load_suite
from harness.suite.run import RunSummary, kinds_of, run_suite
from harness.suite.store import StoreError
from harness.usercode import UserCodeError


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("harness")
    group.addoption("--harness-db", default=None,
                    help="results database for suite files (default: in the pytest cache)")
    group.addoption("--harness-threads", type=int, default=None, help="threads for suite files")
    parser.addini("harness_suites", type="args", default=["suites/*.toml"],
                  help="glob patterns, relative to the rootdir, of the suite files pytest collects "
                       "(a suite file named on the command line is always collected)")


def pytest_collect_file(file_path: Path, parent: pytest.Collector):
    if file_path.suffix == ".toml" and _wanted(file_path, parent.config) and _is_suite(file_path):
        return SuiteFile.from_parent(parent, path=file_path)
    return None


def _wanted(path: Path, config: pytest.Config) -> bool:
    """Named on the command line, or matching one of the ``harness_suites`` patterns (so a
    scratch .toml elsewhere in the repository never breaks collection)."""
    named = {Path(a.split("::")[0]).resolve() for a in config.args}
    if path.resolve() in named:
        return True
    try:
        relative = PurePosixPath(path.resolve().relative_to(config.rootpath.resolve()).as_posix())
    except ValueError:  # outside the rootdir
        return False
    # anchored at the rootdir: "suites/*.toml" is not "tests/data/suites/x.toml"
    return any(relative.match(pattern) and len(relative.parts) == len(PurePosixPath(pattern).parts)
               for pattern in config.getini("harness_suites"))


def _is_suite(path: Path) -> bool:
    """Whether ``path`` holds a suite: a TOML file with any of a suite's tables.  A file that is
    no TOML (or not UTF-8) is not one: it is left alone, not an error that stops the session."""
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False
    return any(table in data for table in ("suite", "case", "render", "sampler"))


class SuiteFile(pytest.File):
    def collect(self):
        try:
            suite = load_suite(self.path)
        except SuiteError as e:
            raise self.CollectError(str(e)) from None
        self.suite = suite
        self.summary: RunSummary | None = None
        self.error: str | None = None
        for kind in kinds_of(suite):
            for i, name in enumerate(kind.names()):
                yield CaseItem.from_parent(self, name=name, kind=kind.name, index=i)

    def teardown(self) -> None:
        """After the file's last case: the suite and its results go (they hold the core's
        integrands and techniques, which pytest's tree of collected items would keep to the end
        of the process, past the core's own teardown: nanobind reported them as leaked)."""
        self.suite, self.summary = None, None

    def run(self) -> RunSummary:
        """The suite's run, made once for all its cases; a run that stopped (a team's code
        failing, the database, a render) is a RunFailure for every case, raised from that one
        attempt, not a new run per case."""
        if self.error is not None:
            raise RunFailure(self.error)
        if self.summary is None:
            opt = self.config.getoption
            cache = getattr(self.config, "cache", None)  # None under -p no:cacheprovider
            db = opt("--harness-db") or (cache.mkdir("harness") / f"{self.suite.file_name}.sqlite" if cache
                                         else Path(f"results/{self.suite.file_name}.sqlite"))
            try:
                self.summary = run_suite(self.suite, db, threads=opt("--harness-threads"))
            except (UserCodeError, RenderError, StoreError, ClusterError) as e:
                self.error = f"the suite's run stopped: {e} (units stored in {db} are kept; fix it and rerun)"
                raise RunFailure(self.error) from None
        return self.summary


class CaseFailure(Exception):
    pass


class RunFailure(Exception):
    """The suite's run stopped before its cases could be judged."""


class CaseItem(pytest.Item):
    """One case of a suite file, of any kind: it fails with the kind's explanation (what was
    measured, its interval, n, alpha and what was expected)."""

    def __init__(self, *, kind: str, index: int, **kwargs):
        super().__init__(**kwargs)
        self.kind, self.index = kind, index

    def runtest(self) -> None:
        outcome = self.parent.run()[self.kind]
        if outcome.status(self.index) == "xfailed":
            pytest.xfail(f"{outcome.xfail[self.index]}\n{outcome.failures[self.index]}")
        why = outcome.problem(self.index)
        if why:
            raise CaseFailure(why)

    def repr_failure(self, excinfo, style=None):
        if isinstance(excinfo.value, (CaseFailure, RunFailure)):
            return f"{self.name}: {excinfo.value}"
        return super().repr_failure(excinfo, style)

    def reportinfo(self):
        return self.path, None, f"suite {self.kind} {self.name}"
