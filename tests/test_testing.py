"""The assertion helpers of harness.testing, called as a user's test calls them.

alpha = 0.01 (the helpers' default); every check uses the helpers' default seed 0."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import reference_estimators as rest

from harness import stats as hs
from harness import testing

GAUSS = rest.integrand("gaussian").reference


def gaussian(u: np.ndarray) -> np.ndarray:
    return np.exp(-u[:, 0] ** 2)


def test_assert_unbiased_passes_a_correct_estimator_and_explains_a_biased_one():
    assert testing.assert_unbiased(gaussian, 1, GAUSS, sample_count=100_000).verdict == "consistent"
    with pytest.raises(AssertionError, match=r"expected an unbiased estimator of 0.7468.*biased: estimate"):
        testing.assert_unbiased(lambda u: 1.01 * gaussian(u), 1, GAUSS, sample_count=100_000)


def test_assert_biased_finds_a_planted_bias_and_fails_without_one():
    r = testing.assert_biased(lambda u: 1.01 * gaussian(u), 1, GAUSS, sample_count=100_000)
    assert r.verdict == "biased"
    with pytest.raises(AssertionError, match="expected a detectable bias"):
        testing.assert_biased(gaussian, 1, GAUSS, sample_count=100_000)


def test_assert_unbiased_warns_when_no_level_can_be_claimed():
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        # a 50 % bias on Pareto-tailed contributions: p < alpha, but no level can be claimed
        testing.assert_unbiased(lambda u: u[:, 0] ** (-2 / 3) / 3 * 1.5, 1, 1.0, sample_count=100_000)
    assert any(issubclass(x.category, testing.HarnessWarning) for x in w)


def test_assert_converges():
    c = testing.assert_converges("gaussian", "uniform/stratified", [256, 1024, 4096, 16384], rate=-1.5,
                                 replicas=16)
    assert c.slope < -1.3
    with pytest.raises(AssertionError, match=r"expected RMSE ~ n\^-0.50 or faster, got .*clamped"):
        testing.assert_converges("gaussian", "clamped:uniform(0.9)", [256, 1024, 4096, 16384], replicas=16)


def test_assert_rare():
    assert testing.assert_rare(3, 10_000, 1e-3) > 0.01
    with pytest.raises(AssertionError, match=r"40 events in 10000 trials where at most a rate of 0.001"):
        testing.assert_rare(40, 10_000, 1e-3)
    for args, kwargs, message in (((3, 10, 2.0), {}, r"'p' must be a probability in \[0, 1\], got 2.0"),
                                  ((10, 10, 0.001), {"alpha": -1}, r"'alpha' must be in \(0, 1\), got -1"),
                                  ((3, 10.5, 0.1), {}, r"'n' must be a positive whole number, got 10.5"),
                                  ((11, 10, 0.1), {}, r"'count' must be an integer in \[0, 10\], got 11")):
        with pytest.raises(ValueError, match=message):   # alpha -1 and n 10.5 had passed
            testing.assert_rare(*args, **kwargs)
    for alpha in (0, 5):   # alpha 0 had passed a biased technique, 5 failed a correct one
        with pytest.raises(ValueError, match=r"'alpha' must be in \(0, 1\)"):
            hs.check_technique("gaussian", "uniform", 10_000, alpha=alpha)
