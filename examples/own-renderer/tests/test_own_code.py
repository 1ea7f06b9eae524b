"""The team's own unit tests, with harness.testing: each assertion fails with the measurement,
its interval, the sample count, alpha and what was expected."""
import myest
import mysampler
import pytest

from harness.testing import assert_biased, assert_converges, assert_sampler, assert_unbiased


def test_nee_is_unbiased():
    assert_unbiased(myest.nee, 2, myest.EXACT, sample_count=1_000_000)


def test_the_skewed_twin_is_found_biased():
    assert_biased(myest.skewed, 2, myest.EXACT, sample_count=1_000_000)


def test_nee_converges_at_the_monte_carlo_rate():
    assert_converges(myest.nee, budgets=[4096, 16384, 65536], dim=2, reference=myest.EXACT)


def test_the_cosine_sampler_draws_its_pdf():
    s = mysampler.good
    assert_sampler(s.sample, s.pdf, "hemisphere", sample_count=500_000)


def test_an_absorbing_sampler_is_checked_with_its_total():
    s = mysampler.Absorbing(albedo=0.6)
    assert_sampler(s.sample, s.pdf, "hemisphere", sample_count=500_000, total=s.total)


def test_the_skewed_sampler_fails_its_check():
    s = mysampler.skewed
    with pytest.raises(AssertionError, match="expected the samples of mysampler:SkewedCosine.sample"):
        assert_sampler(s.sample, s.pdf, "hemisphere", sample_count=500_000)
