"""harness.stats.distributions equals scipy.stats bit for bit, and the harness's import stays light."""
import math
import subprocess
import sys

import numpy as np
import pytest
from scipy import special, stats

from harness.stats import distributions as d

Q = np.array([0.0, 1e-300, 1e-12, 0.005, 0.025, 0.5, 0.975, 0.995, 1 - 1e-12, 1.0, np.nan])
X = np.array([-np.inf, -40.0, -3.0, -0.5, 0.0, 0.5, 3.0, 40.0, np.inf, np.nan])


@pytest.mark.parametrize("df", [1, 2.5, 7, 63, 1e6, 1e20, np.inf])
def test_student_t(df):
    np.testing.assert_array_equal(d.t_ppf(Q, df), stats.t.ppf(Q, df))
    np.testing.assert_array_equal(d.t_cdf(X, df), stats.t.cdf(X, df))
    np.testing.assert_array_equal(d.t_sf(X, df), stats.t.sf(X, df))


@pytest.mark.parametrize("k", [1, 3, 30.5, 1000])
def test_chi2(k):
    np.testing.assert_array_equal(d.chi2_ppf(Q, k), stats.chi2.ppf(Q, k))
    np.testing.assert_array_equal(d.chi2_sf(np.abs(X), k), stats.chi2.sf(np.abs(X), k))


def test_normal_and_f():
    np.testing.assert_array_equal(d.norm_ppf(Q), stats.norm.ppf(Q))
    np.testing.assert_array_equal(d.norm_sf(X), stats.norm.sf(X))
    for d1, d2 in [(2, 10), (6, 400), (40, 2)]:
        np.testing.assert_array_equal(d.f_cdf(np.abs(X), d1, d2), stats.f.cdf(np.abs(X), d1, d2))


def test_scalars_are_numpy_floats_as_in_scipy_stats():
    pairs = [(d.t_ppf(0.975, 5.0), stats.t.ppf(0.975, 5.0)), (d.chi2_sf(3.0, 2), stats.chi2.sf(3.0, 2))]
    for ours, theirs in pairs:
        assert type(ours) is type(theirs) and ours == theirs


def test_the_runner_and_the_cli_do_not_import_scipy_stats_emcee_or_the_renderers():
    """What keeps a resumed suite's command under a second: the run path imports none of them."""
    code = ("import sys, harness, harness.cli, harness.suite.run; "
            "print(sorted(m for m in ('scipy.stats', 'emcee', 'mitsuba', 'pyrender', 'matplotlib', 'dask') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout
    assert out.strip() == "[]"


def test_the_lazy_api_resolves_every_public_name():
    import harness
    import harness.samplers

    for name in harness.__all__:
        assert getattr(harness, name) is not None, name
    assert harness.samplers.mcmc_crosscheck.__module__ == "harness.samplers.mcmc"
    assert set(harness.__all__) <= set(dir(harness))
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        harness.nope  # noqa: B018


def test_the_log_gamma_sum_tail_matches_a_monte_carlo_far_out():
    """The slope's law of a convergence fit (3 budgets, 16 replicas: shapes 8): the saddlepoint
    tail against the quantiles of 2e6 draws, to 1e-4."""
    rng = np.random.default_rng(1)
    x = np.log(256 * 4.0 ** np.arange(3))
    x -= x.mean()
    w, a = 0.5 * x / (x @ x), np.full(3, 8.0)
    draws = w @ np.log(rng.gamma(a[:, None], 1 / a[:, None], (3, 2_000_000)))
    for q in (0.5, 0.1, 1e-2, 1e-3, 1e-4):
        p = d.log_gamma_sum_sf(float(np.quantile(draws, 1 - q)), w, a)
        assert abs(p - q) <= 0.1 * q + 3 * math.sqrt(q / 2e6), (q, p)
    assert d.log_gamma_sum_sf(math.inf, w, a) == 0.0
    assert d.log_gamma_sum_sf(-math.inf, w, a) == 1.0
    assert math.isnan(d.log_gamma_sum_sf(math.nan, w, a))
    # near the mean (where the saddlepoint formula cancels) and for huge shapes: smooth, in [0, 1]
    for shapes in (a, np.array([2.0, 8.0, 16.0]), np.full(3, 1e6)):
        mean = float(np.sum(w * (special.digamma(shapes) - np.log(shapes))))
        sd = math.sqrt(float(np.sum(w * w * special.polygamma(1, shapes))))
        p = [d.log_gamma_sum_sf(mean + k * sd, w, shapes) for k in (-2e-2, -1e-3, -1e-9, 0, 1e-9, 1e-3, 2e-2)]
        assert all(0.4 < v < 0.6 for v in p) and all(np.diff(p) <= 1e-3), (shapes, p)
