"""The core's vectorisable elementary functions (fastmath.h, via reference_estimators.kernels)
against numpy.

exp and log are compared with numpy's (glibc's) double-precision results in units in the
last place, ulp = np.spacing(|reference|): at most 2 ulp wherever the result is a normal
number, and at most 2 subnormal steps (2^-1074 each) where exp's result is subnormal.
sin(2 pi u) and cos(2 pi u) are compared in absolute terms (<= 4e-16) with numpy's sin and
cos evaluated in extended precision: in double precision np.sin(2 * np.pi * u) itself is
off by up to ~2.5e-15 for |u| <= 3, because 2 pi u is rounded before the sine is taken.

The inputs are fixed pseudo-random samples (numpy Generator, seed 0) plus hand-picked values;
these are accuracy bounds, not statistical tests.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from reference_estimators import kernels

N = 1_000_000
TINY = np.finfo(np.float64).tiny          # smallest normal double
SUBNORMAL_STEP = np.spacing(0.0)          # 2^-1074
EXTENDED = np.finfo(np.longdouble).nmant >= 63  # x87 80-bit or IEEE quad long double


def ulps(got: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """|got - ref| in units of the reference's last place (np.spacing of |ref|)."""
    return np.abs(got - ref) / np.spacing(np.abs(ref))


def worst(x, got, ref, err, k: int = 5) -> str:
    i = np.argsort(err)[::-1][:k]
    return "\n  ".join(f"x = {x[j]!r}: got {got[j]!r}, numpy {ref[j]!r}, error {err[j]:.3g}" for j in i)


