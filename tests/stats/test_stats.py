"""harness.stats: the unbiasedness test (false alarms and power measured on the calibration
zoo), Holm, efficiency and error against time.  Convergence rates are tested in
test_convergence.py, the result family's common surface in test_results.py."""
from __future__ import annotations

import math
import sys

import numpy as np
import pytest
from scipy import stats

import reference_estimators as rest

from harness import stats as hs
from harness.stats import zoo as calibration

GAUSS = rest.integrand("gaussian").reference


# --- false alarms and power, over many seeds ---------------------------------------------------
@pytest.fixture(scope="module")
def zoo_table():
    """check_unbiased on every zoo estimator for seeds 0..199, n = 1e5, alpha = 0.01."""
    return calibration.measure(calibration.zoo(), seeds=range(200), sample_count=100_000, alpha=0.01)


@pytest.mark.slow
def test_false_alarm_rate_holds_on_correct_estimators(zoo_table):
    """Correct estimators, light- and heavy-tailed (tail index 2, 3/2, ~1): "biased" at most
    as often as alpha allows.  Per estimator the count must stay below the Binomial(200, 0.01)
    quantile at 1e-3 / (number of estimators); pooled, below the Binomial(runs, 0.01) quantile
    at 1e-3.  Heavy-tailed ones may say "inconclusive" instead."""
    correct = zoo_table[zoo_table["fault"] == "-"]
    per = stats.binom.isf(1e-3 / len(correct), 200, 0.01)
    bad = correct[correct["biased"] > per]
    assert bad.empty, f"false alarms above {per:.0f} of 200:\n{bad.to_string()}"
    pooled = stats.binom.isf(1e-3, int(correct["runs"].sum()), 0.01)
    assert correct["biased"].sum() <= pooled, correct.to_string()
    light = correct[~correct["heavy"]]
    assert (light["inconclusive"] <= 10).all(), light.to_string()  # the flags rarely fire on light tails
    assert (correct["invalid"] == 0).all()


@pytest.mark.slow
def test_power_on_wrong_estimators(zoo_table):
    """Faults of 1 % or more in light-tailed estimators, and a firefly clamp that lowers a
    Pareto(2.5) mean by 1 % (3.5 standard errors), are caught at least 95 % of the time at
    n = 1e5 (measured: 200 of 200, the clamp 199)."""
    wrong = zoo_table[zoo_table["fault"] != "-"].set_index("estimator")
    clear = ["importance:linear, pdf 1% too large", "importance:linear, pdf 0.1% too large",
             "roulette(q=0.99) without 1/q", "stratified(64), a stratum twice",
             "mis_balance, weights sum to 1.02", "hit_or_miss(c=0.95), bound violated", "snis(b=16)",
             "pareto(2.5) clamped, bias -1 %"]
    for name in clear:
        assert wrong.loc[name, "rate"] >= 0.95, wrong.loc[name]


@pytest.mark.slow
def test_power_matches_the_documented_detection_size():
    """The docstring's claim: a bias of 3.5 sigma / sqrt(n) is caught ~80 % of the time.
    roulette(q=0.999) without 1/q has bias 0.00075 (3.7 sigma / sqrt(1e6)); clamping at 0.99
    has bias 0.00067 (3.4 sigma / sqrt(1e6)).  Over 100 seeds both must be caught at least
    60 % of the time (the 80 % expectation minus 4 binomial standard deviations)."""
    names = ("roulette(q=0.999) without 1/q", "uniform clamped at 0.99")
    sub = [e for e in calibration.zoo() if e.name in names]
    table = calibration.measure(sub, seeds=range(100), sample_count=1_000_000)
    assert (table["rate"] >= 0.6).all(), table.to_string()


@pytest.mark.slow
def test_clamps_and_truncations_of_heavy_tails_are_caught_at_least_as_often_as_by_a_t_test():
    """n = 1e6, seeds 0..39, beside scipy.stats.ttest_1samp on the same contributions: Pareto(1.5)
    truncated or clamped at 1e3 (bias -3.1 % and -2.0 %, where the unclamped tail is
    "inconclusive") is caught every time; a firefly clamp of Pareto(2.5) that lowers the mean
    by 0.25 % (2.8 standard errors) at least as often as by the t-test, less 4 runs (the
    paired difference's noise).  benchmarks/unbiased_calibration.py gives the 200-seed table."""
    names = ("pareto(1.5) truncated at 1e3", "pareto(1.5) clamped at 1e3",
             "pareto(2.5) clamped, bias -0.25 %")
    sub = [e for e in calibration.zoo() if e.name in names]
    table = calibration.measure(sub, seeds=range(40), sample_count=1_000_000, ttest=True)
    table = table.set_index("estimator")
    assert (table.loc[list(names[:2]), "biased"] == 40).all(), table.to_string()
    firefly = table.loc[names[2]]
    assert firefly["biased"] >= firefly["ttest"] - 4 and firefly["biased"] >= 20, table.to_string()


