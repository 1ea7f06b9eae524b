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
"""
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

__all__ = ["check_unbiased", "check_sampler", "mcmc_crosscheck", "load", "load_suite", "loads_suite",
           "record", "run_suite", "Contributions", "Suite", "Case", "SuiteError", "RunSummary", "Outcome",
           "UnbiasedResult", "ConvergenceResult", "Efficiency", "ImageBias", "SamplerCheck",
           "ConfidenceInterval", "Failure"]
