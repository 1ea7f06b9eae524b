"""Row kernels against numpy: RowLookup, finite_rows, produced_rows, rows in and out of the adapters, the
weight check, float32 columns."""
from __future__ import annotations

import math

import numpy as np
import pytest

import reference_estimators as rest

from tests.core.check_kernel_helpers import CHUNKS, N


def test_row_lookup_finds_the_first_equal_row_as_numpy_compares():
    """Duplicated rows (the first is found), zeros of either sign alike, NaN rows matching
    nothing, rows absent, every width 1 to 3; a brute-force search as the reference."""
    rng = np.random.default_rng(17)
    for k in (1, 2, 3):
        x = rng.integers(-3, 4, size=(2000, k)).astype(float) / 2     # many duplicates
        x[::97] = np.nan
        x[5] = -0.0
        lookup = rest.RowLookup(x)
        q = np.concatenate([x[rng.integers(0, 2000, 300)], rng.normal(size=(50, k)), np.zeros((1, k)),
                            np.full((1, k), np.nan)])
        with np.errstate(invalid="ignore"):
            equal = np.all(q[:, None, :] == x[None, :, :], axis=2)
        want = np.where(equal.any(axis=1), np.argmax(equal, axis=1), -1)
        np.testing.assert_array_equal(lookup.find(q), want)
    assert rest.RowLookup(np.empty((0, 3))).find(np.zeros((2, 3))).tolist() == [-1, -1]
    with pytest.raises(ValueError, match="width"):
        rest.RowLookup(np.zeros((4, 3))).find(np.zeros((1, 2)))


def test_finite_rows_match_numpy():
    rng = np.random.default_rng(13)
    for shape in ((N, 3), (N, 2), (N,), (N, 2, 2), (0, 3)):
        x = rng.normal(size=shape)
        flat = x.reshape(shape[0], math.prod(shape[1:]))
        flat[rng.random(shape[0]) < 0.01, rng.integers(0, flat.shape[1])] = np.nan
        flat[rng.random(shape[0]) < 0.01, -1] = -np.inf
        ok = rest.finite_rows(x)
        assert ok.dtype == bool and ok.shape == (shape[0],)
        np.testing.assert_array_equal(ok, np.all(np.isfinite(flat), axis=1))
    assert rest.finite_rows(np.array([[1, 2], [3, 4]], dtype=np.float32)).tolist() == [True, True]


def test_produced_rows_match_numpy():
    """A renderer's samples across several chunks: directions with NaN and infinite values,
    pdfs 0, negative, NaN; weights of 1 and 3 channels with zeros, -0.0 and NaN (not 0, as
    numpy's !=), one constant weight (a broadcast view, zero or not), Dirac-lobe flags with
    NaN; with and without weights and flags."""
    rng = np.random.default_rng(19)
    x = rng.normal(size=(CHUNKS, 3))
    x[rng.random(CHUNKS) < 0.01, rng.integers(0, 3)] = np.nan
    x[rng.random(CHUNKS) < 0.01, 2] = np.inf
    pdf = rng.choice([0.0, -1.0, np.nan, 0.5, 2.0], size=CHUNKS, p=[0.05, 0.02, 0.01, 0.5, 0.42])
    delta = rng.choice([0.0, 1.0, np.nan], size=CHUNKS, p=[0.8, 0.19, 0.01])
    base = np.all(np.isfinite(x), axis=1) & (pdf > 0)
    for c in (1, 3):
        w = rng.choice([0.0, -0.0, np.nan, 0.3], size=(CHUNKS, c), p=[0.4, 0.1, 0.01, 0.49])
        nonzero = np.any(w != 0, axis=1)
        np.testing.assert_array_equal(rest.produced_rows(x, pdf, w, delta), base & nonzero & (delta == 0))
        np.testing.assert_array_equal(rest.produced_rows(x, pdf, w), base & nonzero)
        for row in (np.zeros(c), np.full(c, 0.25)):          # one constant weight, as a view
            constant = np.broadcast_to(row, (CHUNKS, c))
            np.testing.assert_array_equal(rest.produced_rows(x, pdf, constant, delta),
                                          base & bool(np.any(row != 0)) & (delta == 0))
    np.testing.assert_array_equal(rest.produced_rows(x, pdf), base)
    assert rest.produced_rows(np.empty((0, 3)), np.empty(0), np.empty((0, 3)), np.empty(0)).shape == (0,)
    assert rest.produced_rows(x[:2], pdf[:2], [[0.0], [1.0]]).tolist() == [False, base[1]]   # a list
    for bad in (np.ones((5, 3)), np.zeros((0, 3)), np.zeros((CHUNKS, 0)), np.ones(CHUNKS),
                np.broadcast_to(np.ones(3), (CHUNKS + 2, 3)), np.ones(3)[None, :]):
        with pytest.raises(ValueError, match="'weight' must be"):      # never read as no weight
            rest.produced_rows(x, pdf, bad)
    with pytest.raises(ValueError, match="'weight' must hold real numbers"):
        rest.produced_rows(x, pdf, np.full((CHUNKS, 1), 1j))
    with pytest.raises(ValueError, match="'pdf' must hold real numbers"):
        rest.produced_rows(x, pdf + 0j)
    for bad in (np.zeros(3), np.zeros(0), np.zeros((CHUNKS, 1))):
        with pytest.raises(ValueError, match="'delta' must be"):
            rest.produced_rows(x, pdf, None, bad)


