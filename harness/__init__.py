"""The harness: suites, runners and (soon) the statistics that judge Monte Carlo estimators."""
from .suite import Case, Suite, SuiteError, load_suite

__all__ = ["Case", "Suite", "SuiteError", "load_suite"]
