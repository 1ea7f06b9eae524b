"""The leaf interpolation bound and the leaf quarters: the bound on monotone densities, and the core's
kernels against their numpy definitions."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import reference_estimators as rest

from harness.samplers.cdf_tables import _interpolation_bound


def _max_interpolation_error(cdf, edges: np.ndarray) -> float:
    """The largest |linear interpolation through the leaf's quarter points - exact CDF| on a fine
    grid of each quarter (cdf: the exact CDF, vectorised)."""
    worst = 0.0
    for a, b in zip(edges[:-1], edges[1:]):
        x = np.linspace(a, b, 2001)
        line = cdf(a) + (cdf(b) - cdf(a)) * (x - a) / (b - a)
        worst = max(worst, float(np.max(np.abs(cdf(x) - line))))
    return worst


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(0.0, 1.0), min_size=1, max_size=12),
       st.lists(st.floats(0.0, 10.0), min_size=1, max_size=12), st.booleans())
def test_the_interpolation_bound_holds_for_any_monotone_density_on_the_leaf(at, rises, falling):
    """Any monotone density on a leaf [0, 1], here a staircase with steps anywhere (the extreme
    case of the quarters' bound): linear interpolation through its quarter points stays within
    _interpolation_bound of the exact CDF on every quarter."""
    at = np.sort(np.array(at[:len(rises)]))
    rises = np.array(rises[:at.size])
    def density_cdf(x):
        x = np.asarray(x, dtype=float)
        s = 1.0 - x if falling else x          # a falling staircase: the rising one mirrored
        total = 0.1 * s + np.sum(rises * np.clip(s[..., None] - at, 0.0, None), axis=-1)
        if falling:
            full = 0.1 + np.sum(rises * np.clip(1.0 - at, 0.0, None))
            return full - total
        return total
    edges = np.linspace(0.0, 1.0, 5)
    qs = np.diff(density_cdf(edges))[None, :]
    bound = float(_interpolation_bound(qs)[0])
    assert _max_interpolation_error(density_cdf, edges) <= bound * (1 + 1e-9) + 1e-12


@pytest.mark.parametrize("k", [-0.9, -0.5, 0.5, 1.0, 3.0, 8.0])
def test_the_quarters_bound_is_tighter_than_the_leafs_on_smooth_densities(k):
    """Power densities x^k on leaves at 0 (singular for k < 0), across much of [0, 1] and narrow
    ones (nearly linear densities): the bound holds everywhere, and on the narrow leaves it is
    at most 0.27 of the leaf-chord bound (a quarter for a linear density, whose end quarter
    bounds s w^2 against the leaf's 4 s w^2, s its slope)."""
    def cdf(x):
        return np.asarray(x, dtype=float) ** (k + 1)
    for a, width in ((0.0, 0.25), (0.5, 0.125), (0.3, 0.01), (0.9, 0.01)):
        edges = a + width * np.linspace(0.0, 1.0, 5)
        qs = np.diff(cdf(edges))[None, :]
        bound = float(_interpolation_bound(qs)[0])
        assert _max_interpolation_error(cdf, edges) <= bound * (1 + 1e-9)
        m = qs.sum()
        leaf = 2 * np.max(np.abs(np.cumsum(qs)[:3] - m * np.array([0.25, 0.5, 0.75])))
        assert bound <= min(leaf, qs.max())
        if width == 0.01:
            assert bound <= 0.27 * leaf


def _reference_interpolation_bound(qs):
    """_interpolation_bound in numpy (what the core's interpolation_bound computes)."""
    m = qs.sum(axis=1)
    cum = np.cumsum(qs, axis=1)[:, :3]
    gap = np.max(np.abs(cum - m[:, None] * np.array([0.25, 0.5, 0.75])), axis=1)
    leaf = np.minimum(2 * gap, qs.max(axis=1))
    steps = np.diff(qs, axis=1)
    rising, falling = np.all(steps >= 0, axis=1), np.all(steps <= 0, axis=1)
    d = np.where(falling[:, None], qs[:, ::-1], qs)
    low = np.concatenate([np.zeros((d.shape[0], 1)), d[:, :3]], axis=1)
    high = np.concatenate([d[:, 1:], np.full((d.shape[0], 1), np.inf)], axis=1)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        inner = (d - low) * (high - d) / (high - low)
        quarters = np.where(np.isinf(high), d - low, np.where(high > low, inner, 0.0))
    return np.where(rising | falling, np.minimum(leaf, quarters.max(axis=1)), leaf)


@pytest.mark.parametrize("rows", [0, 1, 7, 5000])
def test_the_interpolation_bound_in_the_core_is_its_numpy_definition_bit_for_bit(rows):
    """Quarter masses rising, falling, flat, with an extremum, zeros, -0.0, denormals, spans of
    600 orders of magnitude, NaN and infinities: the core's bound is the numpy code's, bit for
    bit (NaN where numpy's is), but for the sign of a zero, which numpy's vector maximum and
    minimum choose by the ISA and no use of the bound reads (it is compared, and summed
    with non-negative errors)."""
    rng = np.random.default_rng(rows)
    qs = rng.random((rows, 4)) * 10.0 ** rng.integers(-300, 300, (rows, 1))
    kind = rng.integers(0, 6, rows)
    qs[kind == 0] = np.sort(qs[kind == 0], axis=1)                   # rising
    qs[kind == 1] = np.sort(qs[kind == 1], axis=1)[:, ::-1]          # falling
    qs[kind == 2] = qs[kind == 2, :1] * np.ones(4)                   # flat
    qs[kind == 3, rng.integers(0, 4)] = 0.0
    special = np.array([0.0, -0.0, 5e-324, np.inf, -np.inf, np.nan, 1e308])
    odd = rng.random((rows, 4)) < 0.02
    qs[odd] = rng.choice(special, int(odd.sum()))
    chosen = np.array([[1.0, 1e-16, 1e-16, 1e-16], [0.0, 0.0, 0.0, 0.0], [3.0, 2.0, 2.0, 1.0]])
    qs[:min(rows, 3)] = chosen[:rows]
    with np.errstate(invalid="ignore", over="ignore"):
        want = _reference_interpolation_bound(qs)
    got = rest.interpolation_bound(qs)
    assert got.shape == (rows,) and got.dtype == np.float64
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    keep = ~np.isnan(want)
    np.testing.assert_array_equal((got[keep] + 0.0).view(np.uint64), (want[keep] + 0.0).view(np.uint64))
    with pytest.raises(ValueError, match=r"shape \(L, 4\)"):
        rest.interpolation_bound(qs[:, :3])


def _reference_quarters(strip, a, b, pieces, used, strip_tol, axis, k):
    """tabulate's quarter boxes in numpy (what the core's LeafQuarters builds): (lo, hi, tol,
    group, parent_lo, parent_hi, full)."""
    npiece = pieces.shape[1]
    edges = a[:, None] + (b - a)[:, None] * np.arange(5)[None, :] / 4
    qa, qb = edges[:, :4].reshape(-1), edges[:, 1:].reshape(-1)
    g = np.repeat(strip, 4)
    tol = np.repeat(strip_tol[g] * np.maximum(qb - qa, 1 / 4096) / used[g], npiece)
    lo, hi = np.empty((qa.size * npiece, k)), np.empty((qa.size * npiece, k))
    lo[:, axis], hi[:, axis] = np.repeat(qa, npiece), np.repeat(qb, npiece)
    if k == 2:
        lo[:, 1 - axis], hi[:, 1 - axis] = pieces[g, :, 0].reshape(-1), pieces[g, :, 1].reshape(-1)
    full = np.all(hi > lo, axis=1)
    nleaf = a.size
    group = (np.repeat(np.arange(nleaf), 4 * npiece) * npiece + np.tile(np.arange(npiece), 4 * nleaf))[full]
    present = np.zeros(nleaf * npiece, dtype=bool)
    present[group] = True
    parents, group = np.flatnonzero(present), (np.cumsum(present) - 1)[group]
    plo, phi = np.empty((nleaf * npiece, k)), np.empty((nleaf * npiece, k))
    plo[:, axis], phi[:, axis] = np.repeat(a, npiece), np.repeat(b, npiece)
    if k == 2:
        plo[:, 1 - axis], phi[:, 1 - axis] = pieces[strip, :, 0].reshape(-1), pieces[strip, :, 1].reshape(-1)
    clo, chi, ctol, cgroup = lo[full], hi[full], tol[full], group
    if k == 2:
        cut = (clo[:, 1 - axis] + chi[:, 1 - axis]) / 2
        clo, chi = np.repeat(clo, 2, axis=0), np.repeat(chi, 2, axis=0)
        chi[0::2, 1 - axis], clo[1::2, 1 - axis] = cut, cut
        ctol, cgroup = np.repeat(ctol / 2, 2), np.repeat(cgroup, 2)
    return clo, chi, ctol, cgroup, plo[parents], phi[parents], full


def _reference_quarter_sums(v, e, full, npiece, k):
    """The boxes' integrals and errors summed back into quarter masses and leaf errors, in numpy."""
    nfull = int(full.sum())
    if k == 2:
        v, e = v.reshape(nfull, 2, v.shape[1]).sum(axis=1), e.reshape(nfull, 2, e.shape[1]).sum(axis=1)
    val, err = np.zeros(full.size), np.zeros(full.size)
    bad = ~(np.isfinite(v[:, 0]) & np.isfinite(e[:, 0]))
    val[full] = np.where(bad, 0.0, v[:, 0])
    err[full] = np.where(bad, 1.0, e[:, 0])
    return np.maximum(val, 0).reshape(-1, 4, npiece).sum(axis=2), err.reshape(-1, 4 * npiece).sum(axis=1)


@pytest.mark.parametrize("k, axis", [(1, 0), (2, 0), (2, 1)])
@pytest.mark.parametrize("npiece", [1, 3, 5, 12, 32, 40, 160])
def test_leaf_quarters_in_the_core_are_the_numpy_boxes_and_sums_bit_for_bit(k, axis, npiece):
    """The quarter boxes of leaves of any width (down to _MIN_WIDTH and ulps, where quarters
    collapse), pieces padded with empty ones, and their integrals folded back (halves summed,
    NaN and infinite ones as mass 0 with error 1, negative ones as 0, errors of -0.0, np.sum's
    pairwise order over up to 640 boxes a leaf, its recursion past 128 included) as tabulate's
    numpy code did.  On an interval (k = 1) the pieces are not read, only counted."""
    rng = np.random.default_rng(5 + npiece)
    for _ in range(10):
        nstrip = int(rng.integers(1, 6))
        cuts = np.sort(rng.random((nstrip, npiece + 1)), axis=1)
        cuts[:, 0], cuts[:, -1] = 0.0, 1.0
        padding = int(rng.integers(0, npiece))
        if padding:
            cuts[:, -padding:] = 1.0     # empty pieces at the end, as _cut_at_steps pads
        pieces = np.stack([cuts[:, :-1], cuts[:, 1:]], axis=2) if k == 2 else np.zeros((nstrip, npiece, 2))
        used = np.maximum(np.sum(pieces[:, :, 1] > pieces[:, :, 0], axis=1), 1)
        nleaf = int(rng.integers(1, 50))
        strip = np.sort(rng.integers(0, nstrip, nleaf))
        a = rng.random(nleaf)
        b = np.minimum(a + rng.choice([2.0**-30, 1e-17, 1e-3, 0.25], nleaf), 1.0)
        strip_tol = rng.random(nstrip) * 1e-6
        want = _reference_quarters(strip, a, b, pieces, used, strip_tol, axis, k)
        boxes = rest.leaf_quarters(strip, a, b, pieces, used, strip_tol, axis, k)
        lo, hi, group, parent_lo, parent_hi, tol = boxes.boxes()
        for x, y in zip(want, (lo, hi, tol, group, parent_lo, parent_hi)):
            np.testing.assert_array_equal(np.asarray(x).view(np.uint64), np.asarray(y).view(np.uint64))
        assert boxes.count == int(want[-1].sum())
        rows = want[0].shape[0]
        v = rng.normal(size=(rows, 2)) * 10.0 ** rng.integers(-12, 0, (rows, 1))
        e = np.abs(rng.normal(size=(rows, 2))) * 1e-9
        v[rng.random(rows) < 0.03, 0] = rng.choice([np.nan, np.inf])
        e[rng.random(rows) < 0.03, 0] = np.nan
        for errors in (e, np.full_like(e, -0.0)):
            for x, y in zip(_reference_quarter_sums(v, errors, want[-1], npiece, k), boxes.sums(v, errors)):
                np.testing.assert_array_equal(x.view(np.uint64), y.view(np.uint64))
    with pytest.raises(ValueError, match=r"a strip \(of 'pieces'\) index"):
        rest.leaf_quarters(np.array([nstrip]), a[:1], b[:1], pieces, used, strip_tol, axis, k)
    with pytest.raises(ValueError, match="'used' must count"):
        rest.leaf_quarters(strip[:1], a[:1], b[:1], pieces, np.zeros_like(used), strip_tol, axis, k)
    with pytest.raises(ValueError, match="integer indices"):      # refused, not truncated to strip 0
        rest.leaf_quarters(np.full(1, 0.7), a[:1], b[:1], pieces, used, strip_tol, axis, k)
    # other integer types are taken (numpy 1 on Windows counts in int32)
    assert rest.leaf_quarters(strip.astype(np.int32), a, b, pieces, used.astype(np.int32), strip_tol, axis,
                              k).count == boxes.count
