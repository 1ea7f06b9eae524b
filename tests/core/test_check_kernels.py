"""The sampler check's batch kernels (src/checks.h, src/tables.h) against the numpy code they
replace, on random input with the edge values mixed in: 0 and 1, points on the boundary of a
domain, outside it, NaN and infinite.  Each reference below is the numpy implementation the
check used before the kernels existed.  Equal means bitwise equal, except where stated: the
azimuth (fastmath's atan2_turns, within 2 ulp of numpy's) and sums (compensated in the core,
pairwise in numpy: relative 1e-12).  The Cramer-von Mises sum is not the numpy code's
value but a bracket of it (no sort): its tests check that it brackets the sorted sum, and
how tightly."""
from __future__ import annotations

import concurrent.futures
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import reference_estimators as rest

N = 20_000
# CHUNKS points: several of the core's fixed chunks (2^16), on every thread, merged in order
CHUNKS = 300_001


# --- references: the numpy code the kernels replace -----------------------------------------
def params_reference(kind: str, x: np.ndarray, lo: float = 0.0, hi: float = 1.0):
    x = np.asarray(x, dtype=float)
    if kind == "interval":
        x = x.reshape(-1)
        return ((x - lo) / (hi - lo))[:, None], np.isfinite(x) & (x >= lo) & (x <= hi)
    if kind == "half_line":
        x = x.reshape(-1)
        with np.errstate(invalid="ignore"):   # inf / inf
            return (x / (1.0 + x))[:, None], np.isfinite(x) & (x >= 0)
    if kind == "square":
        return x.copy(), np.all(np.isfinite(x), axis=1) & np.all((x >= 0) & (x <= 1), axis=1)
    with np.errstate(invalid="ignore"):
        phi = np.mod(np.arctan2(x[:, 1], x[:, 0]) / (2 * math.pi), 1.0)
    if kind == "disk":
        r2 = x[:, 0] ** 2 + x[:, 1] ** 2
        return np.column_stack([r2, phi]), np.all(np.isfinite(x), axis=1) & (r2 <= 1 + 1e-12)
    norm = np.einsum("ij,ij->i", x, x)
    with np.errstate(invalid="ignore"):
        ok = np.all(np.isfinite(x), axis=1) & (np.abs(norm - 1) <= 1e-5)
        z = np.clip(x[:, 2], -1, 1)
    if kind == "hemisphere":
        return np.column_stack([z, phi]), ok & (x[:, 2] >= -1e-12)
    return np.column_stack([(1 - z) / 2, phi]), ok


