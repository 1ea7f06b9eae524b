"""Sampler validation: does a sampler draw what its pdf claims?

Domains and their equal-measure maps (``domains``), adaptive cubature of the claimed pdf over
many cells at once (``cubature``), the chi-square check with its deterministic pre-checks and
marginal and moment tests (``check``) and its outcome (``result``), the Rosenblatt transform's
tests below the bin width (``transform``) and their CDF tables (``cdf_tables``), the user's
sample and pdf called with their results checked (``calls``), the emcee cross-check
(``mcmc``), and the zoo of correct and wrong samplers (``zoo``).  ``mcmc_crosscheck`` loads on
first use (it imports emcee and scipy.stats).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

from harness.samplers.check import (
    SAMPLE_CASE,
    SamplerTest,
    check_sampler,
    check_with_missing,
    failure_pvalue,
    histogram,
)
from harness.samplers.cubature import cell_integrals
from harness.samplers.domains import DOMAINS, Domain, Float32DirectionPdf, as_domain
from harness.samplers.result import SamplerCheck

if TYPE_CHECKING:
    from harness.samplers.mcmc import mcmc_crosscheck

__all__ = ["DOMAINS", "SAMPLE_CASE", "Domain", "Float32DirectionPdf", "SamplerCheck", "SamplerTest",
           "as_domain", "cell_integrals", "check_sampler", "check_with_missing", "failure_pvalue",
           "histogram", "mcmc_crosscheck"]


def __getattr__(name: str) -> Any:
    if name == "mcmc_crosscheck":
        from harness.samplers.mcmc import mcmc_crosscheck

        return mcmc_crosscheck
    raise AttributeError(f"module 'harness.samplers' has no attribute {name!r}")
