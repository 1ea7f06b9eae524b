"""Statistics of Monte Carlo estimates, one job a module:

``bias``      is an estimator unbiased (check_unbiased, check_technique, judge_batches, batch_points);
``tails``     the tail index of the contributions and how a tail ends: clamp, truncation (TailSample);
``multiple``  multiple testing (holm);
``estimator`` what estimates come from: a catalogue pair or a user's contributions callable;
``replicas``  replicas, convergence rates, error against time;
``efficiency`` the efficiency 1/(V T) of replicates and the ratio of two;
``timing``    an estimate's wall time and its error from blocks of replicas (median_time), in
              seconds or in ticks of the reference clock (clock_time, reference_clock);
``results``   the result family every check returns (ConfidenceInterval, Failure);
``merge``     Chan's merge of (count, mean, variance) summaries, with the third moment;
``validate``  argument validators shared across the harness;
``images``    image statistics (imported as ``harness.stats.images``);
``zoo``       the calibration zoo of correct and subtly wrong estimators (``harness.stats.zoo``).

Every figure here carries its uncertainty and its sample count; every test states its
false-alarm rate and what it detects.
"""
from harness.stats.bias import UnbiasedResult, batch_points, check_technique, check_unbiased, judge_batches
from harness.stats.convergence import ConvergenceResult, convergence_rate, fit_convergence
from harness.stats.efficiency import Efficiency, efficiency, efficiency_ratio
from harness.stats.estimator import CatalogueEstimator, Contributions, Estimator, estimator
from harness.stats.multiple import holm
from harness.stats.replicas import Replicates, error_vs_time, replicate
from harness.stats.results import ConfidenceInterval, Failure, failure_counts, failures_from_counts
from harness.stats.tails import TailSample
from harness.stats.timing import CLOCK, clock_time, median_time, reference_clock

__all__ = [
    "Estimator", "CatalogueEstimator", "Contributions", "estimator",
    "UnbiasedResult", "check_unbiased", "check_technique", "judge_batches", "batch_points", "TailSample",
    "holm",
    "Replicates", "replicate", "median_time", "clock_time", "reference_clock", "CLOCK",
    "ConvergenceResult", "convergence_rate", "fit_convergence",
    "Efficiency", "efficiency", "efficiency_ratio", "error_vs_time",
    "ConfidenceInterval", "Failure", "failure_counts", "failures_from_counts",
]