# --- check_unbiased's contract -----------------------------------------------------------------
def test_result_carries_estimate_interval_and_n():
    r = hs.check_unbiased(lambda u: np.exp(-u[:, 0] ** 2), 1, GAUSS, sample_count=200_000, seed=3)
    assert r.verdict == "consistent" and r.passed and r.n == 200_000
    t, p = r
    assert (t, p) == (r.statistic, r.pvalue) and r.df == 200_000 - 1     # i.i.d.: all contributions
    lo, hi = r.confidence_interval(0.99)
    assert lo < r.estimate < hi and hi - lo == pytest.approx(2 * stats.t.ppf(0.995, r.df) * r.stderr)
    # the standard error of all contributions, as scipy's one-sample t-test has it
    y = np.concatenate([np.exp(-u[:, 0] ** 2) for *_, u in hs.batch_points(200_000, 1, seed=3, batches=64)])
    ref = stats.ttest_1samp(y, GAUSS)
    assert r.stderr == pytest.approx(stats.sem(y), rel=1e-9) and t == pytest.approx(ref.statistic, rel=1e-9)
    assert r.stderr == pytest.approx(math.sqrt(r.variance / r.n), rel=0.3)
    assert "consistent" in str(r) and "n = 200000" in str(r)


def test_same_seed_same_verdict_other_seed_other_numbers():
    f = lambda u: u[:, 0] * 2  # noqa: E731
    a = hs.check_unbiased(f, 1, 1.0, sample_count=10_000, seed=1)
    b = hs.check_unbiased(f, 1, 1.0, sample_count=10_000, seed=1)
    c = hs.check_unbiased(f, 1, 1.0, sample_count=10_000, seed=2)
    assert a == b and a.estimate != c.estimate


def test_zero_variance_estimators_are_judged_exactly_and_an_unseen_spread_is_no_evidence():
    """Equal contributions equal to the reference: exact.  Equal but not the reference: a wrong
    constant, or a rare value never drawn; no level can be claimed either way, so the verdict is
    "inconclusive" with the rule of three's bound (at alpha) on what was not seen."""
    ok = hs.check_unbiased(lambda u: np.full(u.shape[0], 0.25), 2, 0.25, sample_count=4096)
    off = hs.check_unbiased(lambda u: np.full(u.shape[0], 0.25 + 1e-12), 2, 0.25, sample_count=4096)
    assert ok.verdict == "consistent" and ok.pvalue == 1.0
    assert off.verdict == "inconclusive" and off.undecided and off.passed and math.isnan(off.statistic)
    assert "all 4096 contributions equal 0.25" in off.flags[-1]
    assert f"probability < {-math.log(0.01) / 4096:.2g} (rule of three at alpha = 0.01)" in off.flags[-1]


def test_a_rare_event_estimator_never_crashes_and_holds_alpha():
    """Y = 1{u < 3e-5} / 3e-5 at n = 1e5: no hit 5 % of the time, exactly 3 hits (t = 0) 22 %:
    over 200 seeds no crash, and "biased" no more often than alpha allows (Binomial(200, 0.01)
    exceeds 5 with probability 0.0005); the zero-hit seeds are "inconclusive"."""
    verdicts = [hs.check_unbiased(lambda u: (u[:, 0] < 3e-5) / 3e-5, 1, 1.0, sample_count=10**5, seed=s)
                for s in range(200)]
    assert sum(r.verdict == "biased" for r in verdicts) <= 5
    zero = [r for r in verdicts if r.estimate == 0]
    assert zero and all(r.undecided for r in zero)
    # 3 hits: t = 0, no division; p < 1 only by the skewness correction
    assert any(r.statistic == 0 and 0.5 < r.pvalue <= 1.0 for r in verdicts)


