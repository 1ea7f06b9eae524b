"""Cubature kernels (nodes, points, float32 directions, sums, moment sums, float32_unit_rows) against
numpy."""
from __future__ import annotations

import math

import numpy as np
import pytest

import reference_estimators as rest

from tests.core.check_kernel_helpers import GL_W, GL_X, N, interleaved, random_boxes


# --- cubature rules --------------------------------------------------------------------------
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
