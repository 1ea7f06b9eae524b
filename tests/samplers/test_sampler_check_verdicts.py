"""check_sampler's verdicts: false alarms and power on the zoo and the catalogue, the deterministic checks,
and the result it returns."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

import reference_estimators as rest

from harness.samplers import SamplerTest, check_sampler
from harness.stats import ConfidenceInterval, Failure
from tests.samplers.zoo_samplers import CORRECT, WRONG, correct, wrong


@pytest.mark.slow
@pytest.mark.parametrize("name", CORRECT)
def test_false_alarm_rate_over_200_seeds(name):
    """alpha = 0.01, 1e5 samples, seeds 0..199: failures must stay below the Binomial(200,
    0.01) quantile at 1e-3 / (number of correct samplers) (Bonferroni)."""
    s = correct(name)
    t = SamplerTest(s.pdf, s.domain, sample_count=100_000, alpha=0.01, breaks=s.breaks)
    fails = [seed for seed in range(200) if not t.check(s.sample, seed=seed).passed]
    bound = stats.binom.isf(1e-3 / len(CORRECT), 200, 0.01)
    assert len(fails) <= bound, (f"{s.name}: {len(fails)} false alarms of 200 (bound {bound:.0f}), "
                                 f"seeds {fails[:10]}")


@pytest.mark.slow
@pytest.mark.parametrize("name", WRONG)
def test_every_mutant_is_caught_at_one_million_samples(name):
    s = wrong(name)
    t = SamplerTest(s.pdf, s.domain, sample_count=1_000_000, breaks=s.breaks)
    results = [t.check(s.sample, seed=seed) for seed in range(5)]
    assert not any(r.passed for r in results), f"{s.name} ({s.fault}) passed: {[r.pvalue for r in results]}"


def test_a_pdf_half_a_percent_too_large_fails_deterministically():
    s = wrong(WRONG[0])
    r = check_sampler(s.sample, s.pdf, s.domain, sample_count=10_000)
    f = {x.check: x for x in r.failures}
    assert not r.passed and "normalization" in f and "1.005000" in f["normalization"].detail
    assert r.normalization[0] == pytest.approx(1.005, abs=1e-9)
    lo, hi = r.confidence_interval()
    assert lo == pytest.approx(1.005, abs=1e-9) and 0 <= hi - lo < 1e-6


def test_points_outside_the_domain_and_bad_pdfs_are_reported_with_examples():
    def sample(u):
        w = rest.sampler("cosine_hemisphere").sample(u)[0]
        w[:10, 2] *= -1  # ten points below the horizon
        return w

    def pdf(w):
        p = np.where(w[:, 2] > 0, w[:, 2] / math.pi, 0.0)
        p[np.abs(w[:, 0] - 0.5) < 1e-4] = np.nan
        return p

    r = check_sampler(sample, pdf, "hemisphere", sample_count=20_000)
    f = {x.check: x for x in r.failures}
    assert not r.passed and r.verdict == "failed" and f["outside_domain"].count == 10
    assert f["outside_domain"].examples[0]["index"] == 0 and f["outside_domain"].examples[0]["point"][2] < 0
    assert f["bad_pdf"].count > 0 and math.isnan(f["bad_pdf"].examples[0]["value"])
    assert "outside_domain: 10" in str(r) and "failed deterministic checks: outside_domain, bad_pdf" in str(r)


def test_samples_where_the_pdf_is_zero_are_reported():
    cone = rest.sampler("uniform_cone", cos_max=0.9)
    narrower = rest.sampler("uniform_cone", cos_max=0.91)
    r = check_sampler(lambda u: cone.sample(u)[0], narrower.pdf, "sphere", sample_count=20_000)
    f = {x.check: x for x in r.failures}
    assert not r.passed and f["zero_pdf"].count > 1000 and f["zero_pdf"].examples


def test_a_sample_of_zero_pdf_fails_on_its_own_not_in_the_pdf_moment():
    """Uniform samples of the square, one moved where the claimed (constant) pdf says 0: its
    own 'zero_pdf' failure; the pdf moment, whose h is constant there (variance 0), leaves it
    out (used, it had rejected at p = 1e-58: a Mitsuba rectangle light's one float32 edge
    sample in a million)."""
    def sample(u):
        x = u.copy()
        x[7] = [0.5, 0.5]
        return x

    def pdf(x):
        return np.where(np.all(x == 0.5, axis=1), 0.0, 1.0)

    r = check_sampler(sample, pdf, "square", sample_count=20_000, seed=3)
    f = {x.check: x for x in r.failures}
    assert not r.passed and f["zero_pdf"].count == 1 and f["zero_pdf"].examples[0]["index"] == 7
    moment = r.tests.set_index("test").loc["pdf moment"]
    assert moment["pvalue"] > 0.01 and (r.tests["adjusted"] > 0.01).all()


def test_result_is_a_table_not_a_bare_bool():
    s = correct("cosine_hemisphere")
    r = check_sampler(s.sample, s.pdf, s.domain, sample_count=50_000, seed=1)
    assert list(r.tests.columns) == ["test", "statistic", "df", "pvalue", "detects", "adjusted"]
    assert list(r.tests["test"]) == ["chi-square 16x32", "chi-square 64x128", "Cramer-von Mises u0 = F(s0)",
                                     "Cramer-von Mises u1 = F(s1 | strip of s0)",
                                     "chi-square equiprobable 32x64", "pdf moment"]
    assert r.passed and r.verdict == "passed" and "PASSED" in str(r)
    assert r.residuals["fine"].shape == (64, 128)
    assert not hasattr(type(r), "__bool__")
    # the result family
    assert r.n == 50_000 and r.alpha == 0.01 and math.isnan(r.statistic)
    assert r.pvalue == r.tests["adjusted"].min() and r.failures == []
    ci = r.confidence_interval(0.99)
    assert isinstance(ci, ConfidenceInterval) and ci.low <= r.normalization[0] <= ci.high
    with pytest.raises(ValueError, match=r"'confidence_level' must be in \(0, 1\)"):
        r.confidence_interval(1.5)


def test_payload_is_plain_json():
    import json

    s = wrong(WRONG[0])
    r = check_sampler(s.sample, s.pdf, s.domain, sample_count=10_000)
    payload = r.to_payload()
    assert json.loads(json.dumps(payload)) == payload
    assert list(payload) == ["passed", "pvalue", "inconclusive", "tests", "failures", "normalization",
                             "residuals", "marginals"]
    assert payload["failures"] == [f.to_dict() for f in r.failures]
    assert [Failure.from_dict(d) for d in payload["failures"]] == r.failures
    assert payload["tests"][0]["test"] == "chi-square 16" and len(payload["residuals"]["fine"]) == 512


def test_for_total_is_the_test_of_the_normalised_pdf():
    """A pdf that integrates to 2: rejected as is, accepted as pdf / 2 without a new cubature."""
    s = correct("cosine_hemisphere")
    twice = SamplerTest(lambda x: 2 * s.pdf(x), s.domain, sample_count=50_000)
    assert not twice.check(s.sample, seed=1).passed
    half = twice.for_total(2.0)
    assert half.normalization == (twice.normalization[0] / 2, twice.normalization[1] / 2)
    r = half.check(s.sample, seed=1)
    assert r.passed, str(r)
    with pytest.raises(ValueError, match="'total' must be a positive"):
        twice.for_total(0.0)


def _registry_sampler(name: str):
    """The registry's sampler ``name`` with its defaults (a table for the tabulated ones)."""
    if name == "piecewise_constant_1d":
        return rest.sampler(name, table=np.array([1.0, 0.0, 3.0, 0.5]))
    if name == "piecewise_constant_2d":
        return rest.sampler(name, table=np.random.default_rng(1).random((8, 16)))
    return rest.sampler(name)


