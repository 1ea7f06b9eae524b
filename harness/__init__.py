"""The harness: statistics, suites, the runner and its storage."""
from harness.suite.store import load
from harness.suite.parse import Case, Suite, SuiteError, load_suite

__all__ = ["Case", "Suite", "SuiteError", "load", "load_suite"]
