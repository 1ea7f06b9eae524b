"""The bindings' output arrays reuse the memory of freed ones (src/buffer_cache.h): a freed
array of 1 MiB or more serves the next array of a size it fits, and a live array's memory is
never handed out again."""
from __future__ import annotations

import gc

import numpy as np

import reference_estimators as rest

N = 1 << 17   # (N, 2) float64 points: 2 MiB


def test_freed_arrays_memory_serves_the_next_arrays():
    """Eight arrays freed fill the cache (it keeps eight buffers, the oldest leaving first), so
    the next array of their size takes one of theirs; the garbage collector is kept from
    freeing earlier tests' arrays in between."""
    def address(a: np.ndarray) -> int:
        return a.__array_interface__["data"][0]   # (a.ctypes would keep a alive)

    gc.collect()
    gc.disable()
    try:
        arrays = [rest.points(3 * N, 2, seed=s) for s in range(8)]
        freed = {address(a) for a in arrays}
        del arrays
        b = rest.points(3 * N, 2, seed=9)
        assert address(b) in freed
    finally:
        gc.enable()
    np.testing.assert_array_equal(b, rest.points(3 * N, 2, seed=9))   # written whole: no stale values


def test_live_arrays_never_share_memory():
    arrays = [rest.points(N, 2, seed=s) for s in range(12)]   # more than the cache holds
    for i, a in enumerate(arrays):
        for b in arrays[i + 1:]:
            assert not np.shares_memory(a, b)
    for s, a in enumerate(arrays):
        np.testing.assert_array_equal(a, rest.points(N, 2, seed=s))


def test_small_and_bool_arrays_are_served_too():
    x = rest.points(N, 3)
    s, inside = rest.domain_params("sphere", x / np.linalg.norm(x, axis=1, keepdims=True))
    assert s.shape == (N, 2) and inside.dtype == bool and inside.all()
    small = rest.points(10, 2)
    assert small.shape == (10, 2) and np.all((small > 0) & (small < 1))
