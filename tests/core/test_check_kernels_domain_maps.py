"""Domain maps in the core (domain_params, domain_points, the azimuth) against numpy; see
check_kernel_helpers."""
from __future__ import annotations

import math

import numpy as np
import pytest

import reference_estimators as rest

from tests.core.check_kernel_helpers import N


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
    a, b, c = x.T
    t = a * a + b * b
    norm = t + c * c
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        ok = np.all(np.isfinite(x), axis=1) & (np.abs(norm - 1) <= 1e-5)
        r = np.sqrt(norm)
        north = c >= 0
        across = t / (r * (r + np.where(north, c, -c)))    # 1 -+ cos theta, across the nearer pole
    if kind == "hemisphere":
        return np.column_stack([np.where(north, 1 - across, across - 1), phi]), ok & (c >= -1e-12)
    return np.column_stack([np.where(north, across * 0.5, 1 - across * 0.5), phi]), ok


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


@pytest.mark.parametrize("kind", ["hemisphere", "sphere"])
def test_cos_theta_near_a_pole_is_the_normalised_float32_directions(kind):
    """A float32 renderer's direction near a pole has a z that moves in steps of 6e-8 and a
    length that misses 1 by as much; its x and y keep their relative precision.  s0 is the
    cos theta of the direction normalised, to a few 1e-16 (long double reference), where z
    itself is off by up to 1e-7: a tenth of a narrow lobe's 1 - cos theta at the pole."""
    rng = np.random.default_rng(7)
    n = 4000
    theta = 10.0 ** rng.uniform(-4, -1, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    pole = 1.0 if kind == "hemisphere" else rng.choice([1.0, -1.0], n)   # the sphere's both poles
    exact = np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), pole * np.cos(theta)])
    x = (exact * (1 + rng.uniform(-1.5e-7, 1.5e-7, (n, 1)))).astype(np.float32).astype(np.float64)
    s, inside = rest.domain_params(kind, x)
    assert inside.all()
    ld = x.astype(np.longdouble)
    r = np.sqrt(np.sum(ld * ld, axis=1))
    cos_ld = ld[:, 2] / r
    ref = cos_ld if kind == "hemisphere" else (1 - cos_ld) / 2
    err = np.abs(s[:, 0].astype(np.longdouble) - ref)
    assert float(err.max()) <= 4e-16
    if kind == "sphere":   # near the north pole s0 is small: its relative precision there
        north = pole > 0
        t = ld[north, 0] ** 2 + ld[north, 1] ** 2
        half = t / (r[north] * (r[north] + ld[north, 2])) / 2   # (1 - cos theta) / 2, no cancellation
        rel = np.abs(s[north, 0].astype(np.longdouble) - half) / half
        assert float(rel.max()) <= 1e-15
    z_err = np.abs(np.clip(x[:, 2], -1, 1).astype(np.longdouble) - cos_ld)   # z as s0, as before
    assert float(z_err.max()) > 1e-8
