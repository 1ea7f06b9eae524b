"""Multiple testing: Holm's step-down, so that a family of tests (a suite's bias tests, its
convergence fits, its sampler checks) holds one stated family-wise false-alarm rate."""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from harness.stats.validate import level

__all__ = ["holm"]


def holm(pvalues: Sequence[float], alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """Holm-Bonferroni step-down: which hypotheses to reject at family-wise level alpha,
    and the adjusted p-values (reject where adjusted <= alpha).  Holds the family-wise
    error rate for any dependence between the tests (Holm 1979).  Written out because
    scipy offers only false-discovery-rate control (false_discovery_control)."""
    p = np.asarray(pvalues, dtype=float)
    if p.ndim != 1 or np.any(~((p >= 0) & (p <= 1))):
        raise ValueError(f"'pvalues' must be a 1-D sequence of values in [0, 1], got {pvalues!r}")
    level(alpha, "alpha")
    m = p.size
    order = np.argsort(p, kind="stable")
    adjusted_sorted = np.maximum.accumulate(np.minimum((m - np.arange(m)) * p[order], 1.0))
    adjusted = np.empty(m)
    adjusted[order] = adjusted_sorted
    return adjusted <= alpha, adjusted
