"""The harness: is a Monte Carlo estimator unbiased, does a sampler draw what its pdf claims,
does a renderer converge, and which technique reaches an error first.

The public API, one import away::

    import harness
    harness.check_unbiased(contributions, dim, reference, sample_count=10**6)   # a bias test
    harness.check_sampler(sample, pdf, "hemisphere", sample_count=10**6)         # a sampler test
    harness.mcmc_crosscheck(sample, pdf, "sphere")                               # emcee cross-check
    summary = harness.run_suite(harness.load_suite("suites/ci.toml"), "results/ci.sqlite")
    harness.load("results/ci.sqlite")                                            # a DataFrame
    harness.record("results/mine.sqlite", {"nee": result})      # Python-API results, for `harness report`

Every check returns a result of one family (``verdict``, ``passed``, ``pvalue``, ``alpha``,
``n``, ``confidence_interval()``, ``failures``; see harness.stats.results).  Sub-packages:
``harness.stats`` (statistics), ``harness.samplers`` (sampler validation), ``harness.suite``
(suite files, plan, execution, storage, the runner) and ``harness.adapters`` (renderers).

The names load on first use (PEP 562), so ``harness run`` on a finished suite imports only
what it needs: the whole API at once costs about a second (scipy.stats, emcee, pandas).
"""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

# name -> the module it comes from
_HOME = {
    "check_sampler": "harness.samplers", "SamplerCheck": "harness.samplers",
    "mcmc_crosscheck": "harness.samplers",
    "check_unbiased": "harness.stats", "Contributions": "harness.stats", "UnbiasedResult": "harness.stats",
    "ConvergenceResult": "harness.stats", "Efficiency": "harness.stats",
    "ConfidenceInterval": "harness.stats", "Failure": "harness.stats",
    "ImageBias": "harness.stats.images",
    "Outcome": "harness.suite.kind",
    "Case": "harness.suite.parse", "Suite": "harness.suite.parse", "SuiteError": "harness.suite.parse",
    "load_suite": "harness.suite.parse", "loads_suite": "harness.suite.parse",
    "load": "harness.suite.readers", "record": "harness.suite.record",
    "RunSummary": "harness.suite.run", "run_suite": "harness.suite.run",
}
_SUBPACKAGES = ("stats", "samplers", "suite", "adapters")

__all__ = ["check_unbiased", "check_sampler", "mcmc_crosscheck", "load", "load_suite", "loads_suite",
           "record", "run_suite", "Contributions", "Suite", "Case", "SuiteError", "RunSummary", "Outcome",
           "UnbiasedResult", "ConvergenceResult", "Efficiency", "ImageBias", "SamplerCheck",
           "ConfidenceInterval", "Failure"]


def __getattr__(name: str) -> Any:
    if name in _SUBPACKAGES:
        return importlib.import_module(f"harness.{name}")
    if name not in _HOME:
        raise AttributeError(f"module 'harness' has no attribute {name!r}")
    value = getattr(importlib.import_module(_HOME[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__, *_SUBPACKAGES})


if TYPE_CHECKING:  # what the names are, for type checkers and editors
    from harness.samplers import SamplerCheck, check_sampler, mcmc_crosscheck
    from harness.stats import (
        ConfidenceInterval,
        Contributions,
        ConvergenceResult,
        Efficiency,
        Failure,
        UnbiasedResult,
        check_unbiased,
    )
    from harness.stats.images import ImageBias
    from harness.suite.kind import Outcome
    from harness.suite.parse import Case, Suite, SuiteError, load_suite, loads_suite
    from harness.suite.readers import load
    from harness.suite.record import record
    from harness.suite.run import RunSummary, run_suite
