"""harness.stats' convergence rate: fitted log-log slopes at the promised rates, the
permutation test's level on heavy-tailed, skewed and pooled errors, its interval, its edge
cases and its settings."""
from __future__ import annotations

import math

import numpy as np
import pytest

from harness import stats as hs

BUDGETS = [256, 1024, 4096, 16384, 65536]


def test_monte_carlo_converges_at_minus_one_half():
    c = hs.convergence_rate("gaussian", "uniform", BUDGETS, 32, seed=0)
    lo, hi = c.confidence_interval()
    assert lo <= -0.5 <= hi and c.verdict == "as expected" and c.passed, c
    assert list(c.table["n"]) == BUDGETS and (c.table["rmse_lo"] < c.table["rmse"]).all()
    assert (c.table["rmse"] < c.table["rmse_hi"]).all() and c.table["rmse"].is_monotonic_decreasing


@pytest.mark.parametrize("integrand, technique, rate", [
    ("gaussian", "uniform/stratified", -1.5),  # smooth, 1-D: n^-3/2
    ("step", "uniform/stratified", -1.0),      # one stratum holds the jump: n^-1
    ("gaussian2d", "uniform/stratified", -1.0),  # smooth, 2-D jittered: n^-1/2 - 1/d = n^-1
])
def test_stratified_rates(integrand, technique, rate):
    c = hs.convergence_rate(integrand, technique, BUDGETS, 32, seed=0, expected=rate)
    lo, hi = c.confidence_interval()
    assert lo - 0.05 <= rate <= hi + 0.05, c


def test_owen_sobol_beats_monte_carlo_on_smooth_integrands():
    for integrand in ("gaussian", "gaussian2d", "gaussian16"):
        c = hs.convergence_rate(integrand, "uniform/sobol", BUDGETS, 32, seed=0)
        assert c.confidence_interval().high < -0.75, c


def test_a_zero_variance_estimator_at_the_rounding_level_is_not_slower_than_expected():
    """Contributions equal to 0.3 up to a few ulp: the RMSE stays near 1e-17 at every budget,
    slope ~0, which is rounding, not slow convergence."""
    r = hs.convergence_rate(lambda u: u[:, 0] + (0.3 - u[:, 0]), dim=1, reference=0.3,
                            budgets=[64, 256, 1024, 4096], replicas=16)
    assert 0 < r.table["rmse"].max() <= r.rounding_floor and r.at_rounding_level
    assert r.verdict == "as expected" and r.pvalue == 1.0 and "rounding level" in str(r)
    slow = hs.convergence_rate(lambda u: u[:, 0], dim=1, reference=0.5, budgets=[64, 256, 1024], replicas=16)
    assert not slow.at_rounding_level


def test_a_biased_estimator_stops_converging_and_is_reported():
    c = hs.convergence_rate("gaussian", "clamped:uniform(0.9)", BUDGETS, 16, seed=0)
    assert c.verdict == "slower than expected" and not c.passed and abs(c.slope) < 0.1
    assert str(c).startswith("slower than expected") and c.pvalue < c.alpha


def test_convergence_is_reproducible():
    a = hs.convergence_rate("step", "uniform", BUDGETS[:3], 16, seed=4)
    b = hs.convergence_rate("step", "uniform", BUDGETS[:3], 16, seed=4)
    assert a.slope == b.slope and a.confidence_interval() == b.confidence_interval()


def test_convergence_needs_three_budgets():
    with pytest.raises(ValueError, match="'budgets' needs at least 3 distinct sizes"):
        hs.convergence_rate("gaussian", "uniform", [100, 100, 200], 16)


def test_a_convergence_slope_is_judged_by_a_permutation_test_that_holds_its_level():
    # with the normal approximation and a bootstrap over 4 replicas a correct uniform MC failed
    # 34 of 1000 seeds at the stated 0.025; the permutation test holds the level at 4 replicas
    fails = sum(not hs.convergence_rate("gaussian", "uniform", BUDGETS[:3], 4, seed=s).passed
                for s in range(400))
    assert fails <= 10, fails         # expected <= 10 at 0.025 (binomial 0.99 quantile: 10)
    # the interval inverts the test: its low end above the bound exactly where p < alpha
    for seed in range(40):
        c = hs.convergence_rate("gaussian", "uniform", BUDGETS[:3], 16, seed=seed)
        low = c.confidence_interval(0.95).low
        assert (low > -0.45) == (c.pvalue < c.alpha) == (c.verdict == "slower than expected")
    # 2 replicas over 3 budgets could not reject even a flat RMSE (a clamped estimator had passed)
    flat = hs.convergence_rate("gaussian", "clamped:uniform(0.9)", BUDGETS[:3], 2)
    assert flat.verdict == "inconclusive" and "not even a flat RMSE would be rejected" in flat.inconclusive
    assert math.isnan(flat.statistic) and flat.pvalue == 1.0
    slow = hs.convergence_rate("gaussian", "clamped:uniform(0.9)", BUDGETS[:3], 16)
    assert slow.verdict == "slower than expected" and slow.statistic > 3
    reps = [hs.replicate("gaussian", "uniform", n, 4, seed=2, case_id=i) for i, n in enumerate(BUDGETS[:3])]
    single = hs.fit_convergence(reps)
    pooled = hs.fit_convergence(reps, pooled=True)   # an image's relMSE: judged from 4 replicas too
    assert pooled.verdict == single.verdict == "as expected" and pooled.pvalue == single.pvalue
    two = [hs.replicate("gaussian", "uniform", n, 2, seed=2, case_id=i) for i, n in enumerate(BUDGETS[:3])]
    few = hs.fit_convergence(two, pooled=True, confidence_level=0.99)   # 6! / 2!^3 arrangements: p >= 1/90
    assert few.verdict == "inconclusive"
    assert "the test's smallest p-value, 0.0111, is not below alpha = 0.005" in few.inconclusive


