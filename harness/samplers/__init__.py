"""Sampler validation: does a sampler draw what its pdf claims?

Domains and their equal-measure maps, adaptive cubature of the claimed pdf, the chi-square
check with its deterministic pre-checks and marginal and moment tests (``check``), the emcee
cross-check, and the zoo of correct and wrong samplers (``zoo``).
"""
from harness.samplers.check import DOMAINS, Domain, SamplerCheck, SamplerTest, check_sampler, mcmc_crosscheck

__all__ = ["DOMAINS", "Domain", "SamplerCheck", "SamplerTest", "check_sampler", "mcmc_crosscheck"]