def test_contributions_beyond_two_to_the_1023_are_scaled_not_overflowed():
    big = 2.0**1023
    r = hs.check_unbiased(lambda u: big * (1 + u[:, 0]), 1, 1.5 * big, sample_count=65536)
    assert r.verdict == "consistent" and math.isfinite(r.estimate) and math.isfinite(r.stderr)
    assert r.variance == math.inf   # (2^1023)^2 / 12 is beyond double range: inf, said as such


def test_nan_contributions_make_the_test_invalid_with_examples():
    def y(u):
        v = u[:, 0].copy()
        v[u[:, 0] < 0.001] = np.nan
        return v
    r = hs.check_unbiased(y, 1, 0.5, sample_count=100_000)
    assert r.verdict == "invalid" and not r.passed and math.isnan(r.pvalue)
    (nan,) = r.failures
    assert nan.check == "nan" and 50 < nan.count < 200 and nan.examples[0]["issue"] == "nan"
    assert all(0 <= e["index"] < 100_000 and math.isnan(e["value"]) for e in nan.examples)
    assert "invalid" in str(r) and f"nan: {nan.count}" in str(r)


def test_heavy_tails_are_flagged_not_judged():
    r = hs.check_unbiased(lambda u: u[:, 0] ** (-2 / 3) / 3, 1, 1.0, sample_count=100_000, seed=0)
    assert r.no_level and r.tail_index < 3 and r.verdict != "biased" and r.passed


def test_a_firefly_clamp_of_a_heavy_tail_is_found_and_named():
    """Pareto(1.5) contributions of mean 1 (infinite variance: "inconclusive" unclamped) clamped
    at 164.6, which lowers the mean by 3 %: the atom at the clamp (about 90 contributions) ends
    the tail, the variance is finite, and the bias (8 standard errors at n = 1e6) is "biased,
    clamped at 164.6"."""
    def pareto(u):
        return u[:, 0] ** (-2 / 3) / 3
    free = hs.check_unbiased(pareto, 1, 1.0, sample_count=10**6)
    r = hs.check_unbiased(lambda u: np.minimum(pareto(u), 164.6), 1, 1.0, sample_count=10**6)
    assert free.no_level and free.tail_index < 2
    assert r.verdict == "biased" and not r.no_level
    assert r.tail_end.startswith("clamped at 164.6 (") and "biased, clamped at 164.6 (" in str(r)


@pytest.mark.slow
def test_a_truncated_heavy_tail_is_found_and_named():
    """Pareto(1.5) paths beyond 1e3 dropped (bias -3.1 %, 10 standard errors at n = 1e6): the
    top spacings are compressed against the bound, so the tail ends and the deficit is proved."""
    r = hs.check_unbiased(lambda u: np.where(u[:, 0] ** (-2 / 3) <= 1e3, u[:, 0] ** (-2 / 3), 0.0), 1, 3.0,
                          sample_count=10**6, seed=3)
    assert r.verdict == "biased" and r.tail_end.startswith("tail truncated near 9")


def test_an_estimate_dominated_by_a_few_contributions_claims_no_level():
    """About 5 exponential hits of weight 2e5 in 1e6 samples: the estimate's skewness (~0.9) is
    beyond 0.5, so even a 3x bias is "inconclusive", with the reason."""
    def y(u):
        return np.where(u[:, 0] < 5e-6, -np.log(u[:, 1]) / 5e-6, 0.0)
    r = hs.check_unbiased(y, 2, 1 / 3, sample_count=10**6, seed=1)
    assert r.skewness > 0.5 and r.no_level and r.verdict in ("inconclusive", "consistent")
    assert any(f.startswith("estimate skewed (+") for f in r.flags)


def test_the_skewness_correction_is_monotone_and_finite_for_any_t():
    """Hall's transformation keeps the order of t (so the test is one rejection region) and
    gives a p-value in [0, 1] for |t| up to 1e300; the split puts 4/5 of alpha on one side."""
    from harness.stats.bias import _skew_corrected_p
    ts = np.concatenate([-np.logspace(300, -3, 200), np.logspace(-3, 300, 200)])
    for g in (-0.5, -0.1, 0.0, 0.2, 0.5):
        ps = [_skew_corrected_p(t, g, 63, 0.5) for t in ts]
        assert all(0.0 <= p <= 1.0 for p in ps)
        lower = [p for t, p in zip(ts, ps) if t < -1]      # the lower side's p rises with t
        assert np.all(np.diff(lower) >= 0)
    assert _skew_corrected_p(-2.5, 0.0, 63, 0.8) == pytest.approx(stats.t.cdf(-2.5, 63) / 0.8)
    assert _skew_corrected_p(2.5, 0.0, 63, 0.8) == pytest.approx(stats.t.sf(2.5, 63) / 0.2)
    assert _skew_corrected_p(-2.5, 0.0, 63, 0.5) == pytest.approx(2 * stats.t.cdf(-2.5, 63))