def test_finite_rows_read_strided_views_in_place():
    """A renderer's (3, N) components seen as (N, 3), every other row, one column, a reversed
    view (negative strides: copied first): the same as numpy's answer on a copy."""
    rng = np.random.default_rng(14)
    x = rng.normal(size=(3, CHUNKS))
    x[rng.integers(0, 3, 500), rng.integers(0, CHUNKS, 500)] = np.nan
    x[2, -1] = np.inf
    for view in (x.T, x.T[::2], x.T[:, 1:], x.T[:, 2], x.T[::-1], x[:, :7].T):
        flat = np.ascontiguousarray(view).reshape(view.shape[0], -1)
        np.testing.assert_array_equal(rest.finite_rows(view), np.all(np.isfinite(flat), axis=1))
    # strides that are not whole values (fields of a packed structured array) are copied first
    packed = np.zeros(1000, dtype=[("x", "f8", (3,)), ("flag", "i1")])
    packed["x"][::7, 1] = np.nan
    np.testing.assert_array_equal(rest.finite_rows(packed["x"]), np.arange(1000) % 7 != 0)
    assert rest.cramer_von_mises_sum(packed["x"][:, 0]).shape == (1, 2)


# --- rows in and out of the adapters: what numpy's indexing gives --------------------------
@pytest.mark.parametrize("n", [0, 5, CHUNKS])
def test_row_kernels_match_numpy(n):
    rng = np.random.default_rng(15)
    columns = rng.normal(size=(3, n)).astype(np.float32)
    rows = rest.float64_rows(columns)
    assert rows.dtype == np.float64 and rows.flags["C_CONTIGUOUS"]
    np.testing.assert_array_equal(rows, columns.T.astype(np.float64))
    keep = rng.random(n) < 0.7
    if n:   # values kept bit for bit in a kept row (and made NaN in a dropped one): -0,
        # infinities, a NaN with a payload and its sign
        nan_a, nan_b = (np.uint64(b).view(np.float64) for b in (0xfff0000000000123, 0x7ff4000000000789))
        rows[:3] = [[-0.0, np.inf, nan_a], [nan_b, nan_a, -0.0],
                    [-np.inf, np.uint64(0x7ff0000000000456).view(np.float64), -0.0]]
        keep[:3] = [True, True, False]
    wide = np.concatenate([rows, rows[:, :2]], axis=1)    # five columns: the kernels' general width
    # 2-D of widths 3, 2 and 5, 1-D, and 1-D and 2-D views copied first; compared bit for bit
    # (numpy's NaN is the quiet NaN 0x7ff8...)
    for x in (rows, rows[:, :2], wide, rows[:, 1], rows[::-1], wide[:, 0]):
        np.testing.assert_array_equal(rest.take_rows(x, keep).view(np.uint64), x[keep].view(np.uint64))
        want = np.where(keep if x.ndim == 1 else keep[:, None], x, np.nan)
        np.testing.assert_array_equal(rest.nan_rows(x, keep).view(np.uint64), want.view(np.uint64))
    # a bool view of bytes other than 0 and 1 keeps those rows, and no more
    byte_keep = (keep.astype(np.uint8) * 3).view(bool)
    np.testing.assert_array_equal(rest.take_rows(rows, byte_keep), rows[keep])
    np.testing.assert_array_equal(rest.nan_rows(rows, byte_keep), np.where(keep[:, None], rows, np.nan))
    for kernel in (rest.take_rows, rest.nan_rows):
        with pytest.raises(ValueError, match="one 'keep' flag per row"):
            kernel(rows, np.ones(n + 1, dtype=bool))
        with pytest.raises(ValueError, match="k >= 1"):
            kernel(np.zeros((n, 0)), np.ones(n, dtype=bool))
    for bad in (columns[0], columns.astype(np.float64), columns[:0]):
        with pytest.raises(ValueError, match="float32 of shape"):
            rest.float64_rows(bad)
    # the columns as separate arrays (a drjit vector's components), strided ones too: the same rows
    as_rows = columns.T.astype(np.float64)
    np.testing.assert_array_equal(rest.float64_rows(list(columns)), as_rows)
    np.testing.assert_array_equal(rest.float64_rows((columns[2], columns[0])), as_rows[:, [2, 0]])
    np.testing.assert_array_equal(rest.float64_rows([columns[1, ::2]]), as_rows[::2, 1:2])
    longer = np.zeros(n + 1, np.float32)
    for bad in ([], [columns[0], longer], [columns[0].astype(np.float64)], [columns], ["x"]):
        with pytest.raises(ValueError, match="float32 columns of one shape"):
            rest.float64_rows(bad)


