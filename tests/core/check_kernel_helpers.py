"""Shared by the test_check_kernels_*.py modules: the sampler check's batch kernels
(src/checks.h, src/tables.h) against the numpy code they replace, on random input with the
edge values mixed in: 0 and 1, points on the boundary of a domain, outside it, NaN and infinite.
Each reference in those modules is the numpy implementation the check used before the kernels
existed.  Equal means bitwise equal, except where stated: the azimuth (fastmath's atan2_turns,
within 2 ulp of numpy's) and sums (compensated in the core, pairwise in numpy: relative 1e-12).
The Cramer-von Mises sum is not the numpy code's value but a bracket of it (no sort): its tests
check that it brackets the sorted sum, and how tightly."""
from __future__ import annotations

import numpy as np

N = 20_000
# CHUNKS points: several of the core's fixed chunks (2^16), on every thread, merged in order
CHUNKS = 300_001


GL_X = (np.polynomial.legendre.leggauss(4)[0] + 1) / 2
GL_W = np.polynomial.legendre.leggauss(4)[1] / 2


def random_boxes(k: int, m: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    lo = rng.random((m, k)) * 0.9
    hi = lo + rng.random((m, k)) * 0.1
    lo[:2], hi[:2] = 0.0, 1.0                  # the whole square and an edge-to-edge box
    return lo, hi


def interleaved(values, boxes, per):
    """Box-major node values (..., boxes per) in cubature_float32_directions' order: blocks of 8
    boxes (the last shorter), node k of box b of a block of w at k w + b."""
    out = np.empty_like(values)
    for m0 in range(0, boxes, 8):
        w = min(8, boxes - m0)
        block = values[..., m0 * per:(m0 + w) * per]
        out[..., m0 * per:(m0 + w) * per] = block.reshape(block.shape[:-1] + (w, per)).swapaxes(-1, -2) \
            .reshape(block.shape)
    return out


def random_table(rng: np.random.Generator, strips: int, leaves: int):
    """Leaves of very different widths (down to 1e-9) tiling [0, 1] in each strip; a CDF
    through them."""
    parts = []
    for _ in range(strips):
        cuts = np.unique(np.concatenate([[0.0, 1.0], rng.random(leaves - 1),
                                         0.3 + 1e-9 * np.arange(5)]))      # a crowd of narrow leaves
        mass = rng.gamma(0.5, 1.0, cuts.size - 1)
        mass /= mass.sum()
        parts.append((cuts[:-1], cuts[1:], np.concatenate([[0.0], np.cumsum(mass)[:-1]]), mass))
    lo, hi, start, mass = (np.concatenate(v) for v in zip(*parts))
    offsets = np.concatenate([[0], np.cumsum([p[0].size for p in parts])])
    return lo, hi, start, mass, offsets
