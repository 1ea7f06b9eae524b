"""The Sobol' point sets, bit for bit against a plain numpy construction of what
pointsets.h documents: Joe-Kuo direction numbers (x(i) = XOR of v[d, k] over the set bits k
of i), Burley's hash-based Owen scrambling of the reversed bits with one seed per dimension
from (seed, case, replica, 0x50b01 + d) by splitmix64, and u = (x + 1/2) 2^-32.  The core
builds the points from bit-reversed tables, in runs of one high index, 16 at a time with
GFNI where the CPU has it (test_isa_builds compares the builds without it)."""
from __future__ import annotations

import numpy as np
import pytest

import reference_estimators as rest
from reference_estimators.sobol import direction_numbers

M64 = (1 << 64) - 1
OWEN_HASH = (0x6C50B47C, 0xB82F1E52, 0xC7AFE638, 0x8D22F6E6)


def splitmix64(x: int) -> int:
    x = (x + 0x9E3779B97F4A7C15) & M64
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & M64
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & M64
    return x ^ (x >> 31)


def reverse_bits(x: np.ndarray) -> np.ndarray:
    bits = (x[:, None] >> np.arange(32, dtype=np.uint32)) & np.uint32(1)
    return (bits << np.arange(31, -1, -1, dtype=np.uint32)).sum(axis=1, dtype=np.uint64).astype(np.uint32)


def sobol_points(indices: np.ndarray, dim: int, seed: int, case_id: int, replica: int) -> np.ndarray:
    v = direction_numbers(dim)
    out = np.empty((indices.size, dim))
    for d in range(dim):
        x = np.zeros(indices.size, dtype=np.uint32)
        for k in range(32):
            x ^= np.where((indices >> np.uint64(k)) & np.uint64(1), v[d, k], np.uint32(0)).astype(np.uint32)
        s = splitmix64(seed ^ splitmix64(case_id ^ splitmix64(replica ^ splitmix64(0x50B01 + d))))
        r = reverse_bits(x) + np.uint32(s & 0xFFFFFFFF)
        for k in OWEN_HASH:
            r ^= r * np.uint32(k)
        out[:, d] = (reverse_bits(r).astype(np.float64) + 0.5) * 2.0**-32
    return out


@pytest.mark.parametrize("dim", [1, 2, 3, 5])
def test_sobol_points_are_the_documented_construction(dim):
    """Whole sets and chunk ranges (blocks that start at a chunk boundary, runs of 2048
    indices, tails of fewer than 16 points), in 1 to 5 dimensions."""
    n = 2 * rest.CHUNK_SIZE + 2061
    keys = dict(seed=12, case_id=4, replica=3)
    got = rest.points(n, dim, "sobol", **keys)
    c = rest.CHUNK_SIZE
    pick = np.concatenate([np.arange(0, 4200), np.arange(c - 37, c + 4133), np.arange(n - 2100, n)])
    np.testing.assert_array_equal(got[pick], sobol_points(pick.astype(np.uint64), dim, **keys))
    tail = rest.points(n, dim, "sobol", chunk_begin=2, **keys)
    np.testing.assert_array_equal(tail, got[2 * rest.CHUNK_SIZE:])
