"""The reported-pdf check on Mitsuba samplers: sample()'s pdf against pdf() at the returned direction."""
from __future__ import annotations

import numpy as np
import pytest

from harness.adapters.mitsuba import catalogue as cat
from harness.adapters.mitsuba import checks, faults
from harness.adapters.mitsuba import samplers as ms
from tests.adapters.mitsuba_helpers import ALPHA


# --- the reported pdf (issue 17): sample()'s pdf against pdf() at the returned direction ---------
# deterministic checks; their tolerance (1e-4 relative + float32 rounding of the direction) is
# harness.samplers.reported's
def _reported(r):
    return [f for f in r.failures if f.check == "reported_pdf"]


def test_mask_opacity_missing_from_the_reported_pdf_fails_with_examples():
    # the samples and pdf() are right, only the reported pdf lacks the factor 0.3: the
    # chi-square cannot see it, the reported-pdf check names every produced sample
    base = ms.bsdf_sampler(cat.MASK, wi=45)
    r = checks.check_mitsuba_sampler(faults.Mutant(base, "opacity missing",
                                                   reported_fault=faults.opacity_missing(0.3)),
                                     sample_count=20_000, seed=0, alpha=ALPHA)
    (f,) = _reported(r)
    produced = 20_000 - int(r.tests.set_index("test").loc["failed samples", "statistic"])
    assert f.count == produced and 0.25 * 20_000 < produced < 0.35 * 20_000
    ex = f.examples[0]
    assert ex["reported"] == pytest.approx(ex["pdf"] / 0.3, rel=1e-5) and "u" in ex
    assert r.tests["adjusted"].min() > ALPHA          # no statistical test rejects: only this check
    assert not r.passed and "reported_pdf" in str(r)


def test_sampled_lobes_pdf_instead_of_the_mixtures_fails():
    blend = ms.bsdf_sampler(cat.BLEND, wi=45)
    lobes = {2: ms.bsdf_sampler(cat.BLEND["bsdf_0"], wi=45), 8: ms.bsdf_sampler(cat.BLEND["bsdf_1"], wi=45)}
    mutant = faults.Mutant(blend, "lobe pdf", reported_fault=faults.lobe_pdf_reported(lobes))
    r = checks.check_mitsuba_sampler(mutant, sample_count=20_000, seed=0, alpha=ALPHA)
    (f,) = _reported(r)
    assert f.count > 0.95 * (20_000 - int(r.tests.set_index("test").loc["failed samples", "statistic"]))
    from harness.samplers.reported import reported_pdf_failure

    u = np.random.default_rng(10).random((20_000, 3))
    assert reported_pdf_failure(*blend.sample_with_pdf(u), blend.pdf) is None   # Mitsuba's own: the mixture's


def test_consistent_pdf_faults_are_reported_consistently():
    # a Mutant whose pdf() is wrong reports that same wrong pdf: the chi-square's job alone
    base = ms.bsdf_sampler({"type": "diffuse"}, wi=30)
    r = checks.check_mitsuba_sampler(faults.Mutant(base, "pdf × 1.005", pdf_scale=1.005), sample_count=20_000)
    assert not _reported(r) and any(f.check == "normalization" for f in r.failures)


def test_an_area_density_reported_for_a_solid_angle_one_fails():
    # the reported-pdf check alone (check_mitsuba_sampler runs it too, after a cubature that
    # costs tens of seconds for an area light: the slow tests and the benchmark do that)
    from harness.adapters.mitsuba import emitters as em
    from harness.samplers.reported import reported_pdf_failure

    s = ms.area_emitter_sampler(em.sphere_light(1.0), ref=cat.REFS[1])
    u = np.random.default_rng(7).random((20_000, 2))
    assert reported_pdf_failure(*s.sample_with_pdf(u), s.pdf) is None
    mutant = faults.Mutant(s, "area", reported_fault=faults.area_density_reported)
    f = reported_pdf_failure(*mutant.sample_with_pdf(u), mutant.pdf)
    assert f is not None and f.count == 20_000 and f.check == "reported_pdf"
    ex = f.examples[0]
    assert ex["reported"] < 0.5 * ex["pdf"]       # per area: dist^2 / cos (about 4) times too small
