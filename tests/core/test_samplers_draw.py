"""draw(): its points follow the exact CDFs and marginals (Kolmogorov-Smirnov), whatever the thread count."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import special, stats

import reference_estimators as rest

from tests.core.sampler_cases import CASES, DIRECTIONS, ONE_D, THREAD_N, Case, cases, table_cdf


def azimuth_fraction(w: np.ndarray) -> np.ndarray:
    return np.mod(np.arctan2(w[:, 1], w[:, 0]) / (2 * math.pi), 1.0)


# --- exact CDFs, from the formulas ----------------------------------------------------------
def cdf_1d(case: Case):
    p = case.p
    if case.name == "exponential":
        return lambda x: -np.expm1(-p["rate"] * np.maximum(x, 0.0))
    if case.name == "linear":
        a, b = p["a"], p["b"]
        return lambda x: (lambda t: t * (a * (2 - t) + b * t) / (a + b))(np.clip(x, 0.0, 1.0))
    if case.name == "power":
        return lambda x: np.clip(x, 0.0, 1.0) ** (p["k"] + 1)
    if case.name == "lomax":
        return lambda x: -np.expm1(-p["shape"] * np.log1p(np.maximum(x, 0.0)))
    if case.name == "trimmed_logistic":
        mu, s, a, b = p["mu"], p["s"], p["a"], p["b"]
        la, lb = special.expit((a - mu) / s), special.expit((b - mu) / s)
        return lambda x: (special.expit((np.clip(x, a, b) - mu) / s) - la) / (lb - la)
    if case.name == "piecewise_constant_1d":
        a, b = p["a"], p["b"]
        edges = np.linspace(a, b, len(case.table) + 1)
        cdf = table_cdf(case.table)
        return lambda x: np.interp(x, edges, cdf)
    raise AssertionError(f"no CDF for {case}")


# --- distribution of draw(): Kolmogorov-Smirnov --------------------------------------------
KS_N = 100_000
KS_SEED = 1
KS_ALPHA = 1e-3


@cases(ONE_D)
def test_draw_follows_the_exact_cdf_ks(case):
    """KS test of draw(100_000, seed=1) against the exact CDF (written here from the
    formula).  Family-wise alpha = 1e-3 over the 1-D samplers, Bonferroni: each test at
    1e-3 / len(ONE_D)."""
    s = case.make()
    x, p, diag = s.draw(KS_N, seed=KS_SEED)
    assert x.shape == (KS_N,) and diag["drawn"] == KS_N and diag["candidates"] == KS_N
    res = stats.kstest(x, cdf_1d(case))
    alpha = KS_ALPHA / len(ONE_D)
    assert res.pvalue > alpha, f"{case}: KS D = {res.statistic:.5g}, p = {res.pvalue:.3g} < {alpha:.3g}"


def direction_marginals():
    out = []
    for c in DIRECTIONS:
        out += [(c, "z"), (c, "azimuth")]
    out += [(c, axis) for c in CASES if c.domain == "square" for axis in ("x", "y")]
    return out


MARGINALS = direction_marginals()


def marginal_cdf(case: Case, which: str):
    p = case.p
    if which == "azimuth":
        return lambda t: np.clip(t, 0, 1)
    if case.domain == "square":
        t = np.asarray(case.table, dtype=float)
        rows, cols = t.shape
        if which == "y":
            edges, cdf = np.linspace(0, 1, rows + 1), table_cdf(t.sum(axis=1))
            return lambda y: np.interp(y, edges, cdf)
        edges, cdf = np.linspace(0, 1, cols + 1), table_cdf(t.sum(axis=0))
        return lambda x: np.interp(x, edges, cdf)
    if case.name == "uniform_hemisphere":
        return lambda z: np.clip(z, 0, 1)
    if case.name == "uniform_sphere":
        return lambda z: np.clip((z + 1) / 2, 0, 1)
    if case.name == "cosine_hemisphere":
        return lambda z: np.clip(z, 0, 1) ** 2
    if case.name == "uniform_cone":
        c = p["cos_max"]
        return lambda z: np.clip((z - c) / (1 - c), 0, 1)
    if case.name == "ggx":
        # P(Z <= z) = P(tan^2 theta >= t2(z)) = alpha^2 / (alpha^2 + tan^2 theta(z))
        a2 = p["alpha"] ** 2

        def f(z):
            z = np.clip(z, 0, 1)
            t2 = (1 - z * z) / np.maximum(z * z, 1e-300)
            return a2 / (a2 + t2)
        return f
    raise AssertionError(f"no marginal for {case}")


@pytest.mark.parametrize("case,which", MARGINALS, ids=[f"{c}-{w}" for c, w in MARGINALS])
def test_draw_marginals_follow_the_exact_cdf_ks(case, which):
    """KS test of one marginal of draw(100_000, seed=1) (cos theta and the azimuth fraction
    for directions; x and y for the 2-D table) against its exact CDF.  Family-wise alpha =
    1e-3 over these marginals, Bonferroni."""
    s = case.make()
    w, _, _ = s.draw(KS_N, seed=KS_SEED)
    data = {"z": lambda: w[:, 2], "azimuth": lambda: azimuth_fraction(w),
            "x": lambda: w[:, 0], "y": lambda: w[:, 1]}[which]()
    res = stats.kstest(data, marginal_cdf(case, which))
    alpha = KS_ALPHA / len(MARGINALS)
    assert res.pvalue > alpha, (f"{case} {which}: KS D = {res.statistic:.5g}, "
                                f"p = {res.pvalue:.3g} < {alpha:.3g}")


# --- draw() is independent of the thread count ---------------------------------------------

@cases()
def test_draw_is_identical_for_any_thread_count(case):
    s = case.make()
    x1, p1, d1 = s.draw(THREAD_N, seed=7, threads=1)
    for t in (2, 3):
        xt, pt, dt = s.draw(THREAD_N, seed=7, threads=t)
        assert np.array_equal(x1, xt), f"{case}: points differ between threads=1 and threads={t}"
        assert np.array_equal(p1, pt), f"{case}: pdfs differ between threads=1 and threads={t}"
        assert dt["candidates"] == d1["candidates"] and dt["drawn"] == d1["drawn"] == THREAD_N


def test_draw_seeds_give_different_streams():
    s = rest.sampler("linear")
    a, _, _ = s.draw(1000, seed=1)
    b, _, _ = s.draw(1000, seed=2)
    assert not np.array_equal(a, b)
