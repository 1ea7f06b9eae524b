"""The Mitsuba area lights' maps in the core: the cap's equal-area map and the rectangle's square, against
numpy."""
from __future__ import annotations

import numpy as np
import pytest

import reference_estimators as rest

from tests.core.check_kernel_helpers import GL_X, N, interleaved, random_boxes


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
