"""Chan's merge of summaries (count, mean, variance) into one count, mean and sum of squared
deviations, in a fixed order: how the bias test pools a batch's pieces and how replicas pool
their per-sample variance.

Not the core's ``merge_states``: that one merges raw accumulator states (compensated sums,
M2..M4, a power-of-two scale) in C++, with other arithmetic; this one merges the summaries the
harness holds (``reference_estimators.Estimate``), and every stored figure is computed with it.
"""
from __future__ import annotations

from collections.abc import Iterable

__all__ = ["chan_merge"]


def chan_merge(parts: Iterable[tuple[int, float, float]]) -> tuple[int, float, float]:
    """(n, mean, M2) of the union of ``parts``, each (count, mean, sample variance with ddof 1),
    merged left to right (Chan, Golub & LeVeque 1979): M2 = sum of squared deviations from the
    mean, so the pooled sample variance is M2 / (n - 1).  A part of count 1 contributes no
    variance of its own (its variance may be passed as 0)."""
    tot, mean, m2 = 0, 0.0, 0.0
    for n, m, v in parts:
        delta = m - mean
        new = tot + n
        m2 += v * (n - 1) + delta * delta * tot * n / new
        mean += delta * n / new
        tot = new
    return tot, mean, m2
