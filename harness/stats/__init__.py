"""Statistics of Monte Carlo estimates: bias tests, tail estimation, multiple testing,
replicas, convergence and efficiency (``bias``), image statistics (``images``) and the
calibration zoo of correct and subtly wrong estimators (``zoo``).

Every figure here carries its uncertainty and its sample count; every test states its
false-alarm rate and what it detects.
"""
from harness.stats.bias import *  # noqa: F403
from harness.stats.bias import __all__ as _bias_all
from harness.stats.results import ConfidenceInterval, Failure

__all__ = [*_bias_all, "ConfidenceInterval", "Failure"]
