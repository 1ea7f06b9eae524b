"""The random streams: PCG32 as published, one stream per chunk, bitwise reproducibility."""
from __future__ import annotations

import numpy as np
import pytest

import reference_estimators as rest
from reference_estimators import _core

M64 = (1 << 64) - 1


def splitmix64(x: int) -> int:
    x = (x + 0x9E3779B97F4A7C15) & M64
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & M64
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & M64
    return x ^ (x >> 31)


class Pcg32:
    """O'Neill's pcg32 (XSH-RR 64/32) with pcg32_srandom_r seeding, in plain Python."""

    MULT = 0x5851F42D4C957F2D

    def __init__(self, seed: int, case_id: int, replica: int, chunk: int):
        h = splitmix64(seed ^ splitmix64(case_id ^ splitmix64(replica ^ splitmix64(chunk))))
        initstate, initseq = splitmix64(h), splitmix64(h ^ 0xDA3E39CB94B95BDB)
        self.inc = ((initseq << 1) | 1) & M64
        self.state = 0
        self.next()
        self.state = (self.state + initstate) & M64
        self.next()

    def next(self) -> int:
        old = self.state
        self.state = (old * self.MULT + self.inc) & M64
        xorshifted = (((old >> 18) ^ old) >> 27) & 0xFFFFFFFF
        rot = old >> 59
        return ((xorshifted >> rot) | (xorshifted << ((-rot) & 31))) & 0xFFFFFFFF


@pytest.mark.parametrize("key", [(0, 0, 0, 0), (1, 2, 3, 4), (2**64 - 1, 7, 0, 123456)])
def test_scalar_generator_is_published_pcg32(key):
    ref = Pcg32(*key)
    expected = [ref.next() for _ in range(100)]
    assert _core.pcg32_outputs(100, *key) == expected


@pytest.mark.parametrize("n", [1, 7, 31, 32, 33, 255, 256, 1000, 4099])
def test_lane_generator_reproduces_the_scalar_stream(n):
    key = (5, 1, 2, 3)
    out = np.array(_core.pcg32_outputs(2 * n, *key), dtype=np.uint64)
    bits = ((out[0::2] << np.uint64(32)) | out[1::2]) >> np.uint64(12)
    expected = (bits.astype(np.float64) + 0.5) * 2.0**-52
    np.testing.assert_array_equal(_core.uniforms(n, *key), expected)


def test_uniforms_lie_strictly_inside_the_unit_interval():
    u = _core.uniforms(1_000_000, seed=9)
    assert u.min() > 0.0 and u.max() < 1.0


def test_stream_keys_give_distinct_streams():
    base = _core.uniforms(64, 0, 0, 0, 0)
    for key in [(1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1)]:
        assert not np.array_equal(base, _core.uniforms(64, *key)), key


CASES = [
    ("gaussian", "uniform"),
    ("gaussian", "rejection"),
    ("peak", "importance:trimmed_logistic"),
    ("half_cauchy", "importance:exponential"),
    ("ggx_lobe", "importance:cosine_hemisphere"),
    ("spherical_cap", "importance:uniform_cone"),
    ("gaussian2d", "importance:piecewise_constant_2d"),
    ("gaussian16", "uniform"),
    ("tiny", "uniform"),
]
FIELDS = ("mean", "stderr", "variance", "log10_variance", "skewness", "kurtosis", "min", "max", "n", "drawn", "counts")


@pytest.mark.parametrize("integrand, technique", CASES)
def test_results_are_bitwise_identical_for_any_thread_count(integrand, technique):
    n = 3 * rest.CHUNK_SIZE + 12345  # a partial last chunk too
    runs = {t: rest.integrate(integrand, technique, n, seed=11, threads=t) for t in (1, 2, 3, 8)}
    for t, est in runs.items():
        for field in FIELDS:
            a, b = getattr(runs[1], field), getattr(est, field)
            assert a == b or (a != a and b != b), f"{field}: 1 thread {a!r} != {t} threads {b!r}"
    ys = [rest.contributions(integrand, technique, n, seed=11, threads=t) for t in (1, 3)]
    np.testing.assert_array_equal(ys[0], ys[1])


def test_contributions_are_what_integrate_averages():
    y = rest.contributions("gaussian", "importance:linear", 200_000, seed=4)
    est = rest.integrate("gaussian", "importance:linear", 200_000, seed=4)
    assert est.n == y.size
    assert est.mean == pytest.approx(np.mean(y), rel=1e-14)
    assert est.variance == pytest.approx(np.var(y, ddof=1), rel=1e-12)


def test_replicas_are_independent_streams():
    a = rest.integrate("gaussian", "uniform", 100_000, seed=0, replica=0)
    b = rest.integrate("gaussian", "uniform", 100_000, seed=0, replica=1)
    assert a.mean != b.mean
