"""The core's low-level kernels, exposed for reproducibility and accuracy tests: the raw PCG32
output of a chunk's stream, the canonical uniforms drawn from it, and the vectorisable
elementary functions (src/fastmath.h) that integrands and samplers evaluate.

A stream is keyed by (seed, case_id, replica, chunk), as in ``integrate``: chunk c of an
estimate draws its samples from stream (seed, case_id, replica, c).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from . import _core
from .arguments import count_arg, seed_arg

__all__ = ["pcg32_outputs", "uniforms", "uniforms_in_pieces", "fast_exp", "fast_log", "fast_sincos_2pi"]


def pcg32_outputs(n: int, *, seed: int = 0, case_id: int = 0, replica: int = 0, chunk: int = 0) -> np.ndarray:
    """The first n 32-bit outputs (uint32) of the stream's scalar PCG32 generator (O'Neill's
    XSH-RR 64/32, seeded from the key by splitmix64)."""
    out = _core.pcg32_outputs(count_arg(n, "n"), *_key(seed, case_id, replica, chunk))
    return np.array(out, dtype=np.uint32)


def uniforms(n: int, *, seed: int = 0, case_id: int = 0, replica: int = 0, chunk: int = 0) -> np.ndarray:
    """The first n canonical uniforms (float64) of the stream: uniform k is (b + 1/2) 2^-52
    with b the top 52 bits of PCG32 outputs 2k (high word) and 2k+1 (low word), so every
    value lies strictly inside (0, 1)."""
    return _core.uniforms(count_arg(n, "n"), *_key(seed, case_id, replica, chunk))


def uniforms_in_pieces(counts: list[int], evens: list[bool], *, seed: int = 0) -> np.ndarray:
    """The stream (chunk 0 of ``seed``) read as the estimators read it: consecutive pieces of
    counts[i] uniforms, all of them, or (evens[i], counts[i] even) the even-numbered ones
    alone, the u0 of (u0, u1) pairs that the polar path reads.  Concatenated, they must be
    :func:`uniforms`' values at the same positions, whatever the pieces."""
    sizes = [count_arg(c, "count") for c in counts]
    return _core.uniforms_in_pieces(sizes, [bool(e) for e in evens], seed_arg(seed))


def fast_exp(x: Any) -> np.ndarray:
    """exp(x) elementwise as the core computes it: within 2 ulp of glibc where the result is
    normal, 2 steps of 2^-1074 where it is subnormal; float64, the shape of x."""
    a = _flat(x)
    return _core.fm_exp(a).reshape(np.shape(x))


def fast_log(x: Any) -> np.ndarray:
    """Natural log elementwise as the core computes it: within 2 ulp of glibc for x > 0
    (subnormal x too), -inf at 0, NaN below; float64, the shape of x."""
    a = _flat(x)
    return _core.fm_log(a).reshape(np.shape(x))


def fast_sincos_2pi(u: Any) -> tuple[np.ndarray, np.ndarray]:
    """(sin(2 pi u), cos(2 pi u)) elementwise as the core computes them, u in turns (one turn
    = 2 pi radians; absolute error <= 4e-16 for |u| <= 3); float64 arrays of u's shape."""
    s, c = _core.fm_sincos_2pi(_flat(u))
    return s.reshape(np.shape(u)), c.reshape(np.shape(u))


def _flat(x: Any) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(x, dtype=np.float64).ravel())


def _key(seed: int, case_id: int, replica: int, chunk: int) -> tuple[int, int, int, int]:
    return (seed_arg(seed), seed_arg(case_id, "case_id"), seed_arg(replica, "replica"),
            seed_arg(chunk, "chunk"))
