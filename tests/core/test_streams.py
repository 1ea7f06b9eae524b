"""The random streams: PCG32 as published, one stream per chunk, bitwise reproducibility, and
estimates computed in pieces (integrate_chunks, estimate_from_states)."""
from __future__ import annotations

import numpy as np
import pytest

import reference_estimators as rest
from reference_estimators import kernels

M64 = (1 << 64) - 1


def stream(key: tuple[int, int, int, int]) -> dict[str, int]:
    """A stream key (seed, case_id, replica, chunk) as the kernels' keyword arguments."""
    return dict(zip(("seed", "case_id", "replica", "chunk"), key))


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
    assert kernels.pcg32_outputs(100, **stream(key)).tolist() == expected


@pytest.mark.parametrize("n", [1, 7, 31, 32, 33, 255, 256, 1000, 4099])
def test_lane_generator_reproduces_the_scalar_stream(n):
    key = (5, 1, 2, 3)
    out = kernels.pcg32_outputs(2 * n, **stream(key)).astype(np.uint64)
    bits = ((out[0::2] << np.uint64(32)) | out[1::2]) >> np.uint64(12)
    expected = (bits.astype(np.float64) + 0.5) * 2.0**-52
    np.testing.assert_array_equal(kernels.uniforms(n, **stream(key)), expected)


@pytest.mark.parametrize("pieces", [
    [(4096, True)],                                           # row-aligned: the lanes' shortcut alone
    [(4096, True), (4096, False), (64, True), (8194, True)],  # shortcut, whole rows, a pair left over
    [(34, True), (100, False), (62, True), (4096, True)],     # a piece that ends mid-row, then unaligned
    [(2, True), (30, True), (64, True), (6, False), (4098, True), (32, False)],
])
def test_even_uniforms_are_the_streams_own(pieces):
    """The polar path's even-numbered uniforms (LaneGenerator::fill_even) are the stream's at
    those positions, and the stream goes on from where a whole fill would leave it: aligned
    or not, whole rows or a remainder, between whole fills."""
    counts, evens = zip(*pieces)
    got = kernels.uniforms_in_pieces(list(counts), list(evens), seed=11)
    whole = kernels.uniforms(sum(counts), seed=11)
    at = np.cumsum((0,) + counts)
    expected = np.concatenate([whole[a:b:2] if e else whole[a:b] for a, b, e in zip(at[:-1], at[1:], evens)])
    np.testing.assert_array_equal(got, expected)


def test_uniforms_lie_strictly_inside_the_unit_interval():
    u = kernels.uniforms(1_000_000, seed=9)
    assert u.min() > 0.0 and u.max() < 1.0


def test_stream_keys_give_distinct_streams():
    base = kernels.uniforms(64, **stream((0, 0, 0, 0)))
    for key in [(1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1)]:
        assert not np.array_equal(base, kernels.uniforms(64, **stream(key))), key


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
FIELDS = ("mean", "stderr", "variance", "log10_variance", "skewness", "kurtosis", "min", "max", "n", "drawn",
          "counts")


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


def test_uniforms_are_what_integrate_draws_in_a_chunk():
    """Chunk c of an estimate draws from stream (seed, case_id, replica, c): the points of a
    random point set are those uniforms, row by row."""
    n = rest.CHUNK_SIZE + 10
    u = rest.points(n, 2, seed=3, case_id=4, replica=5)
    last = kernels.uniforms(20, seed=3, case_id=4, replica=5, chunk=1)
    np.testing.assert_array_equal(u[-10:].ravel(), last)


@pytest.mark.parametrize("integrand, technique", CASES[:4])
def test_one_chunk_per_state_merges_to_bitwise_the_whole_estimate(integrand, technique):
    n = 3 * rest.CHUNK_SIZE + 12345
    keys = dict(seed=11, case_id=6, replica=2)
    whole = rest.integrate(integrand, technique, n, threads=2, **keys)
    states = [rest.integrate_chunks(integrand, technique, n, c, c + 1, threads=1, **keys) for c in range(4)]
    merged = rest.estimate_from_states(integrand, technique, states)
    for field in FIELDS + ("integrand", "technique", "reference", "iid"):
        a, b = getattr(whole, field), getattr(merged, field)
        assert a == b or (a != a and b != b), f"{field}: integrate {a!r} != merged states {b!r}"
    assert merged.chunks == 4


def test_chunk_ranges_give_the_same_bits_wherever_they_are_computed():
    n = 5 * rest.CHUNK_SIZE + 7
    one = [rest.integrate_chunks("peak", "importance:trimmed_logistic", n, a, b, seed=1, threads=t)
           for (a, b), t in [((0, 2), 1), ((2, 6), 2)]]
    two = [rest.integrate_chunks("peak", "importance:trimmed_logistic", n, a, b, seed=1, threads=1)
           for a, b in [(0, 2), (2, 6)]]
    a, b = (rest.estimate_from_states("peak", "importance:trimmed_logistic", s) for s in (one, two))
    assert (a.mean, a.variance, a.kurtosis, a.n) == (b.mean, b.variance, b.kurtosis, b.n)


@pytest.mark.parametrize("begin, end", [(0, 0), (2, 1), (0, 3), (-1, 1), (0.5, 1)])
def test_chunk_ranges_outside_the_estimate_are_rejected(begin, end):
    with pytest.raises(ValueError, match="chunk"):
        rest.integrate_chunks("gaussian", "uniform", rest.CHUNK_SIZE + 1, begin, end)


def test_malformed_states_are_rejected():
    with pytest.raises(ValueError, match="at least one"):
        rest.estimate_from_states("gaussian", "uniform", [])
    with pytest.raises(TypeError, match=r"'states'\[0\] must be a dict"):
        rest.estimate_from_states("gaussian", "uniform", [1.0])
    state = rest.integrate_chunks("gaussian", "uniform", 1000, 0, 1)
    del state["m2"]
    with pytest.raises(ValueError, match="missing m2"):
        rest.estimate_from_states("gaussian", "uniform", [state])


def test_hardware_threads_is_what_threads_none_uses():
    assert rest.hardware_threads() >= 1
    assert rest.integrate("gaussian", "uniform", 4 * rest.CHUNK_SIZE).threads == rest.hardware_threads()