# --- exp ---------------------------------------------------------------------------------
def exp_inputs(kind: str) -> np.ndarray:
    rng = np.random.default_rng(0)
    if kind == "uniform":
        return rng.uniform(-745.0, 709.78, N)
    if kind == "log_uniform":
        mag = 10.0 ** rng.uniform(-300.0, math.log10(745.0), N)
        x = np.where(rng.random(N) < 0.5, -mag, np.minimum(mag, 709.78))
        return x
    if kind == "subnormal_results":
        return rng.uniform(-745.0, -708.4, N // 10)  # exp(x) < 2^-1022 below ~ -708.396
    if kind == "near_zero":
        return rng.uniform(-1.0, 1.0, N)
    if kind == "scaling_switch":   # where exp moves between its exponent-field add and scale2k
        edges = np.nextafter(np.array([-707.0, -707.0, 709.0, 709.0]), [-np.inf, 0, 0, np.inf])
        low, high = rng.uniform(-707.01, -706.99, N // 20), rng.uniform(708.99, 709.01, N // 20)
        return np.concatenate([low, high, edges])
    raise AssertionError(kind)


@pytest.mark.parametrize("kind", ["uniform", "log_uniform", "subnormal_results", "near_zero",
                                  "scaling_switch"])
def test_exp_within_2_ulp(kind):
    x = exp_inputs(kind)
    got, ref = kernels.fast_exp(x), np.exp(x)
    assert np.all(np.isfinite(got)), f"non-finite exp: {x[~np.isfinite(got)][:5]}"
    normal = ref >= TINY
    err = ulps(got[normal], ref[normal])
    assert err.size == 0 or err.max() <= 2, (f"exp error {err.max()} ulp > 2:\n  "
                                             f"{worst(x[normal], got[normal], ref[normal], err)}")
    sub = ~normal
    if kind == "subnormal_results":
        assert sub.sum() > N // 20, "the subnormal range was not exercised"
    steps = np.abs(got[sub] - ref[sub]) / SUBNORMAL_STEP
    assert steps.size == 0 or steps.max() <= 2, (f"exp error {steps.max()} x 2^-1074 on subnormal results:"
                                                 f"\n  {worst(x[sub], got[sub], ref[sub], steps)}")


def test_exp_exact_points():
    x = np.array([0.0, -0.0, 1.0, -1.0, math.log(2.0), 709.78, -708.39, 1e-300, -1e-300])
    got, ref = kernels.fast_exp(x), np.exp(x)
    assert got[0] == 1.0 and got[1] == 1.0
    assert np.all(ulps(got, ref) <= 2), list(zip(x, got, ref))


@pytest.mark.parametrize("x,expected", [
    (math.nan, math.nan), (math.inf, math.inf), (-math.inf, 0.0), (710.0, math.inf), (-746.0, 0.0),
    (1000.0, math.inf), (-1000.0, 0.0), (1e308, math.inf), (-1e308, 0.0),
])
def test_exp_special_values(x, expected):
    got = float(kernels.fast_exp(np.array([x]))[0])
    if math.isnan(expected):
        assert math.isnan(got), f"exp({x}) = {got!r}, expected nan"
    else:
        assert got == expected, f"exp({x}) = {got!r}, expected {expected!r}"


def test_exp_overflow_threshold_agrees_with_numpy():
    x = (np.nextafter(709.782712893384, np.array([-np.inf] * 3 + [np.inf] * 3))
         + np.array([0, -1e-13, -5e-13, 0, 1e-13, 5e-13]))
    x = np.concatenate([x, [709.782712893384, 709.78271289338397]])
    with np.errstate(over="ignore"):
        ref = np.exp(x)
    got = kernels.fast_exp(x)
    assert np.array_equal(np.isinf(got), np.isinf(ref)), list(zip(x, got, ref))
    fin = np.isfinite(ref)
    assert np.all(ulps(got[fin], ref[fin]) <= 2), list(zip(x[fin], got[fin], ref[fin]))


def test_exp_vector_body_and_scalar_tail_agree_bitwise():
    """fast_exp runs whole vectors (AVX-512: permute and vscalefpd) and a scalar tail (table
    load and two exact-or-once-rounded scalings): one array against the same values passed one
    at a time (all tail) must agree bit for bit, subnormal and special results included."""
    rng = np.random.default_rng(1)
    x = np.concatenate([rng.uniform(-746.0, 710.0, 3000), rng.uniform(-745.2, -708.0, 1000),
                        rng.uniform(-1e-3, 1e-3, 500),
                        [0.0, -0.0, math.nan, math.inf, -math.inf, 709.782712893384, -745.13, 1e-300]])
    whole = kernels.fast_exp(x)
    one_by_one = np.array([kernels.fast_exp(x[i:i + 1])[0] for i in range(x.size)])
    assert np.array_equal(whole.view(np.uint64), one_by_one.view(np.uint64)), (
        x[whole.view(np.uint64) != one_by_one.view(np.uint64)][:5])


# --- log ---------------------------------------------------------------------------------
def test_log_vector_body_and_scalar_tail_agree_bitwise():
    """fast_log runs whole vectors and a scalar tail (the same template): one array against
    the same values passed one at a time (all tail) must agree bit for bit, subnormal inputs,
    the sqrt(2) boundary and special values included."""
    rng = np.random.default_rng(3)
    x = np.concatenate([10.0 ** rng.uniform(-323.0, 308.0, 3000), rng.uniform(0.7, 1.5, 1000),
                        rng.uniform(-1.0, 1.0, 200), np.nextafter(math.sqrt(2), [0.0, 2.0]),
                        [0.0, -0.0, 5e-324, 2.2250738585072014e-308, 1.0, math.nan, math.inf, -math.inf]])
    whole = kernels.fast_log(x)
    one_by_one = np.array([kernels.fast_log(x[i:i + 1])[0] for i in range(x.size)])
    assert np.array_equal(whole.view(np.uint64), one_by_one.view(np.uint64)), (
        x[whole.view(np.uint64) != one_by_one.view(np.uint64)][:5])


def log_inputs(kind: str) -> np.ndarray:
    rng = np.random.default_rng(0)
    if kind == "log_uniform":
        return 10.0 ** rng.uniform(-320.0, 308.0, N)  # subnormal inputs below 2.2e-308
    if kind == "around_one":
        return rng.uniform(0.5, 2.0, N)  # log m - ln 2 cancels near 1/sqrt(2)
    if kind == "subnormal_inputs":
        return rng.uniform(0.0, 1.0, N // 10) * TINY + SUBNORMAL_STEP
    raise AssertionError(kind)


@pytest.mark.parametrize("kind", ["log_uniform", "around_one", "subnormal_inputs"])
def test_log_within_2_ulp(kind):
    x = log_inputs(kind)
    got, ref = kernels.fast_log(x), np.log(x)
    err = ulps(got, ref)
    assert err.max() <= 2, f"log error {err.max()} ulp > 2:\n  {worst(x, got, ref, err)}"


def test_log_exact_points():
    x = np.array([1.0, 2.0, 0.5, math.e, 10.0, SUBNORMAL_STEP, TINY, np.finfo(np.float64).max,
                  np.nextafter(1.0, 2.0), np.nextafter(1.0, 0.0)])
    got, ref = kernels.fast_log(x), np.log(x)
    assert got[0] == 0.0
    assert np.all(ulps(got, ref) <= 2), list(zip(x, got, ref))


@pytest.mark.parametrize("x,expected", [
    (0.0, -math.inf), (-0.0, -math.inf), (-1.0, math.nan), (-math.inf, math.nan), (-1e-320, math.nan),
    (math.inf, math.inf), (math.nan, math.nan),
])
def test_log_special_values(x, expected):
    got = float(kernels.fast_log(np.array([x]))[0])
    if math.isnan(expected):
        assert math.isnan(got), f"log({x}) = {got!r}, expected nan"
    else:
        assert got == expected, f"log({x}) = {got!r}, expected {expected!r}"


# --- sincos_2pi --------------------------------------------------------------------------
def reference_sincos(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """sin(2 pi u), cos(2 pi u) to well below 1e-16 absolute."""
    if EXTENDED:
        two_pi = np.longdouble("6.28318530717958647692528676655900576839")
        a = two_pi * u.astype(np.longdouble)
        return np.sin(a).astype(np.float64), np.cos(a).astype(np.float64)
    # Double precision only: reduce exactly to |r| <= 1/8 of a turn, then rotate by quadrant.
    q = np.rint(4 * u)
    r = (u - np.rint(u)) - (q - 4 * np.rint(u)) / 4  # exact for |u| < 2^50
    s, c = np.sin(2 * np.pi * r), np.cos(2 * np.pi * r)
    k = np.mod(q, 4).astype(int)
    sin = np.choose(k, [s, c, -s, -c])
    cos = np.choose(k, [c, -s, -c, s])
    return sin, cos


def sincos_inputs(kind: str) -> np.ndarray:
    rng = np.random.default_rng(0)
    if kind == "wide":
        return rng.uniform(-3.0, 3.0, N)
    if kind == "canonical":
        # the canonical uniforms the samplers see: (m + 0.5) 2^-52, in (0, 1)
        return (rng.integers(0, 2**52, N, dtype=np.int64) + 0.5) * 2.0**-52
    if kind == "quarter_turns":
        k = np.arange(-12, 13) / 4
        return np.concatenate([k, np.nextafter(k, np.inf), np.nextafter(k, -np.inf), k + 1e-9, k - 1e-9,
                               [(0.5) * 2.0**-52, 1 - 0.5 * 2.0**-52]])
    raise AssertionError(kind)


@pytest.mark.parametrize("kind", ["wide", "canonical", "quarter_turns"])
def test_sincos_2pi_absolute_error(kind):
    u = sincos_inputs(kind)
    s, c = kernels.fast_sincos_2pi(u)
    rs, rc = reference_sincos(u)
    es, ec = np.abs(s - rs), np.abs(c - rc)
    assert es.max() <= 4e-16, f"sin(2 pi u) error {es.max():.3g} > 4e-16:\n  {worst(u, s, rs, es)}"
    assert ec.max() <= 4e-16, f"cos(2 pi u) error {ec.max():.3g} > 4e-16:\n  {worst(u, c, rc, ec)}"


def test_sincos_2pi_against_plain_numpy_on_canonical_uniforms():
    """Against plain double-precision np.sin(2 pi u), np.cos(2 pi u): those carry the rounding
    of 2 pi u (up to ~4.4e-16 for u < 1), so the bound here is that plus 4e-16."""
    u = sincos_inputs("canonical")
    s, c = kernels.fast_sincos_2pi(u)
    a = 2 * np.pi * u
    bound = 4e-16 + np.spacing(a)
    assert np.all(np.abs(s - np.sin(a)) <= bound)
    assert np.all(np.abs(c - np.cos(a)) <= bound)


def test_sincos_2pi_exact_quarter_turns():
    u = np.array([0.0, 0.25, 0.5, 0.75, 1.0, -0.25, 2.0])
    s, c = kernels.fast_sincos_2pi(u)
    assert np.array_equal(s, [0.0, 1.0, 0.0, -1.0, 0.0, -1.0, 0.0]), s
    assert np.array_equal(c, [1.0, 0.0, -1.0, 0.0, 1.0, 0.0, 1.0]), c
