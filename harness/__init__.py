"""The harness: statistics, suites, the runner and its storage."""
from .store import load
from .suite import Case, Suite, SuiteError, load_suite

__all__ = ["Case", "Suite", "SuiteError", "load", "load_suite"]