def test_a_result_rejudged_with_another_pvalue_keeps_its_reasons():
    r = hs.check_unbiased(lambda u: u[:, 0] ** (-2 / 3) / 3, 1, 1.0, sample_count=100_000, seed=0)
    assert r.with_pvalue(1e-9).verdict == "inconclusive"   # heavy tail: no level
    ok = hs.check_unbiased(lambda u: u[:, 0], 1, 0.5, sample_count=100_000)
    assert ok.with_pvalue(1e-9).verdict == "biased" and ok.with_pvalue(0.5).verdict == "consistent"


@pytest.mark.parametrize("kwargs, message", [
    ({"sample_count": 0}, r"'sample_count' must be a positive whole number, got 0"),
    ({"sample_count": 1000, "alpha": 1.5}, r"'alpha' must be in \(0, 1\), got 1.5"),
    ({"sample_count": 1000, "batches": 4}, r"'batches' must be an integer in \[8, 1000\], got 4"),
    ({"sample_count": 1e4, "batches": 8.0}, r"'batches' must be an integer in \[8, 10000\], got 8.0"),
    ({"sample_count": 2.5}, r"'sample_count' must be a positive whole number, got 2.5"),
])
def test_bad_arguments_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        hs.check_unbiased(lambda u: u[:, 0], 1, 0.5, **kwargs)


def test_wrong_output_shape_is_named():
    with pytest.raises(ValueError, match=r"<lambda> returned shape \(1000, 2\) for uniforms of shape "
                                         r"\(1000, 2\), float64; expected shape \(1000,\)"):
        hs.check_unbiased(lambda u: u, 2, 0.5, sample_count=64_000)
    # as every entry point that calls a team's code: its exceptions, exits and complex values named
    for bad, message in ((lambda u: 1 / 0, r"<lambda> raised ZeroDivisionError: division by zero \(called on "
                                           r"shape \(1000, 1\), float64; expected to return contributions"),
                         (lambda u: sys.exit(3), r"<lambda> called sys.exit\(3\)"),
                         (lambda u: u[:, 0] + 1j, r"<lambda> returned a ndarray of complex128 values"),
                         (lambda u: np.full(len(u), "0.5"), r"<lambda> returned a ndarray of <U3 values")):
        with pytest.raises(ValueError, match=message):
            hs.check_unbiased(bad, 1, 0.5, sample_count=64_000)
    with pytest.raises(ValueError, match=r"'reference' must be a finite number, got '0.7'"):
        hs.check_unbiased(lambda u: u[:, 0], 1, "0.7", sample_count=64_000)
    with pytest.raises(ValueError, match=r"'dim' must be an integer >= 1, got 0"):
        hs.check_unbiased(lambda u: u[:, 0], 0, 0.5, sample_count=1000)


def test_check_technique_handles_point_sets_and_planted_bias():
    ok = hs.check_technique("gaussian", "uniform/sobol", 262_144, seed=1)
    assert ok.verdict == "consistent" and ok.stderr < 1e-5
    bad = hs.check_technique("gaussian", "snis:linear(b=4)", 262_144, seed=1)
    assert bad.verdict == "biased" and bad.estimate > GAUSS


# --- Holm ----------------------------------------------------------------------------------------
def test_holm_on_a_worked_example():
    reject, adjusted = hs.holm([0.01, 0.04, 0.03, 0.005], alpha=0.05)
    assert reject.tolist() == [True, False, False, True]
    np.testing.assert_allclose(adjusted, [0.03, 0.06, 0.06, 0.02])


