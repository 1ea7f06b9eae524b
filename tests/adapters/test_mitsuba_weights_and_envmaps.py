"""The weight check (weight = eval / pdf) on Mitsuba samplers, and the envmap's texel breaks."""
from __future__ import annotations

import numpy as np
import pytest

from harness.adapters.mitsuba import checks, faults, runtime
from harness.adapters.mitsuba import samplers as ms
from harness.stats import ConfidenceInterval
from tests.adapters.mitsuba_helpers import ALPHA, N


# --- weight consistency ---------------------------------------------------------------------------
def test_envmap_weight_is_radiance_over_pdf():
    # a sky without a sun: no steep texel ramps, so float32 keeps weights within 1e-4
    s = ms.envmap_sampler(ms.sky_bitmap(sun_radiance=0.0))
    w = checks.weight_consistency(s, sample_count=100_000, seed=0)
    assert w.passed, str(w)
    assert w.produced == 100_000


def test_envmap_weight_at_the_sun_rim_within_float32_conditioning():
    # measured: Mitsuba's sample_direction weight differs from eval/pdf_direction by up to
    # 1.4e-3 on the sun's rim texels (a 2000:0.4 ramp), about 2 in 1e5 samples
    s = ms.envmap_sampler()
    w = checks.weight_consistency(s, sample_count=100_000, seed=0, rtol=3e-3)
    assert w.passed, str(w)


def test_envmap_texel_breaks_lie_on_the_kinks_of_its_pdf():
    """EnvmapSampler.breaks (texel_breaks): in the parameters of the sphere with its pole at
    +y, Mitsuba's bilinear pdf bends on every declared break (its second difference within
    two of 20,000 probes of a break) more than 3 times as sharply as anywhere else on the
    line (float32 noise; measured 5.7 and 13 times): a random 8 x 16 map, so that every
    texel line bends it; away from the poles along the rows, where the 1 / sin theta that
    the weight removes is steep."""
    from harness.samplers import Domain

    img = np.random.default_rng(1).uniform(0.2, 1.0, (8, 16, 3)).astype(np.float32)
    s = ms.envmap_sampler(img, texel_breaks=True)
    dom, (rows, columns) = Domain("sphere", pole="y"), s.breaks
    n = 20_000
    t = (np.arange(n) + 0.5) / n
    for axis, declared, weight in [(1, columns, 1.0), (0, rows, np.sqrt(t * (1 - t)))]:
        s_ = np.full((n, 2), 0.37)
        s_[:, axis] = t
        q = s.pdf(dom.to_points(s_)) * weight       # along the rows: without the pole's 1 / sin theta
        bend, mid = np.abs(np.diff(q, 2)), t[1:-1]
        away = np.min(np.abs(mid[:, None] - declared[None, :]), axis=1) > 3 / n
        on = [bend[np.abs(mid - b) <= 2 / n].max() for b in declared]
        elsewhere = bend[away & (mid > 0.02) & (mid < 0.98)].max()
        assert min(on) > 3 * elsewhere, (axis, min(on), elsewhere)
    plain = ms.envmap_sampler(img, texel_breaks=False)
    assert plain.breaks is None and plain.pole == "z"


def test_texel_breaks_of_an_envmap_file_and_from_a_suite_table(tmp_path):
    """A map given by file name has the breaks of its resolution, as read by Mitsuba; a suite
    table asks for them with texel_breaks = true (the sampler's fingerprint says so)."""
    img = np.random.default_rng(2).uniform(0.2, 1.0, (8, 16, 3)).astype(np.float32)
    path = tmp_path / "sky.exr"
    with runtime.using_variant("llvm_ad_rgb") as mi:
        mi.Bitmap(img).write(str(path))
    from_file = ms.make_sampler({"plugin": {"type": "envmap", "filename": str(path)}, "texel_breaks": True})
    from_array = ms.envmap_sampler(img, texel_breaks=True)
    assert all(np.array_equal(a, b) for a, b in zip(from_file.breaks, from_array.breaks))
    assert from_file.pole == "y" and from_file.fingerprint()["texel_breaks"] is True
    assert ms.make_sampler({"plugin": {"type": "envmap"}}).fingerprint()["texel_breaks"] is True  # default
    off = ms.make_sampler({"plugin": {"type": "envmap"}, "texel_breaks": False})
    assert off.fingerprint()["texel_breaks"] is False and off.breaks is None


@pytest.mark.slow
def test_an_envmap_with_texel_breaks_keeps_its_marginal_tests_sharp():
    """The 256 x 128 sky with a hard-edged sun: without texel_breaks the marginal CDF table
    carries a bound of 0.04 (its u0 test has no power at any n); with them, below 1e-4, and
    the tests pass at ALPHA (seed 0), beside Mitsuba's documented reported-pdf finding."""
    import re

    def u0_bound(r):
        row = r.tests[r.tests["test"].str.startswith("Cramer-von Mises u0")].iloc[0]
        return float(re.search(r"CDF error bound ([0-9.e+-]+) carried", row["detects"]).group(1))

    hard = ms.sky_bitmap(sun_edge=0.0)
    r = checks.check_mitsuba_sampler(ms.envmap_sampler(hard, texel_breaks=True), sample_count=N, seed=0,
                                     alpha=ALPHA)
    assert u0_bound(r) <= 1e-4 and r.pvalue > ALPHA, str(r)
    assert [f.check for f in r.failures] == ["reported_pdf"]
    plain = checks.check_mitsuba_sampler(ms.envmap_sampler(hard, texel_breaks=False), sample_count=N, seed=0,
                                         alpha=ALPHA)
    assert u0_bound(plain) >= 0.01


def test_planted_weight_mismatch_is_reported_with_examples():
    base = ms.bsdf_sampler({"type": "roughconductor", "distribution": "ggx", "alpha": 0.1}, wi=45)
    mutant = faults.Mutant(base, "no cos", weight_fault=faults.no_cosine)
    w = checks.weight_consistency(mutant, sample_count=20_000, seed=0)
    assert not w.passed and w.verdict == "failed" and w.n == 20_000
    assert w.mismatches > 0.95 * w.produced
    ex = w.examples[0]
    assert ex["check"] == "weight != eval/pdf"
    assert set(ex) >= {"index", "u", "direction", "weight", "eval/pdf", "eval", "pdf"}
    z = ex["direction"][2]
    assert ex["weight"][0] == pytest.approx(ex["eval/pdf"][0] / z, rel=1e-4)
    assert "weight(s) differ from eval/pdf" in str(w)
    import json

    payload = json.loads(json.dumps(w.to_payload()))
    assert not payload["passed"] and payload["failures"][0]["check"] == "weight_mismatch"
    assert payload["failures"][0]["count"] == w.mismatches
    assert payload["failures"] == [f.to_dict() for f in w.failures]
    assert w.failures[0].check == "weight_mismatch"
    ci = w.confidence_interval()
    assert isinstance(ci, ConfidenceInterval) and ci.low <= w.mismatches / w.produced <= ci.high < 1.01


def test_nan_and_negative_weights_are_reported():
    base = ms.bsdf_sampler({"type": "diffuse"}, wi=0)

    def poison(b):
        w = b.weight.copy()
        w[::100] = np.nan
        w[1::100] = -w[1::100]
        return w

    w = checks.weight_consistency(faults.Mutant(base, "poison", weight_fault=poison), sample_count=10_000,
                                  seed=0)
    assert not w.passed
    assert w.bad_weights == 200
    assert any(e["check"] == "NaN/Inf/negative weight" for e in w.examples)
