"""Transform statistics, the bracketed Cramer-von Mises sum and the pdf summary against numpy."""
from __future__ import annotations

import concurrent.futures
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import reference_estimators as rest

from tests.core.check_kernel_helpers import CHUNKS, N, random_table


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
