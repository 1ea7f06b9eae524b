"""Accumulators: moments without E[Y^2]-E[Y]^2, extreme magnitudes, and nothing averaged
silently (NaN, Inf, negatives counted and shown)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

import reference_estimators as rest


def test_moments_match_numpy_and_scipy():
    rng = np.random.default_rng(0)
    y = rng.gamma(2.0, 3.0, size=300_001)
    est = rest.accumulate(y)
    assert est.n == y.size == est.drawn
    assert est.mean == pytest.approx(np.mean(y), rel=1e-14)
    assert est.variance == pytest.approx(np.var(y, ddof=1), rel=1e-12)
    assert est.stderr == pytest.approx(np.std(y, ddof=1) / math.sqrt(y.size), rel=1e-12)
    assert est.skewness == pytest.approx(stats.skew(y), rel=1e-10)
    assert est.kurtosis == pytest.approx(stats.kurtosis(y, fisher=False), rel=1e-10)
    assert (est.min, est.max) == (y.min(), y.max())
    assert est.ok


def test_offset_integrand_variance_is_right_to_1e6_relative():
    """offset = 1e8 + sin(2 pi x): the variance of the very same contributions, computed
    exactly from Y - 1e8 (exact by Sterbenz's lemma), must match to 1e-6 relative; the
    naive E[Y^2] - E[Y]^2 on the same numbers is shown to be useless."""
    n = 1_000_000
    y = rest.contributions("offset", "uniform", n, seed=0)
    est = rest.integrate("offset", "uniform", n, seed=0)
    d = y - 1e8
    exact = np.var(d, ddof=1)
    assert abs(est.variance / exact - 1) < 1e-6, (est.variance, exact)
    assert abs(est.mean - (1e8 + np.mean(d))) <= 2 * np.spacing(1e8)
    naive = (np.mean(y * y) - np.mean(y) ** 2) * n / (n - 1)
    assert abs(naive / exact - 1) > 1e-3, "the naive formula should have failed here"
    # and the variance estimate agrees with the exact variance 1/2 within its own error
    assert abs(est.variance - 0.5) < 5 * est.variance_rel_error * 0.5


@pytest.mark.parametrize("scale", [1e300, 1e-300])
def test_extreme_magnitudes_keep_finite_errors(scale):
    rng = np.random.default_rng(1)
    base = rng.random(100_000) + 0.5
    est = rest.accumulate(base * scale)
    ref = rest.accumulate(base)
    assert est.mean == pytest.approx(ref.mean * scale, rel=1e-13)
    assert est.stderr == pytest.approx(ref.stderr * scale, rel=1e-9)
    assert est.log10_variance == pytest.approx(ref.log10_variance + 2 * math.log10(scale), rel=1e-12)
    assert math.isfinite(est.stderr) and est.stderr > 0


def test_subnormal_contributions_keep_their_variance():
    """Values near 2^-1060 are subnormal (about 14 significant bits): the moments must be
    those of the numbers as stored, which scaling by 2^1060 (exact, in two steps: 2^1060
    itself overflows) makes normal."""
    rng = np.random.default_rng(1)
    y = (rng.random(100_000) + 0.5) * 2.0**-1060
    est = rest.accumulate(y)
    up = y * 2.0**530 * 2.0**530
    assert est.mean == pytest.approx(np.mean(up) * 2.0**-530 * 2.0**-530, rel=1e-9)
    assert est.log10_variance == pytest.approx(math.log10(np.var(up, ddof=1)) - 2 * 1060 * math.log10(2),
                                               rel=1e-12)
    assert est.stderr > 0


def test_huge_and_tiny_catalogue_cases_match_the_unscaled_one():
    g = rest.integrate("gaussian", "uniform", 500_000, seed=3)
    for name, s in [("huge", 1e300), ("tiny", 1e-300)]:
        e = rest.integrate(name, "uniform", 500_000, seed=3)
        assert e.mean == pytest.approx(g.mean * s, rel=1e-14), name
        assert e.stderr == pytest.approx(g.stderr * s, rel=1e-12), name
        assert e.z_score() == pytest.approx(g.z_score(), rel=1e-9), name


def test_values_spanning_500_orders_of_magnitude():
    y = np.zeros(400_000)
    y[:1000] = 1e-250    # the first blocks set a tiny scale...
    y[300_000] = 4e250   # ...a later value is 500 orders larger
    est = rest.accumulate(y)
    assert est.mean == pytest.approx(4e250 / y.size, rel=1e-12)
    assert math.isfinite(est.stderr)
    assert est.stderr == pytest.approx(np.std(y * 1e-250, ddof=1) * 1e250 / math.sqrt(y.size), rel=1e-9)


def test_nan_inf_and_negatives_are_counted_with_examples_not_averaged():
    y = np.ones(200_000)
    nan_at, inf_at, ninf_at, neg_at = [5, 70_000, 150_000], [9], [12, 13], [100, 101]
    y[nan_at] = np.nan
    y[inf_at] = np.inf
    y[ninf_at] = -np.inf
    y[neg_at] = -2.0
    est = rest.accumulate(y)
    assert est.counts["nan"] == 3 and est.counts["posinf"] == 1 and est.counts["neginf"] == 2
    assert est.counts["negative"] == 2
    assert est.drawn == y.size and est.n == y.size - 6
    assert not est.ok and set(est.issues) == {"nan", "posinf", "neginf"}
    assert est.mean == pytest.approx((y.size - 6 - 2 - 4) / (y.size - 6), rel=1e-14)
    by_issue = {}
    for ex in est.examples:
        by_issue.setdefault(ex["issue"], []).append(ex["index"])
    assert by_issue["nan"] == nan_at and by_issue["posinf"] == inf_at and by_issue["neginf"] == ninf_at
    assert by_issue["negative"] == neg_at
    assert "nan: 3" in str(est)


def test_examples_keep_the_first_eight_in_sample_order_across_threads():
    y = np.ones(5 * rest.CHUNK_SIZE)
    bad = np.arange(3, y.size, 9973)
    y[bad] = np.nan
    for threads in (1, 2, 4):
        est = rest.accumulate(y, threads=threads)
        assert est.counts["nan"] == bad.size
        assert [e["index"] for e in est.examples] == list(bad[:8])


def test_nan_from_a_tabulated_integrand_is_reported_with_its_point():
    """A planted NaN in a tabulated integrand reaches the estimator through the C++ path:
    reported with the sample's point, excluded from the moments."""
    values = np.array([1.0, 2.0, np.nan, -1.0])
    f = rest.tabulated_integrand(values, 0.0, 2.0)
    est = rest.integrate(f, rest.uniform(f), 100_000, seed=2)
    assert est.counts["nan"] > 20_000 and est.counts["negative"] > 20_000
    assert est.n + est.counts["nan"] == est.drawn == 100_000
    points = [e["point"][0] for e in est.examples if e["issue"] == "nan"]
    assert points and all(1.0 <= p <= 1.5 for p in points), points
    negatives = [e["point"][0] for e in est.examples if e["issue"] == "negative"]
    assert negatives and all(1.5 <= p <= 2.0 for p in negatives)
    assert not est.ok  # NaN is an error; negatives are allowed for a signed integrand
    assert "negative" not in est.issues


def test_zero_variance_estimates_are_exact_to_rounding():
    for integrand, technique in [("singularity", "importance:power"), ("ggx_lobe", "importance:ggx")]:
        est = rest.integrate(integrand, technique, 1_000_000, seed=0)
        assert abs(est.mean - est.reference) <= est.rounding_error, (integrand, est.mean)
        assert est.stderr <= est.rounding_error
        assert abs(est.z_score()) <= 1


def test_empty_and_malformed_values_are_rejected():
    with pytest.raises(ValueError, match="'values' must not be empty"):
        rest.accumulate([])
    with pytest.raises(ValueError, match="'values' must be one-dimensional"):
        rest.accumulate(np.ones((3, 2)))


def test_examples_name_the_right_sample_after_excluded_ones():
    """Samples dropped for a bad pdf are removed before the contributions are screened; an
    infinite contribution later in the same block must still report its own index."""
    x = np.full(10, 0.5)
    pdf = np.ones(10)
    pdf[1] = 0.0        # zero pdf: excluded, reported
    pdf[4] = 1e-320     # f/p overflows to +inf: excluded, reported
    est = rest.estimate_from_samples("gaussian", x, pdf)
    ex = {e["issue"]: e["index"] for e in est.examples}
    assert ex == {"zero_pdf": 1, "posinf": 4}, est.examples
    assert est.n == 8 and est.drawn == 10