def points(kind: str, rng: np.random.Generator) -> np.ndarray:
    """Random points of the domain and around it, with edge values and non-finite ones."""
    if kind in ("interval", "half_line"):
        if kind == "interval":
            x = rng.uniform(-0.5, 1.5, N)
        else:
            x = rng.exponential(1.0, N) * rng.choice([1, -1e-3], N)
        x[:8] = [0.0, 1.0, -0.0, np.nan, np.inf, -np.inf, 1e300, 5e-324]
        return x
    if kind in ("square", "disk"):
        x = rng.uniform(-1.2, 1.2, (N, 2))
        x[:10] = [[0, 0], [1, 1], [0, 1], [-0.0, 0.0], [0.0, -0.0], [-0.0, -0.0], [np.nan, 0.5],
                  [0.5, np.inf], [1.0, 0.0], [-1.0, 0.0]]
        return x
    x = rng.normal(size=(N, 3))
    x /= np.linalg.norm(x, axis=1)[:, None]
    x[: N // 4] *= 1 + rng.uniform(-2e-5, 2e-5, (N // 4, 1))   # around the 1e-5 norm tolerance
    x[:10] = [[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, -1, 0], [0, 0, -1e-12], [0, 0, -2e-12],
              [np.nan, 0, 1], [0, np.inf, 0], [0.6, 0.8, 0.0]]
    return x


def azimuth_reference(x: np.ndarray) -> np.ndarray:
    """mod(atan2(y, x) / (2 pi), 1) in long double, rounded to double."""
    ld = np.longdouble
    t = np.arctan2(x[:, 1].astype(ld), x[:, 0].astype(ld)) / (2 * np.pi * ld(1))
    return np.mod(t, ld(1)).astype(float)


def circular_ulps(got: np.ndarray, ref: np.ndarray) -> np.ndarray:
    d = np.abs(got - ref)
    d = np.minimum(d, 1 - d)                   # 0 and 1 are the same azimuth
    return d / np.spacing(np.maximum(np.maximum(np.abs(ref), np.abs(got)), 2.0**-1022))


# --- domain maps -----------------------------------------------------------------------------
@pytest.mark.parametrize("kind", rest.CHECK_DOMAINS)
def test_domain_params_match_numpy(kind):
    rng = np.random.default_rng(1)
    x = points(kind, rng)
    lo, hi = (-0.25, 1.25) if kind == "interval" else (0.0, 1.0)
    s, inside = rest.domain_params(kind, x, lo, hi)
    ref_s, ref_inside = params_reference(kind, x, lo, hi)
    assert s.shape == ref_s.shape and inside.dtype == bool
    np.testing.assert_array_equal(inside, ref_inside)
    np.testing.assert_array_equal(s[:, 0], ref_s[:, 0])     # no azimuth: the same operations
    if s.shape[1] == 2 and kind != "square":
        fin = np.all(np.isfinite(x[:, :2]), axis=1)
        assert np.all(np.isnan(s[~fin & ~np.isinf(x[:, :2]).any(axis=1), 1]))
        err = circular_ulps(s[fin, 1], ref_s[fin, 1])
        assert np.all(err <= 2), f"azimuth off by {err.max():.3g} ulp at {x[fin][np.argmax(err)]}"
        assert np.all((s[fin, 1] >= 0) & (s[fin, 1] <= 1))
    elif kind == "square":
        np.testing.assert_array_equal(s, ref_s)


def test_azimuth_is_within_2_ulp_of_long_double_atan2_and_keeps_signed_zeros():
    rng = np.random.default_rng(2)
    mag = 10.0 ** rng.uniform(-300, 300, (200_000, 2))
    x = mag * rng.choice([-1.0, 1.0], mag.shape)
    x[:6] = [[0.0, 0.0], [-0.0, 0.0], [0.0, -0.0], [-0.0, -0.0], [1.0, 1.0], [-1.0, -1.0]]
    s, _ = rest.domain_params("disk", x)
    err = circular_ulps(s[:, 1], azimuth_reference(x))
    assert np.all(err <= 2), f"worst {err.max():.3g} ulp at {x[np.argmax(err)]}"
    # signed zeros as numpy's mod(arctan2(y, x) / (2 pi), 1): +0 for (+0, +-0) and 0.5 for (-0, +-0)
    assert list(s[:4, 1]) == [0.0, 0.5, 0.0, 0.5] and not np.signbit(s[0, 1]) and not np.signbit(s[2, 1])
    assert s[4, 1] == 0.125 and s[5, 1] == 0.625


@pytest.mark.parametrize("kind", ["hemisphere", "sphere"])
def test_direction_params_are_the_same_in_vector_lanes_and_one_at_a_time(kind):
    """The (hemi)sphere's map runs whole vectors of directions in lanes and a scalar tail: the
    points above (the norm tolerance's edges, the horizon's, NaN and infinite coordinates, the
    poles, signed zeros) give the same parameters and flags bit for bit either way."""
    x = points(kind, np.random.default_rng(3))[:203]
    x[10:14] = [[-0.0, -0.0, 1.0], [0.0, 0.0, 0.0], [0.0, 0.0, -np.inf], [0.0, 0.0, 1.0000001]]
    s, inside = rest.domain_params(kind, x)
    one = [rest.domain_params(kind, x[i:i + 1]) for i in range(len(x))]
    np.testing.assert_array_equal(s.view(np.uint64), np.concatenate([o[0] for o in one]).view(np.uint64))
    np.testing.assert_array_equal(inside, np.concatenate([o[1] for o in one]))


def test_domain_params_reject_a_wrong_shape_or_kind():
    with pytest.raises(ValueError, match="shape"):
        rest.domain_params("sphere", np.zeros((5, 2)))
    for kind in ("interval", "half_line"):     # (N, 1) is N points; (N, 2) is not 2N of them
        np.testing.assert_array_equal(rest.domain_params(kind, np.full((5, 1), 0.5))[0],
                                      rest.domain_params(kind, np.full(5, 0.5))[0])
        with pytest.raises(ValueError, match="shape"):
            rest.domain_params(kind, np.zeros((5, 2)))
    with pytest.raises(ValueError, match="'kind' must be one of"):
        rest.domain_params("torus", np.zeros((5, 2)))


@pytest.mark.parametrize("kind", ["disk", "hemisphere", "sphere"])
def test_domain_points_vector_lanes_equal_the_scalar_tail_and_numpy(kind):
    rng = np.random.default_rng(3)
    s = rng.random((N + 3, 2))      # not a multiple of any vector width: a scalar tail too
    s[:6] = [[0, 0], [1, 0.25], [0.5, 0.5], [0, 0.75], [1, 1], [0.25, 0.999999]]
    x = rest.domain_points(kind, s)
    one_by_one = np.concatenate([rest.domain_points(kind, s[i:i + 1]) for i in range(200)])
    np.testing.assert_array_equal(x[:200].view(np.uint64), one_by_one.view(np.uint64))
    # numpy's forms of the maps; its cos(2 pi s1) first rounds 2 pi s1, so 1e-15 apart
    phi = 2 * np.pi * s[:, 1]
    if kind == "disk":
        r, z = np.sqrt(s[:, 0]), None
    else:
        z = s[:, 0] if kind == "hemisphere" else 1 - 2 * s[:, 0]
        r = np.sqrt(np.maximum(1 - z * z, 0))
    ref = np.column_stack([r * np.cos(phi), r * np.sin(phi)] + ([] if z is None else [z]))
    np.testing.assert_allclose(x, ref, rtol=0, atol=2e-15)


# --- cubature rules --------------------------------------------------------------------------
GL_X = (np.polynomial.legendre.leggauss(4)[0] + 1) / 2
GL_W = np.polynomial.legendre.leggauss(4)[1] / 2


def random_boxes(k: int, m: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    lo = rng.random((m, k)) * 0.9
    hi = lo + rng.random((m, k)) * 0.1
    lo[:2], hi[:2] = 0.0, 1.0                  # the whole square and an edge-to-edge box
    return lo, hi


@pytest.mark.parametrize("k", [1, 2])
def test_cubature_nodes_are_the_meshgrid_of_each_box(k):
    lo, hi = random_boxes(k, 500, np.random.default_rng(4))
    axes = [lo[:, None, j] + (hi - lo)[:, None, j] * GL_X[None, :] for j in range(k)]   # (M, g) each
    if k == 1:
        ref = axes[0].reshape(-1, 1)
    else:
        ref = np.stack([np.repeat(axes[0], 4, axis=1), np.tile(axes[1], (1, 4))], axis=-1).reshape(-1, 2)
    np.testing.assert_array_equal(rest.cubature_nodes(lo, hi, GL_X), ref)


# boxes enough for several of cubature_points' chunks (a quarter of 2^16 nodes) on every
# thread, an odd count (a scalar tail after the vector lanes); 3 and 9 nodes an axis besides
# the rule's 4 (9: beyond the separable maps' 8, the nodes mapped one by one)
@pytest.mark.parametrize("kind", rest.CHECK_DOMAINS)
@pytest.mark.parametrize("g", [4, 3, 9])
def test_cubature_points_are_the_domain_points_of_the_nodes(kind, g):
    k = 1 if kind in ("interval", "half_line") else 2
    lo, hi = random_boxes(k, 40_001 // g**k | 1, np.random.default_rng(5))
    nodes = np.sort(np.random.default_rng(g).random(g)) if g != 4 else GL_X
    ends = (-2.0, 3.0) if kind == "interval" else (0.0, 1.0)
    got = rest.cubature_points(kind, lo, hi, nodes, ends)
    ref = rest.domain_points(kind, rest.cubature_nodes(lo, hi, nodes), *ends)
    np.testing.assert_array_equal(got.view(np.uint64), ref.view(np.uint64))
    if ref.ndim == 2:   # the columns permuted in place: numpy's ref[:, columns], bit for bit
        columns = [1, 2, 0] if ref.shape[1] == 3 else [1, 0]
        got = rest.cubature_points(kind, lo, hi, nodes, ends, columns)
        np.testing.assert_array_equal(got.view(np.uint64), ref[:, columns].view(np.uint64))
        with pytest.raises(ValueError, match="permutation"):
            rest.cubature_points(kind, lo, hi, nodes, ends, [0, 0, 1][: ref.shape[1]])


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


@pytest.mark.parametrize("boxes", [0, 1, 7, 8, 9, 8 * 5 + 3])
def test_interleaved_order_is_the_blocks_node_major_order(boxes):
    values = np.random.default_rng(boxes).random((2, boxes * 9))
    np.testing.assert_array_equal(values[:, rest.interleaved_order(boxes, 9)], interleaved(values, boxes, 9))


@pytest.mark.parametrize("kind", ["hemisphere", "sphere"])
@pytest.mark.parametrize("g", [4, 3, 9])
def test_cubature_float32_directions_are_the_rounded_cubature_points(kind, g):
    """The nodes' directions as float32 columns in one pass: float32_unit_rows of
    cubature_points' rows, bit for bit, in the interleaved order (blocks of 8 boxes, a short
    one last), with the pole's permutation, with a slack of 1e-18 (every row not of squared
    length exactly 1 through the normalising path) and with slacks of 3 and NaN (no inner
    interval: every row one at a time); other domains refused."""
    lo, hi = random_boxes(2, 40_001 // g**2 | 1, np.random.default_rng(15))
    lo[:3], hi[:3] = 0.0, 1.0        # whole-domain boxes: nodes near both poles
    assert lo.shape[0] % 8
    nodes = np.sort(np.random.default_rng(g).random(g)) if g != 4 else GL_X
    for columns in (None, [2, 0, 1]):
        for slack in (1e-6, 1e-18, 3.0, math.nan):
            points = rest.cubature_points(kind, lo, hi, nodes, columns=columns)
            cols, ok = rest.float32_unit_rows(points, slack)
            got = rest.cubature_float32_directions(kind, lo, hi, nodes, columns, slack)
            assert got[0].dtype == np.float32 and got[0].shape == (3, lo.shape[0] * g * g)
            assert all(c.flags.c_contiguous for c in got[0])
            want = interleaved(cols, lo.shape[0], g * g)
            np.testing.assert_array_equal(got[0].view(np.uint32), want.view(np.uint32))
            np.testing.assert_array_equal(got[1], interleaved(ok, lo.shape[0], g * g))
    with pytest.raises(ValueError, match="hemisphere or sphere"):
        rest.cubature_float32_directions("disk", lo, hi, nodes)
    with pytest.raises(ValueError, match="permutation"):
        rest.cubature_float32_directions(kind, lo, hi, nodes, [0, 0, 1])


@pytest.mark.parametrize("boxes", [5_003, 8, 3])
def test_cubature_sums_of_float32_or_interleaved_values_are_those_of_the_float64_box_major_ones(boxes):
    """A float32 renderer's pdf values summed as returned (widened as read) and in the
    interleaved order: the same bits as the float64 copy in box-major order."""
    rng = np.random.default_rng(16)
    lo, hi = random_boxes(2, boxes, rng)
    w = np.outer(GL_W, GL_W).reshape(-1)
    v = rng.lognormal(0, 3, lo.shape[0] * w.size).astype(np.float32)
    v[[0, 40 % v.size]] = [np.inf, np.nan]
    want = rest.cubature_sums(lo, hi, v.astype(np.float64), w, 4 * math.pi)
    for values, order in [(v, False), (interleaved(v, boxes, w.size), True),
                          (interleaved(v, boxes, w.size).astype(np.float64), True)]:
        got = rest.cubature_sums(lo, hi, values, w, 4 * math.pi, interleaved=order)
        np.testing.assert_array_equal(got.view(np.uint64), want.view(np.uint64))
    with pytest.raises(ValueError, match="one column"):
        rest.cubature_sums(lo, hi, np.ones((v.size, 2)), w, interleaved=True)


@pytest.mark.parametrize("k, cols", [(1, 0), (2, 0), (2, 3)])
def test_cubature_sums_are_each_boxes_weighted_sum_times_its_volume(k, cols):
    rng = np.random.default_rng(6)
    lo, hi = random_boxes(k, 9_001, rng)
    w = GL_W if k == 1 else np.outer(GL_W, GL_W).reshape(-1)
    shape = (lo.shape[0] * w.size,) + ((cols,) if cols else ())
    v = rng.lognormal(0, 3, shape)
    got = rest.cubature_sums(lo, hi, v, w)
    ref = np.einsum("mwc,w->mc", v.reshape(lo.shape[0], w.size, -1), w) * np.prod(hi - lo, axis=1)[:, None]
    assert got.shape == (lo.shape[0], max(cols, 1))
    np.testing.assert_allclose(got, ref, rtol=1e-14, atol=0)
    scaled = rest.cubature_sums(lo, hi, v, w, 2 * math.pi)   # a constant factor, per box
    np.testing.assert_array_equal(scaled, got * (2 * math.pi))


@pytest.mark.parametrize("cols", [0, 3, 6])
def test_cubature_sums_of_several_columns_are_each_columns_own_sums(cols):
    """Columns summed in one pass (four at a time): each the same bits as that column alone."""
    rng = np.random.default_rng(7)
    lo, hi = random_boxes(2, 3_001, rng)
    w = np.outer(GL_W, GL_W).reshape(-1)
    v = rng.lognormal(0, 3, (lo.shape[0] * w.size, max(cols, 1)))
    got = rest.cubature_sums(lo, hi, v if cols else v[:, 0], w)
    for j in range(max(cols, 1)):
        alone = rest.cubature_sums(lo, hi, np.ascontiguousarray(v[:, j]), w)
        np.testing.assert_array_equal(got[:, j].view(np.uint64), alone[:, 0].view(np.uint64))


@pytest.mark.parametrize("c", [0.7, 0.0, -1.0])
def test_cubature_moment_sums_are_the_sums_of_the_moment_columns(c):
    """The fused moment integrals: the same bits as cubature_sums of the columns (q, h q, h^2 q)
    made in numpy (harness.samplers.domains.MomentColumns), zeros, infinities and NaN included."""
    from harness.samplers.domains import MomentColumns
    rng = np.random.default_rng(8)
    lo, hi = random_boxes(2, 3_001, rng)
    w = np.outer(GL_W, GL_W).reshape(-1)
    q = rng.lognormal(0, 3, lo.shape[0] * w.size)
    q[rng.integers(0, q.size, 300)] = 0.0
    q[[5, 77, 901]] = [np.inf, np.nan, 1e300]
    with np.errstate(invalid="ignore"):
        want = rest.cubature_sums(lo, hi, MomentColumns(c)(q), w)
        got = rest.cubature_moment_sums(lo, hi, q, w, c)
    np.testing.assert_array_equal(got.view(np.uint64), want.view(np.uint64))


@pytest.mark.parametrize("boxes", [3_001, 8, 5])
def test_cubature_moment_sums_of_scaled_float32_or_interleaved_values_are_numpys(boxes):
    """A float32 renderer's densities times the Jacobian (scale), read as returned and in the
    interleaved order: the same bits as the moment columns of numpy's float64 product."""
    from harness.samplers.domains import MomentColumns
    rng = np.random.default_rng(18)
    lo, hi = random_boxes(2, boxes, rng)
    w = np.outer(GL_W, GL_W).reshape(-1)
    p = rng.lognormal(0, 3, lo.shape[0] * w.size).astype(np.float32)
    p[[0, 3]] = [0.0, np.inf]
    order = rest.interleaved_order(boxes, w.size)
    for c in (0.7, 0.0):
        with np.errstate(invalid="ignore"):
            want = rest.cubature_sums(lo, hi, MomentColumns(c)(p.astype(np.float64) * (4 * math.pi)), w)
            for values, flag in [(p, False), (p[order], True), (p[order].astype(np.float64), True)]:
                got = rest.cubature_moment_sums(lo, hi, values, w, c, 4 * math.pi, interleaved=flag)
                np.testing.assert_array_equal(got.view(np.uint64), want.view(np.uint64))


def test_cubature_kernels_reject_mismatched_boxes_and_values():
    lo, hi = np.zeros((3, 2)), np.ones((3, 2))
    with pytest.raises(ValueError, match="shape"):
        rest.cubature_nodes(lo, np.ones((3, 1)), GL_X)
    with pytest.raises(ValueError, match="dimension"):
        rest.cubature_points("interval", lo, hi, GL_X)
    with pytest.raises(ValueError, match="one row per node"):
        rest.cubature_sums(lo, hi, np.ones(47), np.ones(16))
    with pytest.raises(ValueError, match="one value per node"):
        rest.cubature_moment_sums(lo, hi, np.ones((48, 2)), np.ones(16), 1.0)
    # no node or weight: refused, not a division by zero
    for call in (lambda: rest.cubature_nodes(lo, hi, []), lambda: rest.cubature_points("sphere", lo, hi, []),
                 lambda: rest.cubature_float32_directions("sphere", lo, hi, []),
                 lambda: rest.cubature_cap_float32_directions(lo, hi, [], [0, 0, 1], [1, 0, 0], [0, 1, 0],
                                                              0.5, 0.5)):
        with pytest.raises(ValueError, match="'nodes' must hold at least one point"):
            call()
    for call in (lambda: rest.cubature_sums(lo, hi, np.ones(0), np.ones(0), interleaved=True),
                 lambda: rest.cubature_sums(lo, hi, np.ones(0), np.ones(0)),
                 lambda: rest.cubature_moment_sums(lo, hi, np.ones(0), np.ones(0), 1.0)):
        with pytest.raises(ValueError, match="'weights' must hold at least one weight"):
            call()


def test_float32_unit_rows_match_numpy_and_name_the_bad_rows():
    rng = np.random.default_rng(4)
    x = rng.normal(size=(N, 3))
    x /= np.linalg.norm(x, axis=1)[:, None]
    x[: N // 4] *= 1 + rng.uniform(-3e-6, 3e-6, (N // 4, 1))   # around the slack
    x[:6] = [[np.nan, 0, 1], [0, 0, 0], [2, 0, 0], [0, np.inf, 0], [0, 0, -1], [3e-100, 0, 0]]
    cols, ok = rest.float32_unit_rows(x, 1e-6)
    norm = np.sqrt(x[:, 0] * x[:, 0] + x[:, 1] * x[:, 1] + x[:, 2] * x[:, 2])
    good = np.isfinite(norm) & (norm > 0)
    with np.errstate(invalid="ignore"):
        scale = np.where(good & (np.abs(norm - 1) > 1e-6), norm, 1.0)
        ref = np.where(good[:, None], x / scale[:, None], [0.0, 0.0, 1.0]).astype(np.float32)
    assert cols.dtype == np.float32 and cols.shape == (3, N) and all(c.flags.c_contiguous for c in cols)
    np.testing.assert_array_equal(ok, good)
    np.testing.assert_array_equal(cols.T, ref)
    assert list(ok[:6]) == [False, False, True, False, True, True]
    assert cols[:, 2].tolist() == [1, 0, 0] and cols[:, 5].tolist() == [1, 0, 0]
    with pytest.raises(ValueError, match="shape"):
        rest.float32_unit_rows(np.zeros((4, 2)), 1e-6)


# --- the cap's equal-area map (Mitsuba area lights) -------------------------------------------
def cap_to_world_reference(h, axis, t, b, cos_alpha, scale):
    """Cap.to_world in numpy (r as sqrt(x^2 + y^2), as the core computes it)."""
    with np.errstate(all="ignore"):
        x = h / np.sqrt(np.einsum("ij,ij->i", h, h))[:, None]
        c = np.clip(cos_alpha + x[:, 2] * scale, -1.0, 1.0)
        r = np.sqrt(x[:, 0] * x[:, 0] + x[:, 1] * x[:, 1])
        pole = r == 0
        s = np.sqrt(np.maximum(0.0, 1 - c * c)) / np.where(pole, 1.0, r)
        cos_phi, sin_phi = np.where(pole, s, s * x[:, 0]), np.where(pole, 0.0, s * x[:, 1])
    return cos_phi[:, None] * t + sin_phi[:, None] * b + c[:, None] * axis


@pytest.mark.parametrize("g", [4, 9])
def test_cubature_cap_float32_directions_are_the_rounded_cap_map_of_the_nodes(g):
    """An area light's cubature nodes in one pass: float32_unit_rows(cap_to_world(the
    hemisphere's cubature_points)), bit for bit, in the interleaved order, for caps from a
    sliver to past a hemisphere (g = 9: through the rows)."""
    from harness.adapters.mitsuba.cap import Cap

    lo, hi = random_boxes(2, 20_001 // g**2 | 1, np.random.default_rng(17))
    lo[:3], hi[:3] = 0.0, 1.0
    nodes = GL_X if g == 4 else np.sort(np.random.default_rng(g).random(g))
    for cap in (Cap([0.3, -0.2, 0.9], 0.97), Cap([0.0, 0.6, -0.8], 0.9999), Cap([1.0, 0.0, 0.0], -0.3)):
        world = cap.to_world(rest.cubature_points("hemisphere", lo, hi, nodes))
        cols, ok = rest.float32_unit_rows(world, 1e-6)
        got, got_ok = rest.cubature_cap_float32_directions(lo, hi, nodes, cap.axis, cap.t, cap.b,
                                                           cap.cos_alpha, cap.scale, 1e-6)
        want = interleaved(cols, lo.shape[0], g * g)
        np.testing.assert_array_equal(got.view(np.uint32), want.view(np.uint32))
        np.testing.assert_array_equal(got_ok, interleaved(ok, lo.shape[0], g * g))
    with pytest.raises(ValueError, match="3-vectors"):
        rest.cubature_cap_float32_directions(lo, hi, nodes, [0, 0, 1, 0], cap.t, cap.b, 0.5, 0.5)


def test_cap_to_world_matches_the_numpy_map_at_poles_horizons_and_nan():
    rng = np.random.default_rng(12)
    axis = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    t = np.cross([1.0, 0.0, 0.0], axis)
    t /= np.linalg.norm(t)
    b = np.cross(axis, t)
    h = rng.normal(size=(N, 3)) * rng.uniform(0.5, 2.0, (N, 1))      # not normalised
    h[:6] = [[0, 0, 1], [0, 0, 2], [1, 0, 0], [0, -1, 1e-300], [0.3, 0.4, -0.5], [np.nan, 0, 1]]
    got = rest.cap_to_world(h, axis, t, b, 0.8, 0.2)
    ref = cap_to_world_reference(h, axis, t, b, 0.8, 0.2)
    # einsum's norm may differ by an ulp, and sqrt(1 - c^2) near the axis magnifies that: far
    # below the float32 rounding the directions go to Mitsuba with
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-13)
    assert np.isnan(got[5]).all() and np.array_equal(np.isnan(got), np.isnan(ref))
    # rows in vector lanes and in the scalar tail, on one thread's chunk or two: the same bits
    for start in (1, 3, 7):
        assert np.array_equal(rest.cap_to_world(h[start:], axis, t, b, 0.8, 0.2), got[start:], equal_nan=True)
    with pytest.raises(ValueError, match="3-vectors"):
        rest.cap_to_world(h, axis[:2], t, b, 0.8, 0.2)


def cap_to_hemisphere_reference(d, axis, t, b, cos_alpha, scale, rim_slack):
    """Cap.to_hemisphere in numpy, with trigonometry (the map the core's kernel computes by ratios)."""
    with np.errstate(all="ignore"):
        u = d / np.linalg.norm(d, axis=1, keepdims=True)
        c = u @ axis
        c = np.where((c < cos_alpha) & (c >= cos_alpha - rim_slack), cos_alpha, c)
        z = (c - cos_alpha) / scale
        phi = np.arctan2(u @ b, u @ t)
        r = np.sqrt(np.maximum(0.0, 1 - z * z))
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def test_cap_to_hemisphere_is_the_numpy_map_and_inverts_cap_to_world():
    """Random directions (not normalised), the axis itself (azimuth 0), directions just inside,
    on and just below the rim (within the slack: onto the horizon; beyond it: below), below the
    cap, NaN and zero rows; vector lanes and the scalar tail alike."""
    rng = np.random.default_rng(15)
    axis = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    t = np.cross([1.0, 0.0, 0.0], axis)
    t /= np.linalg.norm(t)
    b = np.cross(axis, t)
    cos_alpha, scale, slack = 0.8, 0.2, 2e-7
    d = rng.normal(size=(N, 3)) * rng.uniform(0.5, 2.0, (N, 1))
    rim = np.sqrt(1 - cos_alpha**2)
    d[:8] = [axis, 3 * axis, cos_alpha * axis + rim * t, (cos_alpha - 1e-7) * axis + rim * t,
             (cos_alpha - 1e-6) * axis + rim * t, -axis, [np.nan, 0, 1], [0, 0, 0]]
    got = rest.cap_to_hemisphere(d, axis, t, b, cos_alpha, scale, slack)
    ref = cap_to_hemisphere_reference(d, axis, t, b, cos_alpha, scale, slack)
    # within 1e-6 of the axis the azimuth is rounding noise, the two maps' alike: there both
    # points lie within the small circle of radius r about the pole
    radius = np.hypot(ref[:, 0], ref[:, 1])
    near = (radius < 1e-6) & (ref[:, 2] > 0.5)
    np.testing.assert_allclose(got[~near], ref[~near], rtol=0, atol=1e-13)
    assert np.all(np.abs(got[near] - ref[near]) <= 2 * radius[near, None] + 1e-15)
    assert np.array_equal(np.isnan(got), np.isnan(ref)) and np.isnan(got[6:8]).all()
    assert got[0, :2].tolist() == [0.0, 0.0] and got[0, 2] == pytest.approx(1.0, abs=1e-15)   # the axis
    assert got[3, 2] == 0.0 and got[4, 2] < 0      # within the rim's slack: on the horizon; beyond: below
    frame = (axis, t, b, cos_alpha, scale)
    for start in (1, 3, 7):
        assert np.array_equal(rest.cap_to_hemisphere(d[start:], *frame, slack), got[start:], equal_nan=True)
    h = rng.normal(size=(N, 3))
    h[:, 2] = np.abs(h[:, 2])
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    back = rest.cap_to_hemisphere(rest.cap_to_world(h, *frame), *frame, slack)
    np.testing.assert_allclose(back, h, rtol=0, atol=1e-12)


def test_cap_density_is_numpys_float32_product_where_the_point_is_on_the_hemisphere():
    rng = np.random.default_rng(16)
    h = rng.normal(size=(N, 3))
    h[:5] = [[0, 0, 0.0], [0, 0, -0.0], [0, 0, -1e-300], [np.inf, 0, 1], [np.nan, 0, 1]]
    p = rng.random(N) * 10.0 ** rng.integers(-40, 40, N)
    p[5:9] = [np.nan, np.inf, -1.0, 1e300]
    with np.errstate(over="ignore"):     # 1e300 and beyond float32's range: inf, as numpy rounds
        want = np.where(np.all(np.isfinite(h), axis=1) & (h[:, 2] >= 0),
                        (p.astype(np.float32) * np.float32(0.3)).astype(float), 0.0)
    np.testing.assert_array_equal(rest.cap_density(h, p, 0.3).view(np.uint64), want.view(np.uint64))


# --- the rectangle light's map (Mitsuba area lights) -----------------------------------------
def rectangle_frame(ref=(0.6, -0.4, 0.3)):
    """A tilted parallelogram's frame as harness.adapters.mitsuba.rectangle.Rectangle builds it."""
    from harness.adapters.mitsuba.rectangle import Rectangle

    return Rectangle(ref, (-1.0, 1.0, 1.2), (2.0, 0.1, -0.3), (0.2, -1.8, 0.1)).frame


def rect_square_reference(d, frame, slack):
    """Rectangle.to_domain's definition in numpy, left to right."""
    to_corner, e0, e1, n, dual, height, area = frame
    dn = d[:, 0] * n[0] + d[:, 1] * n[1] + d[:, 2] * n[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = height / dn
        hit = (t > 0) & (t < np.inf)
        tt = np.where(hit, t, 0.0)
        o = [-to_corner[k] + tt * d[:, k] for k in range(3)]
    s = np.stack([o[0] * f[0] + o[1] * f[1] + o[2] * f[2] for f in dual], axis=1)
    with np.errstate(invalid="ignore"):
        s = np.where((s >= -slack) & (s <= 1 + slack), np.clip(s, 0.0, 1.0), s)
    s[~hit] = -1.0
    s[np.isnan(d).any(axis=1)] = np.nan
    return s


def rect_vectors(s, frame):
    to_corner, e0, e1 = frame[:3]
    return [to_corner[k] + s[:, 0] * e0[k] + s[:, 1] * e1[k] for k in range(3)]


def test_rect_to_square_is_its_numpy_definition_bit_for_bit():
    """Rays that hit the plane, miss it (behind ref, parallel), land within the slack of an
    edge (clamped onto it) or beyond it (kept), NaN and zero rows; several chunks."""
    frame = rectangle_frame()
    rng = np.random.default_rng(21)
    s_true = rng.uniform(-0.2, 1.2, (N, 2))
    s_true[:6] = [[0.0, 0.5], [1.0, 0.5], [-5e-7, 0.2], [1 + 5e-7, 0.9], [-2e-6, 0.5], [0.5, 1 + 3e-6]]
    d = rect_world_reference(s_true, frame)
    d[6:9] = -d[6:9]                                    # away from the plane
    d[9] = np.cross(frame[1], frame[2])                 # along the normal, one way or the other
    d[10] = np.cross(frame[3], frame[1])                # parallel to the plane
    d[11:14] = [[np.nan, 0, 1], [0, 0, 0], [np.inf, 0, 0]]
    got = rest.rect_to_square(d, frame, 1e-6)
    with np.errstate(invalid="ignore"):
        want = rect_square_reference(d, frame, 1e-6)
    np.testing.assert_array_equal(got.view(np.uint64), want.view(np.uint64))
    np.testing.assert_allclose(got[:4], [[0.0, 0.5], [1.0, 0.5], [0.0, 0.2], [1.0, 0.9]], rtol=0, atol=1e-12)
    assert got[2, 0] == 0.0 and got[3, 0] == 1.0       # within the slack: onto the edge exactly
    assert got[4, 0] < 0 and got[5, 1] > 1 and (got[6:9] == -1).all() and np.isnan(got[11]).all()
    assert (got[12:14] == -1).all()          # a zero direction (t infinite) and an infinite one: no hit
    far = np.all((np.abs(s_true) > 1e-5) & (np.abs(s_true - 1) > 1e-5), axis=1)   # from the slack's band
    far[:14] = False
    np.testing.assert_allclose(got[far], s_true[far], rtol=0, atol=1e-12)   # the map inverts to_world
    with pytest.raises(ValueError, match="'d' must have shape"):
        rest.rect_to_square(d[:, :2], frame, 1e-6)
    with pytest.raises(ValueError, match="3-vectors"):
        rest.rect_to_square(d, (frame[0][:2], *frame[1:]), 1e-6)
    with pytest.raises(ValueError, match="shape \\(2, 3\\)"):
        rest.rect_to_square(d, (*frame[:4], frame[4].T, *frame[5:]), 1e-6)


def rect_world_reference(s, frame):
    w = rect_vectors(s, frame)
    length = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    return np.stack(w, axis=1) / length[:, None]


def test_rect_to_world_is_its_numpy_definition_bit_for_bit():
    frame = rectangle_frame()
    s = np.random.default_rng(22).uniform(-0.1, 1.1, (N, 2))
    s[:3] = [[0.0, 0.0], [1.0, 1.0], [np.nan, 0.5]]
    got = rest.rect_to_world(s, frame)
    np.testing.assert_array_equal(got.view(np.uint64), rect_world_reference(s, frame).view(np.uint64))
    with pytest.raises(ValueError, match="'s' must have shape"):
        rest.rect_to_world(s[:, :1], frame)


def test_rect_density_is_numpys_float32_product_inside_the_square():
    """float32(p) * float32(J(s)), J = area |<w, n>| / (dist2 sqrt(dist2)); 0 outside [0, 1]^2
    and at NaN points; NaN, infinite and huge p as numpy rounds them."""
    frame = rectangle_frame()
    rng = np.random.default_rng(23)
    s = rng.uniform(-0.05, 1.05, (N, 2))
    s[:4] = [[0.0, 1.0], [np.nan, 0.5], [0.5, -0.0], [np.inf, 0.5]]
    p = rng.random(N) * 10.0 ** rng.integers(-40, 40, N)
    p[4:8] = [np.nan, np.inf, -1.0, 1e300]
    area, n = frame[6], frame[3]
    inside = (s[:, 0] >= 0) & (s[:, 0] <= 1) & (s[:, 1] >= 0) & (s[:, 1] <= 1)
    w = rect_vectors(np.where(inside[:, None], s, 0.5), frame)
    dist2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2]
    jac = area * np.abs(w[0] * n[0] + w[1] * n[1] + w[2] * n[2]) / (dist2 * np.sqrt(dist2))
    with np.errstate(over="ignore", invalid="ignore"):
        want = np.where(inside, (p.astype(np.float32) * jac.astype(np.float32)).astype(float), 0.0)
    got = rest.rect_density(s, p, frame)
    np.testing.assert_array_equal(got.view(np.uint64), want.view(np.uint64))
    assert got[1] == 0 and got[3] == 0 and got[2] > 0
    with pytest.raises(ValueError, match="one value per row"):
        rest.rect_density(s, p[:-1], frame)


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


# --- transform statistics, Cramer-von Mises, pdf summary --------------------------------------
@pytest.mark.parametrize("square", [False, True])
def test_transform_statistics_match_the_transform_counted_and_sorted_in_numpy(square):
    rng = np.random.default_rng(7)
    marginal = random_table(rng, 1, 3000)
    conditional = random_table(rng, 32, 200) if square else None
    edges = np.concatenate([[0.0], np.sort(rng.random(31)), [1.0]])
    n = 200_000        # several chunks of the core's, on every thread
    s = rng.random((n, 2 if square else 1))
    s[:3, -1] = [0.0, 1.0, np.nextafter(1, 0)]
    bins = 64
    sums, counts = rest.transform_statistics(marginal, conditional, edges, s, bins)
    u, strip = rest.rosenblatt(marginal, conditional, edges, s)
    v = u[:, -1]
    j = np.minimum((v * bins).astype(np.int64), bins - 1)
    expected = np.bincount(strip * bins + j, minlength=(32 if square else 1) * bins)
    np.testing.assert_array_equal(counts, expected)
    np.testing.assert_array_equal(sums, rest.cramer_von_mises_sum(u))
    for c in range(u.shape[1]):
        assert_brackets(sums[c], cvm_sum_reference(u[:, c]))


def test_transform_statistics_count_no_nan_and_give_nan_sums():
    rng = np.random.default_rng(10)
    marginal, conditional = random_table(rng, 1, 10), random_table(rng, 4, 10)
    edges = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
    s = rng.random((1000, 2))
    s[0, 1] = np.nan
    sums, counts = rest.transform_statistics(marginal, conditional, edges, s, 8)
    assert counts.sum() == 999 and np.isnan(sums[1]).all() and np.isfinite(sums[0]).all()


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


def cvm_sum_reference(u: np.ndarray) -> float:
    """The Cramer-von Mises sum by its definition: a sort of the values clamped to [0, 1]."""
    n = u.size
    c = (2 * np.arange(1, n + 1) - 1) / (2 * n)
    return float(np.sum((c - np.sort(np.clip(u, 0.0, 1.0))) ** 2))


def assert_brackets(bracket: np.ndarray, exact: float) -> None:
    """upper >= exact >= upper - slack, to the sums' rounding (1e-12 relative)."""
    upper, slack = bracket
    tol = 1e-12 * max(exact, 1.0)
    assert upper - slack - tol <= exact <= upper + tol, (upper, slack, exact)


@pytest.mark.parametrize("case", ["uniform", "ties", "crowded", "edges", "outside", "tiny", "pair"])
def test_cramer_von_mises_sum_brackets_the_sorted_sum(case):
    rng = np.random.default_rng(8)
    u = {"uniform": lambda: rng.random(N),
         "ties": lambda: rng.integers(0, 50, N) / 49.0,
         "crowded": lambda: 0.5 + 1e-9 * rng.random(N),          # all in one cell
         "edges": lambda: np.concatenate([np.zeros(500), np.ones(500), rng.random(N)]),
         "outside": lambda: rng.uniform(-0.5, 1.5, N),
         "tiny": lambda: np.array([0.3]),
         "pair": lambda: np.array([0.7, 0.2])}[case]()
    assert_brackets(rest.cramer_von_mises_sum(u)[0], cvm_sum_reference(u))


def test_cramer_von_mises_sum_clamps_to_the_unit_interval():
    """Values outside [0, 1] count as 0 or 1 (the uniform CDF there): one outlier leaves the
    bracket as tight as without it, where widening the outer cells to reach it had made the
    slack 50001 against S = 33334."""
    u = np.append(np.ones(99_999), 2.0)
    upper, slack = rest.cramer_von_mises_sum(u)[0]
    assert slack == pytest.approx(rest.cramer_von_mises_sum(np.ones(100_000))[0][1])
    assert_brackets((upper, slack), cvm_sum_reference(u))
    assert cvm_sum_reference(u) > 3e4


@pytest.mark.parametrize("n", [1000, 100_000, 1_000_000])
def test_cramer_von_mises_sum_is_tight_for_spread_values(n):
    """The bracket's width for values spread over [0, 1] stays near n / (2 K^2) <= 1.2e-4 at
    any n (K about 64 sqrt(n) cells), where the statistic's 1 % point is 0.74: the test loses
    no power to it.  Its actual error is about a third of it."""
    u = np.random.default_rng(n).random(n) ** 1.005
    upper, slack = rest.cramer_von_mises_sum(u)[0]
    assert 0 < slack <= 1.3e-4
    assert 0 < upper - cvm_sum_reference(u) <= slack / 2


@settings(max_examples=200, deadline=None, derandomize=True)
@given(arrays(np.float64, st.integers(1, 3000), elements=st.floats(-0.25, 1.25)))
def test_cramer_von_mises_sum_brackets_any_values(u):
    assert_brackets(rest.cramer_von_mises_sum(u)[0], cvm_sum_reference(u))


def test_cramer_von_mises_sum_by_column_and_nan():
    rng = np.random.default_rng(9)
    u = rng.random((N, 2))
    got = rest.cramer_von_mises_sum(u)
    assert got.shape == (2, 2)
    for c in range(2):
        assert_brackets(got[c], cvm_sum_reference(u[:, c]))
    # a strided column in reverse: the same cells, the same sum to rounding
    assert rest.cramer_von_mises_sum(u[::-1, 1])[0] == pytest.approx(got[1], rel=1e-12)
    u[17, 1] = np.nan
    got = rest.cramer_von_mises_sum(u)
    assert np.isfinite(got[0]).all() and np.isnan(got[1]).all()


def test_cramer_von_mises_sums_of_concurrent_callers_are_their_own():
    """A suite runs sampler checks on several Python threads at once, and the core's thread
    pool serves them in turn, between the passes of one caller's sum too: each caller's counts
    must stay its own (worker tables kept by the pool's threads were reset under a merge: a
    main-job check of a correct sampler failed with a statistic of 5e4)."""
    rng = np.random.default_rng(15)
    data = [rng.random(n) ** 1.01 for n in (CHUNKS, 2 * CHUNKS, 150_001, 3 * CHUNKS)]
    alone = [rest.cramer_von_mises_sum(u) for u in data]
    with concurrent.futures.ThreadPoolExecutor(max_workers=len(data)) as pool:
        for _ in range(10):
            together = list(pool.map(rest.cramer_von_mises_sum, data))
            for a, b in zip(alone, together):
                np.testing.assert_array_equal(a, b)


def test_cramer_von_mises_sum_over_chunks():
    """Both passes run on the threads in chunks of 2^16 values, their counts merged: the
    bracket of values spanning several chunks is the sorted sum's, and a NaN in the last
    chunk alone makes it NaN."""
    u = np.random.default_rng(12).random(CHUNKS) ** 1.01
    assert_brackets(rest.cramer_von_mises_sum(u)[0], cvm_sum_reference(u))
    u[-1] = np.nan
    assert np.isnan(rest.cramer_von_mises_sum(u)[0]).all()


@pytest.mark.parametrize("n", [N, CHUNKS])
@pytest.mark.parametrize("kind", ["interval", "half_line", "sphere"])
def test_pdf_summary_matches_numpy(kind, n):
    rng = np.random.default_rng(10)
    k = 1 if kind in ("interval", "half_line") else 2
    s = rng.random((n, k))
    inside = rng.random(n) < 0.95
    p = rng.exponential(1.0, n)
    p[:6] = [0.0, -1.0, np.nan, np.inf, -0.0, 5e-324]
    inside[:6] = True
    inside[6:9], p[6:9] = False, [0.0, np.nan, 2.0]
    measure, c = (1.0 if kind == "half_line" else 4 * math.pi), 0.7
    for total in (1.0, 0.8, 3.0):      # the values divided by the total first
        bad, zero, used, h_sum = rest.pdf_summary(kind, measure, s, inside, p, c, total)
        q = p / total
        ref_bad = ~np.isfinite(q) | (q < 0)
        jac = 1.0 / (1.0 - s[:, 0]) ** 2 if kind == "half_line" else measure
        good = inside & ~ref_bad & (q != 0)   # a zero pdf (its own failure) is not used
        ps = (q * jac)[good] if kind == "half_line" else q[good] * jac
        assert bad == int(ref_bad.sum()) and zero == int(((q == 0) & inside).sum()) and used == ps.size
        assert h_sum == pytest.approx(float(np.sum(ps / (ps + c))), rel=1e-12)
    assert rest.pdf_summary(kind, measure, s, inside, p, 0.0)[3] == 0.0
