"""float32 points in the core: detection, dithering, nudging, and the reported pdf's mismatching rows,
against numpy."""
from __future__ import annotations

import numpy as np
import pytest

import reference_estimators as rest

from tests.core.check_kernel_helpers import CHUNKS, N


# --- float32 points: detection and dithering -----------------------------------------------
def all_float32_reference(values: np.ndarray) -> bool:
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v) & (v != 0)]
    with np.errstate(over="ignore"):
        return bool(v.size) and np.array_equal(v.astype(np.float32).astype(float), v)


def dither_reference(x: np.ndarray, u: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", over="ignore"):
        x32 = x.astype(np.float32)
        below = (x + np.nextafter(x32, np.float32(-np.inf)).astype(float)) / 2
        above = (x + np.nextafter(x32, np.float32(np.inf)).astype(float)) / 2
        d = below + (above - below) * u.reshape(x.shape)
    return np.where(np.isfinite(d), d, x)


F32_EDGES = [0.0, -0.0, 1.0, -1.0, 2.0**-149, -(2.0**-149), 2.0**-126, float(np.finfo(np.float32).max),
             -float(np.finfo(np.float32).max), 3.5e38, 1e39, 1e300, np.inf, -np.inf, np.nan]


@pytest.mark.parametrize("n", [N, CHUNKS])
def test_dither_float32_matches_numpy(n):
    rng = np.random.default_rng(12)
    x = rng.normal(size=(n, 3)).astype(np.float32).astype(float)
    x.reshape(-1)[:len(F32_EDGES)] = F32_EDGES
    x[-1] = [0.1, 1e-7, 1 - 1e-9]                      # float64 values: dithered around their rounding
    u = rng.random(x.shape)
    u.reshape(-1)[:2] = [0.0, 1 - 2.0**-53]
    got = rest.dither_float32(x, u)
    assert got.shape == x.shape
    np.testing.assert_array_equal(got, dither_reference(x, u))


def test_dither_float32_matches_numpy_on_any_bits():
    """Every kind of double: random bit patterns (NaN payloads, infinities, beyond float32's
    range), float32 values of every exponent, powers of two either side of the subnormals
    (where the spacing below halves), and uniforms at 0, just below 1 and NaN."""
    rng = np.random.default_rng(16)
    floats = rng.integers(0, 2**32, size=50_000, dtype=np.uint64).astype(np.uint32).view(np.float32)
    twos = np.ldexp(1.0, np.arange(-160, 130))
    with np.errstate(invalid="ignore"):    # float32 NaNs widened
        wide = floats.astype(np.float64)
    values = [rng.integers(0, 2**64, size=50_000, dtype=np.uint64).view(np.float64), wide,
              np.concatenate([twos, -twos, twos * (1 + 2.0**-23), -twos * (1 - 2.0**-24), F32_EDGES])]
    for x in values:
        ends = (np.zeros(x.size), np.full(x.size, 1 - 2.0**-53), np.full(x.size, np.nan))
        for u in (rng.random(x.size), *ends):
            with np.errstate(invalid="ignore"):
                want = dither_reference(x, u)
            np.testing.assert_array_equal(rest.dither_float32(x, u).view(np.uint64), want.view(np.uint64))


def nudged_reference(x: np.ndarray, column: int, steps: int) -> np.ndarray:
    with np.errstate(invalid="ignore", over="ignore"):
        y = x.astype(np.float32)
        col = y[:, column]
        for _ in range(abs(steps)):
            col = np.nextafter(col, np.float32(np.inf if steps > 0 else -np.inf), dtype=np.float32)
        y[:, column] = col
        return y.astype(np.float64)


@pytest.mark.parametrize("steps", [1, 4, -1, -4, 9])
def test_float32_nudged_matches_numpy_on_any_bits(steps):
    """The reported-pdf check's nudged points: numpy's float32 nextafter steps, bit for bit,
    on random bit patterns, float32 values of every exponent, the subnormals next to both zeros
    (a step across zero: nextafter's -2^-149 up is -0.0, -0.0 up is +2^-149), float32's ends
    and the infinities, over more rows than a chunk; a column out of range refused."""
    rng = np.random.default_rng(17)
    tiny = 2.0**-149 * np.arange(-10, 11)
    special = np.concatenate([tiny, [-0.0], F32_EDGES, -(2.0**-149) * np.arange(1, 10)])
    floats = rng.integers(0, 2**32, size=CHUNKS, dtype=np.uint64).astype(np.uint32).view(np.float32)
    with np.errstate(invalid="ignore"):
        wide = floats.astype(np.float64)
    doubles = rng.integers(0, 2**64, size=5000, dtype=np.uint64).view(np.float64)
    column = np.concatenate([special, wide, doubles])
    x = np.stack([column, rng.permutation(column), rng.permutation(column)], axis=1)
    for c in range(3):
        got, want = rest.float32_nudged(x, c, steps), nudged_reference(x, c, steps)
        np.testing.assert_array_equal(np.isnan(got), np.isnan(want))    # NaN payloads aside
        bits = lambda v: np.where(np.isnan(v), 0, v.view(np.uint64))  # noqa: E731
        np.testing.assert_array_equal(bits(got), bits(want))
    with pytest.raises(ValueError, match="column"):
        rest.float32_nudged(x, 3, steps)


def test_float32_nudged_takes_steps_of_the_int32_range_only():
    """The core steps an int32: the range's ends work (a step to an infinity stops there),
    one beyond is a ValueError naming 'steps', not nanobind's TypeError."""
    x = np.ones((3, 2))
    assert rest.float32_nudged(x, 0, 2**31 - 1)[0, 0] == np.inf
    assert rest.float32_nudged(x, 0, -(2**31))[0, 0] == -4.0   # 1.0's float32 order less 2^31
    for steps in (2**31, -(2**31) - 1, 10**30):
        with pytest.raises(ValueError, match=r"'steps' must be in \[-2\^31, 2\^31\)"):
            rest.float32_nudged(x, 0, steps)


@pytest.mark.parametrize("n", [1, 7, 65_536, 65_537, 140_001])
@pytest.mark.parametrize("kind", ["interval", "hemisphere"])
def test_dither_uniforms_drawn_in_the_pass_are_those_of_points(kind, n):
    """dithered_domain_params with stream=(seed, case_id) draws the uniforms points(N,
    coordinates, seed, case_id) gives, chunk by chunk inside the pass: the same bits as
    passing them, below one chunk, at its edge, past it and over several; an interval's
    points as (N,) or (N, 1), and any other shape refused."""
    rng = np.random.default_rng(n)
    dim = 1 if kind == "interval" else 3
    x = rng.random(n) if dim == 1 else rng.normal(size=(n, 3))
    if dim == 3:
        x[:, 2] = np.abs(x[:, 2])
        x /= np.linalg.norm(x, axis=1)[:, None]
    x = x.astype(np.float32).astype(float)
    u = rest.points(n, dim, seed=9, case_id=0xD17E)
    want = rest.dithered_domain_params(kind, x, u)
    for points in ((x, x[:, None]) if dim == 1 else (x,)):
        got = rest.dithered_domain_params(kind, points, stream=(9, 0xD17E))
        np.testing.assert_array_equal(got[0].view(np.uint64), want[0].view(np.uint64))
        np.testing.assert_array_equal(got[1], want[1])
    if dim == 1:
        with pytest.raises(ValueError, match=r"shape \(N, 1\)"):
            rest.dithered_domain_params(kind, np.stack([x, x], axis=1), stream=(9, 0xD17E))
    for bad in ((9,), (9, 1, 2), 9, (9, -1), {"seed": 9, "case_id": 1}):
        with pytest.raises(ValueError, match="'stream' must be a pair|'case_id' must be"):
            rest.dithered_domain_params(kind, x, stream=bad)
    with pytest.raises(ValueError, match="one of them"):
        rest.dithered_domain_params(kind, x, u, stream=(9, 0xD17E))


def test_all_float32_matches_numpy():
    rng = np.random.default_rng(13)
    x = rng.normal(size=5000).astype(np.float32).astype(float)
    cases = [x, np.append(x, F32_EDGES), np.append(x, 0.1), np.append(x, 1e39),
             np.array([0.0, np.nan, np.inf]), np.array([]), np.array([2.0**-149]), np.array([1.0 + 2.0**-30]),
             # just beyond float32's range, a float64 between float32 subnormals, one in a later block
             np.array([float(np.finfo(np.float32).max) * (1 + 2.0**-40)]), np.array([1.5 * 2.0**-149]),
             np.array([2.0**-140 + 2.0**-160]), np.append(np.ones(3000), [1.0 + 2.0**-30, 1.0]),
             # float32 values with the range's ends, and with NaN and infinities (failed samples): True
             np.append(x, [float(np.finfo(np.float32).max), -float(np.finfo(np.float32).max)]),
             np.append(x, [np.nan, np.inf, -np.inf, -0.0])]
    assert all_float32_reference(cases[-1]) and all_float32_reference(cases[-2])
    for v in cases:
        assert rest.all_float32(v) == all_float32_reference(v), v[-3:]


def test_pdf_mismatches_are_numpys_rows():
    rng = np.random.default_rng(14)
    p = rng.random(CHUNKS) * 10
    off = rng.choice([0.0, 0.99e-4, 1.01e-4, -1.01e-4, 0.5], size=p.size, p=[0.9, 0.04, 0.02, 0.02, 0.02])
    reported = p * (1 + off)
    edges = [(1.0, np.nan), (np.nan, 1.0), (np.inf, 1.0), (-0.0, 0.0), (0.0, 0.0), (-1e-300, 0.0),
             (1.0, np.inf), (np.inf, np.inf), (1e-300, 0.0), (-1.0, -1.0), (np.inf, 1e308)]
    reported[:len(edges)], p[:len(edges)] = zip(*edges)
    reported[-1] = 2 * p[-1]                                  # the last row mismatches
    for rtol in (1e-4, 10.0):       # 10: an infinite or negative report mismatches however close
        with np.errstate(invalid="ignore", over="ignore"):
            near = np.abs(reported - p) <= rtol * np.abs(p)
            want = np.flatnonzero(~near | ~np.isfinite(reported) | (reported < 0))
        got = rest.pdf_mismatches(reported, p, rtol)
        assert got.dtype == np.int64 and {9, 10} | ({p.size - 1} if rtol < 1 else set()) <= set(want.tolist())
        np.testing.assert_array_equal(got, want)
    assert rest.pdf_mismatches(p[len(edges):], p[len(edges):], 0.0).size == 0   # equal values: none
    with pytest.raises(ValueError, match="same length"):
        rest.pdf_mismatches(p, p[:-1], 1e-4)
