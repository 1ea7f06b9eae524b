"""The grid histogram and the CDF tables' kernels (piecewise-linear lookup, Rosenblatt transform) against
their definitions."""
from __future__ import annotations

import numpy as np
import pytest

import reference_estimators as rest

from tests.core.check_kernel_helpers import CHUNKS, N, random_table


# --- histogram -------------------------------------------------------------------------------
def histogram_reference(s: np.ndarray, inside: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    s = np.clip(s[inside], 0, np.nextafter(1, 0))
    idx = np.zeros(s.shape[0], dtype=np.int64)
    for axis, m in enumerate(shape):
        idx = idx * m + np.minimum((s[:, axis] * m).astype(np.int64), m - 1)
    return np.bincount(idx, minlength=int(np.prod(shape))).astype(float).reshape(shape)


@pytest.mark.parametrize("n", [N, CHUNKS])
@pytest.mark.parametrize("shape", [(4096,), (16,), (128, 256), (3, 5)])
def test_grid_histogram_matches_numpy_with_clamping_and_the_inside_mask(shape, n):
    rng = np.random.default_rng(3)
    s = rng.uniform(-0.01, 1.01, (n, len(shape)))
    s[:4] = 0.0
    s[4:8] = 1.0
    s[8:12] = np.nextafter(1, 0)
    s[-3:] = np.nan
    inside = rng.random(n) < 0.9
    got = rest.grid_histogram(s, inside, shape)
    counted = inside & ~np.isnan(s).any(axis=1)
    np.testing.assert_array_equal(got, histogram_reference(s, counted, shape))
    assert got.sum() == counted.sum()


def test_grid_histogram_counts_no_nan():
    s = np.array([[0.5, np.nan], [np.nan, 0.5], [0.25, 0.75]])
    got = rest.grid_histogram(s, np.ones(3, dtype=bool), (2, 2))
    np.testing.assert_array_equal(got, [[0, 1], [0, 0]])


# --- Rosenblatt transform --------------------------------------------------------------------
def rosenblatt_reference(marginal, conditional, edges, s):
    """Transform.apply as it was: searchsorted strips, one table lookup per axis."""
    n = s.shape[0]
    u0 = rest.piecewise_linear_lookup(*marginal, np.zeros(n, dtype=np.int64), s[:, 0])
    if conditional is None:
        return u0[:, None], np.zeros(n, dtype=np.int64)
    g = np.clip(np.searchsorted(edges, s[:, 0], side="right") - 1, 0, edges.size - 2)
    return np.column_stack([u0, rest.piecewise_linear_lookup(*conditional, g, s[:, 1])]), g


def lookup_reference(lo, hi, start, mass, offsets, strip, x):
    """The table's definition, leaf by leaf with numpy's searchsorted."""
    out = np.full(x.size, np.nan)
    for g in range(offsets.size - 1):
        a, b = offsets[g], offsets[g + 1]
        sel = (strip == g) & ~np.isnan(x)
        if b <= a or not sel.any():
            continue
        i = a + np.maximum(np.searchsorted(lo[a:b], x[sel], side="right") - 1, 0)
        w = hi[i] - lo[i]
        t = np.clip(np.where(w > 0, (x[sel] - lo[i]) / np.where(w > 0, w, 1), 0.0), 0, 1)
        out[sel] = np.clip(start[i] + mass[i] * t, 0, 1)
    return out


@pytest.mark.parametrize("strips, leaves", [(1, 4000), (32, 256), (3, 1)])
def test_piecewise_linear_lookup_matches_its_definition(strips, leaves):
    rng = np.random.default_rng(4)
    table = random_table(rng, strips, leaves)
    x = rng.uniform(-0.1, 1.1, N)
    x[:6] = [0.0, 1.0, 0.3, 0.3 + 2e-9, np.nan, 0.3 - 1e-12]
    g = rng.integers(-1, strips + 1, N)      # out-of-range strips give NaN
    got = rest.piecewise_linear_lookup(*table, g, x)
    np.testing.assert_array_equal(got, lookup_reference(*table, g, x))


@pytest.mark.parametrize("empty", [(0,), (1, 3), (3,), (0, 1, 2, 3)])
def test_piecewise_linear_lookup_gives_nan_in_an_empty_strip(empty):
    """A strip without leaves (first, inner, last: its leaves would start at the sentinel's
    index, or all) gives NaN; the strips around it are looked up as defined."""
    rng = np.random.default_rng(11)
    lo, hi, start, mass, offsets = random_table(rng, 4, 50)
    keep = ~np.isin(np.repeat(np.arange(4), np.diff(offsets)), empty)
    sizes = np.where(np.isin(np.arange(4), empty), 0, np.diff(offsets))
    table = (lo[keep], hi[keep], start[keep], mass[keep], np.concatenate([[0], np.cumsum(sizes)]))
    x = rng.uniform(-0.1, 1.1, 5000)
    x[:3] = [0.0, 1.0, np.nan]
    g = rng.integers(0, 4, x.size)
    got = rest.piecewise_linear_lookup(*table, g, x)
    np.testing.assert_array_equal(got, lookup_reference(*table, g, x))
    assert np.isnan(got[np.isin(g, empty)]).all()


def test_a_table_without_strips_gives_nan_and_reads_nothing():
    """offsets [0]: no strip, no leaf.  Every lookup is NaN, as for a strip outside a table;
    the transform through such a marginal too (its four passes read strip 0's index, which a
    table without strips does not have)."""
    empty = tuple(np.zeros(0) for _ in range(4)) + (np.zeros(1, dtype=np.int64),)
    x = np.array([0.0, 0.5, 1.0, np.nan])
    assert np.isnan(rest.piecewise_linear_lookup(*empty, np.zeros(4, dtype=np.int64), x)).all()
    rng = np.random.default_rng(12)
    conditional, edges = random_table(rng, 4, 10), np.array([0.0, 0.25, 0.5, 0.75, 1.0])
    s = rng.random((100, 2))
    u, _ = rest.rosenblatt(empty, conditional, edges, s)
    assert np.isnan(u[:, 0]).all()
    sums, counts = rest.transform_statistics(empty, None, np.array([0.0, 1.0]), s[:, :1], 8)
    assert np.isnan(sums).all() and counts.sum() == 0
    u, _ = rest.rosenblatt(random_table(rng, 1, 10), empty, np.array([0.5]), s)   # as the conditional
    assert np.isnan(u[:, 1]).all() and np.isfinite(u[:, 0]).all()


@pytest.mark.parametrize("square, on_leaves", [(False, False), (True, False), (True, True)])
def test_rosenblatt_matches_the_lookups_it_replaces(square, on_leaves):
    """Strips by a search among the edges, or, where the edges lie on the marginal's leaves
    (as the sampler check's do), by the leaf s0 falls in: searchsorted's strips either way."""
    rng = np.random.default_rng(5)
    marginal = random_table(rng, 1, 3000)
    conditional = random_table(rng, 32, 200) if square else None
    inner = np.sort(rng.choice(marginal[0][1:], 31, replace=False)) if on_leaves else np.sort(rng.random(31))
    edges = np.concatenate([[0.0], inner, [1.0]])
    s = rng.random((N, 2 if square else 1))
    s[:5, 0] = [0.0, 1.0, edges[7], np.nextafter(edges[7], 0), edges[-2]]
    if square:
        s[5:9, 0] = [-0.5, 1.5, np.nextafter(edges[-2], 0), -np.inf]
        s[9:9 + edges.size, 0] = edges
    u, strip = rest.rosenblatt(marginal, conditional, edges, s)
    ref_u, ref_strip = rosenblatt_reference(marginal, conditional, edges, s)
    np.testing.assert_array_equal(strip, ref_strip)
    np.testing.assert_array_equal(u, ref_u)


@pytest.mark.parametrize("on_leaves", [False, True])
def test_rosenblatt_puts_a_nan_point_in_the_last_strip_as_searchsorted_does(on_leaves):
    rng = np.random.default_rng(6)
    marginal, conditional = random_table(rng, 1, 10), random_table(rng, 4, 10)
    inner = marginal[0][[2, 4, 6]] if on_leaves else [0.25, 0.5, 0.75]
    edges = np.array([0.0, *inner, 1.0])
    s = np.array([[np.nan, 0.5], [edges[2], np.nan]])
    u, strip = rest.rosenblatt(marginal, conditional, edges, s)
    assert list(strip) == [3, 2] and np.isnan(u[0, 0]) and np.isnan(u[1, 1])


def crowded_table(rng: np.random.Generator):
    """A narrow lobe's CDF table: a few leaves over most of [0, 1] and thousands crowded into
    [0, 1e-3], widths down to 2^-40 at 0 (the leaves a GGX alpha = 0.01 marginal has)."""
    cuts = np.unique(np.concatenate([[0.0, 1.0], 2.0 ** -np.arange(10, 41), 1e-3 * rng.random(3000),
                                     rng.random(20), 5e-4 + 1e-12 * np.arange(40)]))
    mass = rng.gamma(0.5, 1.0, cuts.size - 1)
    mass /= mass.sum()
    start = np.concatenate([[0.0], np.cumsum(mass)[:-1]])
    return cuts[:-1], cuts[1:], start, mass, np.array([0, cuts.size - 1])


def test_piecewise_linear_lookup_in_crowded_buckets_matches_its_definition():
    rng = np.random.default_rng(11)
    table = crowded_table(rng)
    lo = table[0]
    x = np.concatenate([1e-3 * rng.random(N), rng.random(N // 4), lo, np.nextafter(lo, -1),
                        np.nextafter(lo, 2), 2.0 ** -np.arange(30, 60), [-0.1, 1.0, 1.1, np.inf, -np.inf]])
    g = np.zeros(x.size, dtype=np.int64)
    np.testing.assert_array_equal(rest.piecewise_linear_lookup(*table, g, x), lookup_reference(*table, g, x))