def test_holm_holds_the_family_wise_rate():
    """10 true null hypotheses with uniform p-values, 4000 families: the rate of any false
    rejection must be <= alpha = 0.05 (upper 1e-3 binomial bound)."""
    rng = np.random.default_rng(0)
    hits = sum(hs.holm(rng.random(10), 0.05)[0].any() for _ in range(4000))
    assert hits <= stats.binom.isf(1e-3, 4000, 0.05), hits


def test_holm_rejects_bad_input():
    with pytest.raises(ValueError, match="'pvalues' must be a 1-D sequence of values in \\[0, 1\\]"):
        hs.holm([0.1, 1.5], 0.05)


# --- efficiency and error against time ---------------------------------------------------
def test_efficiency_ratio_of_importance_sampling_over_uniform():
    """linear IS cuts the variance ~40x at ~5x the time per sample: its efficiency ratio
    against uniform MC is well above 1, with an interval that says so."""
    a = hs.efficiency(hs.replicate("gaussian", "importance:linear", 200_000, 16, seed=0))
    b = hs.efficiency(hs.replicate("gaussian", "uniform", 200_000, 16, seed=0))
    ratio, (lo, hi) = hs.efficiency_ratio(a, b)
    assert 1 < lo < ratio < hi
    v_ratio = 10 ** (b.log10_variance - a.log10_variance)
    assert 20 < v_ratio < 80, v_ratio  # sigma^2 0.040 vs 0.0009: measured from samples
    lo_e, hi_e = a.confidence_interval()
    assert lo_e < a.value < hi_e and a.budget == 200_000 and a.replicas == 16 and a.n == 16 * 200_000
    assert a.verdict == "measured" and a.passed


def test_an_infinite_variance_has_efficiency_zero_and_no_interval():
    """singularity/uniform: V infinite (analytic), whatever a finite sample's spread says; a
    tail index below 2 says the same, one in [2, 3) gives a value without an interval."""
    r = hs.replicate("singularity", "uniform", 100_000, 8, seed=0)
    e = hs.efficiency(r)
    assert e.verdict == "infinite variance" and e.value == 0 and e.log10_value == -math.inf
    assert all(math.isnan(x) for x in e.confidence_interval()) and "no interval" in str(e)
    g = hs.replicate("gaussian", "uniform", 100_000, 8, seed=0)
    base = hs.efficiency(g)
    ratio, interval = hs.efficiency_ratio(e, base)
    assert ratio == 0.0 and all(math.isnan(x) for x in interval)
    assert math.isnan(hs.efficiency_ratio(base, e)[0])   # against an efficiency of 0: no ratio
    assert hs.efficiency(g, tail_index=1.5).verdict == "infinite variance"
    shaky = hs.efficiency(g, tail_index=2.5)
    assert shaky.verdict == "unreliable" and math.isfinite(shaky.log10_value)
    assert all(math.isnan(x) for x in shaky.confidence_interval())
    assert hs.efficiency(g, tail_index=3.5).verdict == "measured"


def test_the_time_error_comes_from_the_spread_between_blocks_of_replicas():
    """32 replicas whose times drift from 1.0 to 1.31 s (the machine slowing down), each block
    of 4 alike: the spread within blocks is nearly nothing, the block medians spread: the
    standard error is theirs, SD(block medians) / sqrt(8)."""
    t = np.repeat(1.0 + 0.04 * np.arange(8), 4) + np.tile([0, 1e-4, 2e-4, 3e-4], 8)
    med, se = hs.median_time(t)
    blocks = np.median(t.reshape(8, 4), axis=1)
    assert med == np.median(t) and se == pytest.approx(np.std(blocks, ddof=1) / math.sqrt(8))
    assert se > 1.2533 * 1.4826 * np.median(np.abs(t - med)) / math.sqrt(32)   # the within-replica rule


def test_the_time_in_clock_ticks_is_the_median_time_over_the_median_reading():
    """A machine that slows down for a block slows the clock read beside it alike: the time in
    ticks and its error (from the blocks' median time over median reading) do not move.  A
    replica and another replica's reading that each lost a time slice in one block are one
    outlier of each series: the block's ratio stays put."""
    clock = np.repeat(1.0 + 0.04 * np.arange(8), 4)       # the machine's speed, block by block
    t = 3.0 * clock * (1 + np.tile([0, 1e-4, 2e-4, 3e-4], 8))
    ticks, se = hs.clock_time(t, clock)
    assert ticks == np.median(t) / np.median(clock) and ticks == pytest.approx(3.0, rel=1e-3)
    assert se < 1e-3 * hs.median_time(t)[1]
    t2, c2 = t.copy(), clock.copy()
    t2[4], c2[5] = 5 * t2[4], 5 * c2[5]
    ticks2, se2 = hs.clock_time(t2, c2)
    assert ticks2 == pytest.approx(ticks, rel=1e-3) and se2 < 1e-4
    with pytest.raises(ValueError, match=r"'clock' must have one time per replica: \(31,\) against \(32,\)"):
        hs.clock_time(t, clock[1:])
    with pytest.raises(ValueError, match="'clock' times must be positive, got min 0"):
        hs.clock_time(t, np.where(np.arange(32) == 5, 0.0, clock))


