"""The reported-pdf check: the pdf a sampler reports with its samples against its claimed pdf."""
from __future__ import annotations

import math

import numpy as np
import pytest

import reference_estimators as rest

from harness.samplers import SamplerTest, check_sampler
from harness.samplers.reported import reported_pdf_failure
from harness.usercode import UserCodeError


# --- the pdf a sampler reports with its samples ------------------------------------------------
def test_a_sampler_reporting_its_own_pdf_passes_also_in_float32():
    cos = rest.sampler("cosine_hemisphere")
    assert check_sampler(cos.sample, cos.pdf, "hemisphere", sample_count=20_000).passed

    def float32_sample(u):  # a float32 renderer: points and pdf values rounded to float32
        w, p = cos.sample(u)
        return w.astype(np.float32), (w.astype(np.float32)[:, 2] / np.float32(math.pi)).astype(np.float32)

    r = check_sampler(float32_sample, cos.pdf, "hemisphere", sample_count=20_000)
    assert r.passed, str(r)


@pytest.mark.parametrize("fault, factor", [("an opacity factor 0.7 left out", 1 / 0.7),
                                           ("a factor 1.001 too large", 1.001)])
def test_a_reported_pdf_off_by_a_factor_fails_with_counts_and_examples(fault, factor):
    cos = rest.sampler("cosine_hemisphere")

    def sample(u):
        w, p = cos.sample(u)
        return w, p * factor

    r = check_sampler(sample, cos.pdf, "hemisphere", sample_count=10_000)
    f = {x.check: x for x in r.failures}
    assert not r.passed and r.verdict == "failed" and "reported_pdf" in f, fault
    assert f["reported_pdf"].count == 10_000 and len(f["reported_pdf"].examples) == 5
    ex = f["reported_pdf"].examples[0]
    assert ex["reported"] == pytest.approx(factor * ex["pdf"], rel=1e-12)
    assert f"{factor - 1:.3g}" in f["reported_pdf"].detail


def test_the_reported_pdf_check_told_every_point_is_finite_finds_the_same():
    """The sampler check tells the reported-pdf check that every point is finite where every
    point lies inside the domain (all_finite, which skips finite_rows): the same failure, count,
    detail and examples as that check testing the rows itself, on mismatches spread over the
    rows and on none."""
    from harness.samplers.reported import reported_pdf_failure
    cos = rest.sampler("cosine_hemisphere")
    w, p = cos.sample(rest.points(5_000, 2, seed=2))
    off = p.copy()
    off[::7] *= 1.01
    for reported in (p, off):
        told = reported_pdf_failure(w, reported, cos.pdf, all_finite=True)
        found = reported_pdf_failure(w, reported, cos.pdf)
        assert told == found
    assert found is not None and found.count == len(off[::7])


def test_the_sampled_lobes_pdf_reported_instead_of_the_mixtures_fails():
    """A two-lobe mixture (cosine and uniform, half each) whose sample() reports the pdf of
    the lobe it sampled: where the samples go is right, so only this check sees it."""
    cos, uni = rest.sampler("cosine_hemisphere"), rest.sampler("uniform_hemisphere")

    def pdf(w):
        return 0.5 * cos.pdf(w) + 0.5 * uni.pdf(w)

    def sample(u):
        first = u[:, 0] < 0.5
        v = u.copy()
        v[:, 0] = np.where(first, 2 * u[:, 0], 2 * u[:, 0] - 1)
        wc, pc = cos.sample(v)
        wu, pu = uni.sample(v)
        return np.where(first[:, None], wc, wu), np.where(first, pc, pu)

    r = check_sampler(sample, pdf, "hemisphere", sample_count=20_000)
    assert [f.check for f in r.failures] == ["reported_pdf"]
    assert r.tests["adjusted"].min() > 0.01  # the tests of where the samples go all pass
    honest = check_sampler(lambda u: (sample(u)[0], pdf(sample(u)[0])), pdf, "hemisphere",
                           sample_count=20_000)
    assert honest.passed, str(honest)


def test_the_claimed_pdf_is_called_once_at_the_samples_also_with_a_reported_pdf():
    """check_points calls the user's pdf once at the sampled points and the reported-pdf check
    reuses those values, also where the density tested is pdf / total (missing samples); a
    mismatch calls it again only at the nudged copies of the mismatching samples."""
    cos = rest.sampler("cosine_hemisphere")
    calls = []

    def pdf(w):
        calls.append(w.shape[0])
        return cos.pdf(w)

    test = SamplerTest(pdf, "hemisphere", sample_count=20_000)
    w, p = cos.sample(rest.points(20_000, 2, seed=1))
    half = test.for_total(0.5)
    assert np.array_equal(half.pdf(w), cos.pdf(w) / 0.5)
    for t in (test, half):
        calls.clear()
        r = t.check_points(w, p)
        assert calls == [20_000] and "reported_pdf" not in [f.check for f in r.failures]
    calls.clear()
    r = test.check_points(w, p * 1.01)
    assert [f.check for f in r.failures] == ["reported_pdf"] and r.failures[0].count == 20_000
    assert calls == [20_000] * 7            # at the samples, then at the 6 nudged copies
    with pytest.raises(ValueError, match="'values' must hold pdf"):
        reported_pdf_failure(w, p, cos.pdf, values=p[:10])


def test_a_reported_pdf_of_the_wrong_length_is_named():
    cos = rest.sampler("cosine_hemisphere")
    with pytest.raises(UserCodeError, match="pdf values with 2000 points"):
        check_sampler(lambda u: (cos.sample(u)[0], np.ones(3)), cos.pdf, "hemisphere", sample_count=2000)
