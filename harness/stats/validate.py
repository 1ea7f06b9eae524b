"""Argument validators shared across the harness: each returns the value normalised (an
``int`` or a ``float``) or raises ``ValueError`` naming the argument, the rule and the value.

Written once here so that the statistics, the samplers and the adapters word the same rule
the same way.  (``reference_estimators`` keeps its own: the core does not import the harness.)
"""
from __future__ import annotations

import math
import numbers
from typing import Any

__all__ = ["count", "finite", "integer_in", "level", "sizes"]


def count(x: Any, name: str) -> int:
    """A positive whole number of things (samples, replicas, budgets): an integer or a float
    with no fractional part (so ``1e5`` is accepted), not a bool."""
    whole = isinstance(x, numbers.Real) and not isinstance(x, bool) and math.isfinite(x) and x == int(x)
    if not (whole and x > 0):
        raise ValueError(f"'{name}' must be a positive whole number, got {x!r}")
    return int(x)


def integer_in(x: Any, name: str, lo: int, hi: int | None = None) -> int:
    """An integer (not a float, not a bool) in [lo, hi], or >= lo where ``hi`` is None."""
    ok = isinstance(x, numbers.Integral) and not isinstance(x, bool) and lo <= x and (hi is None or x <= hi)
    if not ok:
        rule = f"an integer >= {lo}" if hi is None else f"an integer in [{lo}, {hi}]"
        raise ValueError(f"'{name}' must be {rule}, got {x!r}")
    return int(x)


def level(x: Any, name: str) -> float:
    """A probability strictly between 0 and 1: a false-alarm rate ``alpha`` or a
    ``confidence_level`` (NaN is refused)."""
    if isinstance(x, bool) or not isinstance(x, numbers.Real) or not 0 < x < 1:
        raise ValueError(f"'{name}' must be in (0, 1), got {x!r}")
    return float(x)


def finite(x: Any, name: str) -> float:
    """A finite real number (a numpy scalar too; not a bool, NaN or an infinity)."""
    if isinstance(x, bool) or not isinstance(x, numbers.Real) or not math.isfinite(x):
        raise ValueError(f"'{name}' must be a finite number, got {x!r}")
    return float(x)


def sizes(x: Any, name: str, least: int) -> list[int]:
    """At least ``least`` distinct sample counts (budgets), sorted: whole numbers
    (:func:`count`), from any sequence (an array too)."""
    try:
        given = [] if x is None or isinstance(x, (str, bytes)) else list(x)
    except TypeError:
        raise ValueError(f"'{name}' must be a sequence of sample counts, got {x!r}") from None
    b = sorted({count(v, name) for v in given})
    if len(b) < least:
        what = f"{least} distinct sizes" if least > 1 else "one size"
        raise ValueError(f"'{name}' needs at least {what}, got {x!r}")
    return b