@pytest.mark.parametrize("n", [0, 7, CHUNKS])
@pytest.mark.parametrize("channels", [1, 3])
def test_weight_agreement_is_numpys_weight_check(n, channels):
    """The adapter's weight check in the core against its numpy expressions: weights equal to
    e / p, off by a little (within atol + rtol |ratio|) and by more, NaN, infinite, negative and
    -0.0 weights, NaN and zero pdfs and values, ratios below atol; per-row weights and one
    constant weight (a broadcast view, row stride 0).  The same masks and the same largest
    relative difference (numpy's nan_to_num(nan=inf) of it over the rows not bad)."""
    atol, rtol = 1e-6, 1e-4
    rng = np.random.default_rng(n + channels)
    p = rng.uniform(0.01, 10.0, n)
    e = rng.uniform(0.0, 5.0, (n, channels))
    with np.errstate(all="ignore"):
        w = e / p[:, None] * (1 + rng.choice([0.0, 5e-5, 2e-4, -3e-3], (n, channels)))
    odd = rng.random((n, channels)) < 0.01
    w[odd] = rng.choice([np.nan, np.inf, -np.inf, -1.0, -0.0, 0.0, 1e-9], int(odd.sum()))
    odd_p = rng.random(n) < 0.005
    p[odd_p] = rng.choice([0.0, np.nan, 1e300], int(odd_p.sum()))
    e[rng.random((n, channels)) < 0.005] = np.nan
    constant = np.broadcast_to(np.array([0.5, 2.0, 0.0][:channels]), (n, channels))

    def numpy_check(w):
        with np.errstate(all="ignore"):
            ratio = e / p[:, None]
            diff = np.abs(w - ratio)
            rel = np.where(np.abs(ratio) > atol, diff / np.abs(ratio), diff)
        bad = ~np.all(np.isfinite(w) & (w >= 0), axis=1)
        mis = ~np.all(diff <= atol + rtol * np.abs(ratio), axis=1) & ~bad
        most = float(np.max(np.nan_to_num(rel[~bad], nan=np.inf))) if (~bad).any() else 0.0
        return mis, bad, most

    for weights in (w, constant):
        mis, bad, most = rest.weight_agreement(weights, e, p, atol, rtol)
        want_mis, want_bad, want_most = numpy_check(weights)
        np.testing.assert_array_equal(mis, want_mis)
        np.testing.assert_array_equal(bad, want_bad)
        assert most == want_most and isinstance(most, float)
        if n == CHUNKS and weights is w:   # every kind of row is there
            assert 0 < mis.sum() < n and 0 < bad.sum() < n and most == np.inf   # a NaN value: inf
    with pytest.raises(ValueError, match="'e' must be"):
        rest.weight_agreement(w[:, :0], e[:, :0], p, atol, rtol)
    with pytest.raises(ValueError, match="'e' must be"):
        rest.weight_agreement(w, e, np.append(p, 1.0), atol, rtol)
    for wrong in (np.zeros((n, channels + 1)), np.broadcast_to(np.ones(channels), (n + 1, channels))):
        with pytest.raises(ValueError, match="'w' must have the shape of 'e'"):
            rest.weight_agreement(wrong, e, p, atol, rtol)


@pytest.mark.parametrize("n", [0, 7, CHUNKS])
def test_float32_columns_match_numpy(n):
    """float32_columns is numpy's minimum(rows[:, j], cap, dtype=float32) for every column j,
    bit for bit: values rounded to float32 first (those between the cap and 1 round to 1 or to
    the cap), then capped; NaN, -0 and values off [0, 1] kept as numpy keeps them."""
    rng = np.random.default_rng(16)
    cap = float(np.float32(1.0) - np.float32(2.0**-24))
    special = [1.0, np.nextafter(1.0, 0.0), cap, np.nextafter(cap, 2.0), np.nextafter(cap, 0.0), 0.0, -0.0,
               np.nan, -np.nan, np.uint64(0xfff4000000000123).view(np.float64), 2.0, -1e-300, 1e-46,
               0.5 + 2.0**-25]
    for c in (1, 2, 3):
        rows = rng.random((n, c))
        rows.flat[:min(len(special), rows.size)] = special[:rows.size]
        got = rest.float32_columns(rows, cap)
        assert got.dtype == np.float32 and got.shape == (c, n) and got.flags["C_CONTIGUOUS"]
        with np.errstate(invalid="ignore"):      # numpy warns as it casts a NaN
            want = np.stack([np.minimum(rows[:, j], np.float32(cap), dtype=np.float32) for j in range(c)]) \
                if n else np.zeros((c, 0), np.float32)
        np.testing.assert_array_equal(got.view(np.uint32), want.view(np.uint32))
    with pytest.raises(ValueError, match="c >= 1"):
        rest.float32_columns(np.zeros((n, 0)), cap)
    for bad_cap in (0.1, 1e300, math.nan):
        with pytest.raises(ValueError, match="float32 value"):
            rest.float32_columns(np.zeros((n, 2)), bad_cap)
