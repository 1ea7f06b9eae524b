"""Chan's merge of summaries (count, mean, variance) into one count, mean and sum of squared
deviations, in a fixed order: how the bias test pools a batch's pieces and how replicas pool
their per-sample variance; with the third central moment (Pebay's update) for the bias test's
skewness correction.

Not the core's ``merge_states``: that one merges raw accumulator states (compensated sums,
M2..M4, a power-of-two scale) in C++, with other arithmetic; this one merges the summaries the
harness holds (``reference_estimators.Estimate``), and every stored figure is computed with it.
"""
from __future__ import annotations

from collections.abc import Iterable

__all__ = ["chan_merge", "merge_moments"]


def chan_merge(parts: Iterable[tuple[int, float, float]]) -> tuple[int, float, float]:
    """(n, mean, M2) of the union of ``parts``, each (count, mean, sample variance with ddof 1),
    merged left to right (Chan, Golub & LeVeque 1979): M2 = sum of squared deviations from the
    mean, so the pooled sample variance is M2 / (n - 1).  A part of count 1 contributes no
    variance of its own (its variance may be passed as 0)."""
    n, mean, m2, _ = merge_moments((k, m, v * (k - 1), 0.0) for k, m, v in parts)
    return n, mean, m2


def merge_moments(parts: Iterable[tuple[int, float, float, float]]) -> tuple[int, float, float, float]:
    """(n, mean, M2, M3) of the union of ``parts``, each (count, mean, M2, M3) with Mj the sum
    of j-th powers of deviations from the part's mean, merged left to right (Chan et al.; the
    M3 update of Pebay 2008)."""
    tot, mean, m2, m3 = 0, 0.0, 0.0, 0.0
    for n, m, m2b, m3b in parts:
        delta = m - mean
        new = tot + n
        m3 += (m3b + delta * delta * delta * tot * n * (tot - n) / (new * new)
               + 3 * delta * (tot * m2b - n * m2) / new)
        m2 += m2b + delta * delta * tot * n / new
        mean += delta * n / new
        tot = new
    return tot, mean, m2, m3
