"""Samplers that fail to produce some samples (NaN rows: absorption, below the horizon) are
checked with check_sampler's total=: the samples produced against pdf / total, the missing
count by an exact binomial test, Holm-combined at alpha; and a user's sampler or pdf that
raises or returns the wrong shape is named with its input."""
import numpy as np
import pytest

from harness.samplers import check_sampler
from harness.testing import assert_sampler
from harness.usercode import UserCodeError

N = 100_000


def cosine(u):
    """Cosine-weighted hemisphere directions."""
    r, phi = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(1 - r * r, 0))])


def absorbing(albedo):
    """Produces a cosine direction with probability albedo (u0 < albedo, rescaled), else none."""
    def sample(u):
        keep = u[:, 0] < albedo
        v = np.column_stack([np.where(keep, u[:, 0] / albedo, 0.5), u[:, 1]])
        x = cosine(v)
        x[~keep] = np.nan
        return x
    return sample


def scaled_pdf(albedo):
    return lambda x: albedo * x[:, 2] / np.pi


def test_a_sampler_with_missing_samples_passes_with_its_total():
    r = check_sampler(absorbing(0.7), scaled_pdf(0.7), "hemisphere", sample_count=N, total=0.7)
    assert r.passed, r
    row = r.tests.set_index("test").loc["failed samples"]
    assert abs(row["statistic"] - 0.3 * N) < 5 * np.sqrt(0.21 * N)
    assert abs(r.normalization[0] - 0.7) < 1e-3


def test_the_total_is_taken_from_the_cubature_when_not_given():
    r = check_sampler(absorbing(0.7), scaled_pdf(0.7), "hemisphere", sample_count=N)
    assert r.passed and "failed samples" in set(r.tests["test"])


def test_a_pdf_that_claims_the_wrong_missing_mass_fails():
    # the pdf says 80 % of samples arrive; 70 % do
    r = check_sampler(absorbing(0.7), scaled_pdf(0.8), "hemisphere", sample_count=N)
    assert not r.passed
    assert r.tests.set_index("test").loc["failed samples", "adjusted"] <= 0.01
    r = check_sampler(absorbing(0.7), scaled_pdf(0.7), "hemisphere", sample_count=N, total=0.8)
    assert not r.passed and [f.check for f in r.failures] == ["normalization"]
    assert "not the given total 0.8" in r.failures[0].detail


def linear_absorbing(u):
    """x = sqrt(v) on [0, 1] (pdf 2x) for 60 % of the uniforms, no sample for the rest."""
    keep = u < 0.6
    return np.where(keep, np.sqrt(np.where(keep, u / 0.6, 0.0)), np.nan)


@pytest.mark.parametrize("total", [0.6, None])
def test_the_false_alarm_rate_holds_with_missing_samples(total):
    alpha = 0.05
    rejected = sum(not check_sampler(linear_absorbing, lambda x: 1.2 * x, "interval", sample_count=20_000,
                                     seed=s, alpha=alpha, total=total).passed for s in range(200))
    # binomial(200, 0.05): mean 10, P(X > 20) ~ 0.2 %
    assert rejected <= 20


def test_almost_nothing_produced_is_a_deterministic_failure():
    r = check_sampler(absorbing(0.005), scaled_pdf(0.005), "hemisphere", sample_count=N)
    assert not r.passed and r.failures[0].check == "too_few_samples"
    with pytest.raises(ValueError, match=r"'total' must be the pdf's integral over the domain, in \(0, 1\]"):
        check_sampler(cosine, lambda x: x[:, 2] / np.pi, "hemisphere", sample_count=N, total=1.5)


def test_a_scalar_pdf_is_named_with_the_input_shape():
    def flat(x):
        return 1 / (2 * np.pi)
    with pytest.raises(UserCodeError, match=r"flat returned shape \(\) for points of shape \(\d+, 3\), "
                                            r"float64; expected shape \(\d+,\), one density per point"):
        check_sampler(cosine, flat, "hemisphere", sample_count=N)


def test_an_exception_inside_the_sampler_names_it_and_its_input():
    def broken(u):
        return u[:, 5]
    with pytest.raises(UserCodeError, match=r"broken raised IndexError: .* \(called on shape \(100000, 2\), "
                                            r"float64; expected to return points of shape \(100000, 3\) on "
                                            r"the hemisphere\)"):
        check_sampler(broken, lambda x: x[:, 2] / np.pi, "hemisphere", sample_count=N)


def test_assert_sampler_passes_and_fails_with_the_explanation():
    assert_sampler(cosine, lambda x: x[:, 2] / np.pi, "hemisphere", sample_count=N).passed
    with pytest.raises(AssertionError, match=r"expected the samples of .*cosine to follow the pdf .*FAILED"):
        assert_sampler(cosine, lambda x: np.full(len(x), 1 / (2 * np.pi)), "hemisphere", sample_count=N)