@pytest.mark.slow
@pytest.mark.parametrize("name, domain", [(info["name"], info["domain"]) for info in rest.samplers()])
def test_every_catalogue_sampler_passes_at_one_million_samples(name, domain):
    """Registry defaults, seed 0, alpha = 0.01 each (the seed was fixed before the run)."""
    s = _registry_sampler(name)
    r = check_sampler(lambda u: s.sample(u)[0], s.pdf, domain, sample_count=1_000_000, seed=0)
    assert r.passed, str(r)


def test_a_rejection_sampler_passes_and_its_broken_twin_fails():
    lin = rest.sampler("linear", a=1.0, b=0.37)
    good = rest.rejection_sampler("gaussian", lin, c=1.2)
    r = check_sampler(lambda u: good.draw(len(u), seed=5)[0], good.pdf, "interval", sample_count=200_000)
    assert r.passed, str(r)
    broken = rest.rejection_sampler("gaussian", lin, c=0.5)  # bound violated: too few points where f > c p
    r = check_sampler(lambda u: broken.draw(len(u), seed=5)[0], broken.pdf, "interval", sample_count=200_000)
    assert not r.passed


def test_half_line_domain_for_heavy_tails():
    lomax, expo = rest.sampler("lomax", shape=1.0), rest.sampler("exponential", rate=1.0)
    assert check_sampler(lambda u: lomax.sample(u)[0], lomax.pdf, "half_line", sample_count=200_000).passed
    # exponential points claimed to be Lomax-distributed
    assert not check_sampler(lambda u: expo.sample(u)[0], lomax.pdf, "half_line", sample_count=200_000).passed
