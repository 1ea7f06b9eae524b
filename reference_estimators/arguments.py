"""Checks of the arguments the core's Python face passes on (api.py, kernels.py, checks.py):
sample counts, seeds and stream keys, thread counts, point arrays and chunk ranges.  Each
returns the value as the core takes it or raises a TypeError / ValueError naming the argument
and the rule.
"""
from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np

from . import _core


def chunk_range(n: int, chunk_begin: Any, chunk_end: Any) -> tuple[int, int]:
    """[begin, end) within the chunks of an estimate of n samples (end None: the last)."""
    chunks = -(-n // _core.CHUNK_SIZE)
    begin = seed_arg(chunk_begin, "chunk_begin")
    end = chunks if chunk_end is None else seed_arg(chunk_end, "chunk_end")
    if not begin < end <= chunks:
        raise ValueError(f"chunks [{chunk_begin}, {chunk_end}) must be a non-empty range within the {chunks} "
                         f"chunk(s) of n = {n} samples")
    return begin, end


def points_arg(a: Any, dim: int, name: str) -> np.ndarray:
    x = np.ascontiguousarray(a, dtype=np.float64)
    if not (x.ndim == 2 and x.shape[1] == dim) and not (dim == 1 and x.ndim == 1):
        want = f"(N, {dim})" + (" or (N,)" if dim == 1 else "")
        raise ValueError(f"'{name}' must have shape {want}, got {x.shape}")
    return x


MAX_COUNT = 2**63 - 1   # the core counts samples in 64-bit signed integers


def count_arg(n: Any, name: str, *, zero: bool = False) -> int:
    if isinstance(n, numbers.Real) and not isinstance(n, bool) and not math.isfinite(n):
        raise ValueError(f"'{name}' must be a finite number of samples, got {n!r}")
    if isinstance(n, bool) or not isinstance(n, numbers.Real) or n != int(n):
        raise TypeError(f"'{name}' must be a whole number of samples, got {n!r}")
    if n < 0 or (n == 0 and not zero):
        raise ValueError(f"'{name}' must be a {'non-negative' if zero else 'positive'} number of samples, "
                         f"got {n!r}")
    if n > MAX_COUNT:
        raise ValueError(f"'{name}' must be at most 2**63 - 1 samples, got {n!r}")
    return int(n)


def seed_arg(s: Any, name: str = "seed") -> int:
    if isinstance(s, bool) or not isinstance(s, numbers.Integral) or not 0 <= s < 2**64:
        raise ValueError(f"'{name}' must be an integer in [0, 2**64), got {s!r}")
    return int(s)


def stream_arg(stream: Any) -> tuple[int, int]:
    """A stream key (seed, case_id): exactly two integers in [0, 2**64)."""
    if not isinstance(stream, (tuple, list)) or len(stream) != 2:
        raise ValueError(f"'stream' must be a pair (seed, case_id), got {stream!r}")
    return seed_arg(stream[0], "seed"), seed_arg(stream[1], "case_id")


def threads_arg(t: Any) -> int:
    if t is None:
        return 0
    if isinstance(t, bool) or not isinstance(t, numbers.Integral) or t < 1:
        raise ValueError(f"'threads' must be a positive integer or None (all cores), got {t!r}")
    return int(t)