def test_the_reference_clock_reads_a_positive_finite_time():
    ticks = [hs.reference_clock() for _ in range(3)]
    assert all(math.isfinite(c) and c > 0 for c in ticks), ticks
    assert hs.CLOCK["samples"] > 0


def test_efficiency_in_clock_ticks_is_the_one_in_seconds_times_the_runs_clock():
    """replicate(..., clock=True) reads the clock beside each replica; the efficiency in clock
    ticks has its own interval, and equals the one in 1/s times the run's clock (its median
    reading, s), to rounding.  Each says what its interval claims."""
    r = hs.replicate("gaussian", "importance:linear", 65536, 8, seed=0, clock=True)
    assert r.clock.shape == (8,) and np.all(np.isfinite(r.clock)) and np.all(r.clock > 0)
    e, k = hs.efficiency(r), hs.efficiency(r, clock=True)
    assert (e.time_unit, k.time_unit) == ("s", "clock") and k.verdict == "measured"
    assert k.seconds == r.clock_time[0] and math.isfinite(k.log_se) and k.log_se > 0
    run_clock = float(np.median(r.clock))                 # the run's clock: its median reading
    assert k.log10_value == pytest.approx(e.log10_value + math.log10(run_clock), abs=1e-12)
    lo, hi = k.confidence_interval()
    assert 0 < lo < k.value < hi < math.inf
    assert "this run's machine state" in str(e) and "across runs" in str(k) and "clock ticks" in str(k)
    inf = hs.efficiency(hs.replicate("singularity", "uniform", 65536, 8, seed=0, clock=True), clock=True)
    assert inf.verdict == "infinite variance" and inf.time_unit == "clock"
    with pytest.raises(ValueError, match="efficiencies in different time units: importance:linear in 'clock"):
        hs.efficiency_ratio(k, e)
    ratio, (lo, hi) = hs.efficiency_ratio(k, k)
    assert ratio == 1.0 and lo < 1 < hi
    with pytest.raises(ValueError, match="clock=True needs the reference clock's time beside each replica"):
        hs.efficiency(hs.replicate("gaussian", "uniform", 65536, 8, seed=0), clock=True)


def test_efficiency_survives_huge_integrands():
    e = hs.efficiency(hs.replicate("huge", "uniform", 50_000, 8, seed=0))
    assert e.value == 0.0 and -600 < e.log10_value < -580  # 1/(V T) ~ 1e-590 is no double
    assert e.verdict == "measured"


def test_replicates_measure_bias_and_rmse():
    r = hs.replicate("gaussian", "roulette_biased:uniform(q=0.9)", 100_000, 16, seed=0)
    bias, se = r.bias
    assert bias == pytest.approx(-0.1 * GAUSS, abs=5 * se)
    assert r.rmse == pytest.approx(abs(bias), rel=0.05)
    lo, hi = r.rmse_interval()
    assert lo < r.rmse < hi


def test_error_against_time_table():
    techniques = ["uniform", "uniform/stratified", "importance:linear"]
    df = hs.error_vs_time("gaussian", techniques, [1024, 16384], 8, seed=0)
    assert list(df.columns) == ["technique", "n", "rmse", "rmse_lo", "rmse_hi", "seconds", "seconds_se",
                                "replicas"]
    assert len(df) == 6 and (df["replicas"] == 8).all() and (df["seconds"] > 0).all()
    for t, g in df.groupby("technique"):
        assert g["rmse"].iloc[1] < g["rmse"].iloc[0], t
    strat = df[df["technique"] == "uniform/stratified"]["rmse"].iloc[-1]
    assert strat < df[df["technique"] == "uniform"]["rmse"].iloc[-1] / 50