def _synthetic(errors_by_budget, budgets=BUDGETS[:3]):
    return [hs.Replicates("synthetic", "t", n, 0.0, np.asarray(e, dtype=float), np.full(len(e), 1e-3),
                          math.nan, math.nan, False, 1) for n, e in zip(budgets, errors_by_budget)]


def test_the_slope_tests_edge_cases_end_and_say_what_they_are():
    """Each had gone wrong in review: errors on an exact power law (every arrangement ties)
    had bisected forever; an RMSE of 0 at one budget had given a slope of +126 with an interval
    ending where exp overflowed; at 99 % the interval had used fewer arrangements than the
    p-value and disagreed with it."""
    import warnings
    exact = hs.fit_convergence(_synthetic([np.full(8, n ** -1.0) for n in BUDGETS[:3]]))
    assert exact.slope == pytest.approx(-1.0) and exact.verdict == "as expected"
    lo, hi = exact.confidence_interval()
    assert lo <= exact.slope <= hi and hi - lo < 1e-6
    rng = np.random.default_rng(0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")         # no overflow on the way
        hole = hs.fit_convergence(_synthetic([np.zeros(8)] + [rng.standard_normal(8) * n ** -0.5
                                                              for n in BUDGETS[1:3]]))
        assert hole.verdict == "inconclusive" and "an RMSE of 0 at some budget" in hole.inconclusive
        assert all(math.isnan(v) for v in hole.confidence_interval())
        steep = hs.fit_convergence(_synthetic([rng.standard_normal(8) * n ** 40.0 for n in BUDGETS[:3]]))
        assert steep.verdict == "slower than expected" and math.isfinite(steep.statistic)
        assert all(math.isfinite(v) for v in steep.confidence_interval())
    for seed in range(30):
        r = np.random.default_rng(seed)
        fit = hs.fit_convergence(_synthetic([r.standard_normal(16) * n ** -0.45 for n in BUDGETS[:4]],
                                            BUDGETS[:4]), confidence_level=0.99, seed=seed)
        assert (fit.confidence_interval(0.99).low > -0.45) == (fit.pvalue < fit.alpha)
    # beyond the draws' resolution: inconclusive, not "as expected"
    far = hs.fit_convergence(_synthetic([r.standard_normal(32) * n ** 0.6 for n in BUDGETS]),
                             confidence_level=0.99999)
    assert far.verdict == "inconclusive" and "the test's smallest p-value, 7.58e-06" in far.inconclusive


def test_the_permutation_test_holds_its_level_for_heavy_tailed_and_skewed_errors():
    """Replicas whose RMSE falls as n^-0.45 exactly (the default bound), errors t(3) (no fourth
    moment: fireflies) and centred log-normal (skewed).  The parametric law, its shape from
    the squares' spread, had rejected log-normal errors at 9.9 % for 5 % (16 replicas, 3
    budgets, 2000 seeds).  300 seeds a kind: rejections at p < 0.05 at most 25 (binomial
    0.999 quantile of 300 x 0.05)."""
    for kind in ("t3", "lognormal"):
        rejected = 0
        for seed in range(300):
            rng = np.random.default_rng(seed)
            errors = [(rng.standard_t(3, 16) if kind == "t3" else rng.lognormal(0, 1, 16) - math.exp(0.5))
                      * n ** -0.45 for n in BUDGETS[:3]]
            rejected += hs.fit_convergence(_synthetic(errors), seed=seed).pvalue < 0.05
        assert rejected <= 25, (kind, rejected)


@pytest.mark.parametrize("kwargs, message", [
    ({"expected": math.nan}, "'expected' must be a finite number, got nan"),     # had passed, p = 0
    ({"tolerance": math.inf}, "'tolerance' must be a finite number"),
    ({"tolerance": -0.1}, "'tolerance' must be >= 0"),
    ({"confidence_level": 1.0}, r"'confidence_level' must be in \(0, 1\), got 1.0"),
])
def test_convergence_settings_are_checked_before_any_work(kwargs, message):
    with pytest.raises(ValueError, match=message):
        hs.convergence_rate("gaussian", "uniform", BUDGETS[:3], 16, **kwargs)


def test_convergence_budgets_may_be_an_array_and_a_fit_needs_three():
    c = hs.convergence_rate("gaussian", "uniform", np.array(BUDGETS[:3]), 16)    # had been ambiguous
    assert list(c.table["n"]) == BUDGETS[:3]
    with pytest.raises(ValueError, match="'budgets' must be a sequence of sample counts, got 256"):
        hs.convergence_rate("gaussian", "uniform", 256, 16)
    one = [hs.replicate("gaussian", "uniform", 1024, 16, seed=1, case_id=i) for i in range(3)]
    with pytest.raises(ValueError, match="'budgets' needs at least 3 distinct sizes"):   # had passed
        hs.fit_convergence(one)
