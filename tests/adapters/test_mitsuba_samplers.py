"""Mitsuba 3 samplers (harness.adapters.mitsuba: samplers, checks, faults, catalogue, runtime)
against their pdfs and weights.

Real llvm_ad_rgb objects.  Statistical checks state alpha and use seed 0 (chosen before the
tests were written); 2e5 samples per check here, 1e6 in benchmarks/mitsuba_samplers.py.
"""
from __future__ import annotations

import math
import os

import numpy as np
import pytest

from harness.adapters.mitsuba import catalogue as cat
from harness.adapters.mitsuba import checks, faults, runtime
from harness.adapters.mitsuba import samplers as ms
from harness.samplers import check_sampler
from harness.samplers.check import failure_pvalue
from harness.stats import ConfidenceInterval

N = 200_000
ALPHA = 0.01


# --- the failure-aware check on a synthetic defective sampler (no Mitsuba) ---------------------
class _Capped:
    """Uniform directions on the hemisphere; those with z < 0.1 are 'not produced' (NaN).
    The pdf claims 1/(2 pi) on z >= ``claimed_cut`` and 0 below: P = 1 - claimed_cut."""

    domain, udim, variant = "hemisphere", 2, "llvm_ad_rgb"

    def __init__(self, claimed_cut: float = 0.1):
        self.claimed_cut = claimed_cut

    def sample(self, u):
        z, phi = u[:, 0], 2 * math.pi * u[:, 1]
        r = np.sqrt(1 - z * z)
        x = np.column_stack([r * np.cos(phi), r * np.sin(phi), z])
        x[z < 0.1] = np.nan
        return x

    def pdf(self, x):
        return np.where(x[:, 2] >= self.claimed_cut, 1 / (2 * math.pi), 0.0)


def test_failed_samples_are_allowed_when_the_pdf_says_so():
    r = checks.check_mitsuba_sampler(_Capped(0.1), sample_count=N, seed=0, alpha=ALPHA)
    assert r.passed, str(r)
    assert r.normalization[0] == pytest.approx(0.9, abs=1e-6)
    row = r.tests[r.tests["test"] == "failed samples"].iloc[0]
    assert 0.09 * N < row["statistic"] < 0.11 * N


def test_failure_count_against_the_pdf_mass_is_tested():
    # 10 % of samples fail, the pdf claims 0 mass missing on z >= 0.08: 2 % too few failures
    r = checks.check_mitsuba_sampler(_Capped(0.08), sample_count=N, seed=0, alpha=ALPHA)
    assert not r.passed
    assert r.tests.set_index("test").loc["failed samples", "adjusted"] <= ALPHA


def test_samples_where_the_pdf_is_zero_are_reported_by_their_own_index():
    # samples with 0.1 <= z < 0.2 are produced, the pdf claims nothing below z = 0.2
    r = checks.check_mitsuba_sampler(_Capped(0.2), sample_count=20_000, seed=0, alpha=ALPHA)
    zero = [f for f in r.failures if f.check == "zero_pdf"]
    assert zero and 0.05 * 20_000 < zero[0].count < 0.15 * 20_000
    for ex in zero[0].examples:
        assert 0.1 <= ex["u"][0] < 0.2                   # u of the original sample: z = u0
        assert ex["point"][2] == pytest.approx(ex["u"][0])


def test_check_sampler_takes_failed_samples_as_the_mitsuba_check_does():
    # NaN rows are missing samples for check_sampler too: the same failure-aware check
    s = _Capped(0.1)
    a = check_sampler(s.sample, s.pdf, "hemisphere", sample_count=20_000, seed=0, udim=s.udim)
    b = checks.check_mitsuba_sampler(s, sample_count=20_000, seed=0)
    assert a.passed and b.passed and a.tests.equals(b.tests)


@pytest.mark.slow
def test_failure_aware_check_false_alarms_stay_rare():
    # 20 seeds of a correct defective sampler at alpha = 0.01: more than 3 rejections would
    # happen with probability < 1e-3 if the false-alarm rate held
    rejected = sum(not checks.check_mitsuba_sampler(_Capped(0.1), sample_count=20_000, seed=s,
                                                    alpha=ALPHA).passed for s in range(20))
    assert rejected <= 3, f"{rejected} of 20 correct checks rejected at alpha = {ALPHA}"


def test_failure_pvalue_is_conservative_within_the_cubature_error():
    assert failure_pvalue(1000, 100_000, 0.99, 1e-6) == 1.0       # exactly N (1 - P)
    assert 0.01 < failure_pvalue(1020, 100_000, 0.99, 1e-6) < 0.9  # 0.6 sigma off
    assert failure_pvalue(1010, 100_000, 0.99, 2e-4) == 1.0       # inside the interval
    assert failure_pvalue(0, 100_000, 1.0, 1e-6) == 1.0
    assert failure_pvalue(3, 100_000, 1.0, 0.0) == 0.0            # failures where the pdf says none
    assert failure_pvalue(0, 100_000, 0.99, 1e-6) < 1e-100         # no failures, 1 % expected


# --- real plugins pass, planted faults are caught ------------------------------------------------
REAL = [
    ("diffuse", {"type": "diffuse"}, 45),
    ("conductor ggx 0.01", {"type": "roughconductor", "distribution": "ggx", "alpha": 0.01}, 45),
    ("conductor beckmann 0.1 all normals",
     {"type": "roughconductor", "distribution": "beckmann", "alpha": 0.1, "sample_visible": False}, 80),
    ("conductor ggx 0.5", {"type": "roughconductor", "distribution": "ggx", "alpha": 0.5}, 0),
    ("dielectric ggx 0.5",
     {"type": "roughdielectric", "distribution": "ggx", "alpha": 0.5, "int_ior": 1.5}, 45),
    ("dielectric ggx 0.1",
     {"type": "roughdielectric", "distribution": "ggx", "alpha": 0.1, "int_ior": 1.5}, 80),
    ("plastic ggx 0.1", {"type": "roughplastic", "distribution": "ggx", "alpha": 0.1}, 0),
]


@pytest.fixture(scope="module")
def real_table():
    entries = [cat.CatalogueEntry(label, t, lambda p=p, t=t: ms.bsdf_sampler(p, wi=t))
               for label, p, t in REAL]
    entries += [
        cat.CatalogueEntry("microfacet ggx 0.1 visible", 80,
                           lambda: ms.microfacet_sampler("ggx", 0.1, wi=80)),
        cat.CatalogueEntry("microfacet beckmann 0.5 all", None,
                           lambda: ms.microfacet_sampler("beckmann", 0.5, visible=False)),
        cat.CatalogueEntry("envmap sky + sun", None, lambda: ms.envmap_sampler()),
    ]
    return cat.run_catalogue(entries, sample_count=N, seed=0, alpha=ALPHA, weight_samples=N)


@pytest.mark.slow
def test_real_plugins_pass_the_chi_square(real_table):
    # Holm over the 10 checks at family-wise alpha = 0.01
    bad = real_table[real_table["chi2"] != "pass"]
    assert bad.empty, bad[["label", "pvalue", "adjusted", "failures"]].to_string()
    domains = ["hemisphere"] * 4 + ["sphere"] * 2 + ["hemisphere"] * 3 + ["sphere"]
    assert (real_table["domain"] == domains).all()


@pytest.mark.slow
def test_real_bsdf_weights_equal_eval_over_pdf(real_table):
    bsdfs = real_table[real_table["plugin"].isin([label for label, _, _ in REAL])]
    assert len(bsdfs) == len(REAL)
    bad = bsdfs[bsdfs["weight"] != "pass"]
    assert bad.empty, bad[["label", "weight_mismatches", "bad_weights", "weight_max_rel"]].to_string()
    assert (bsdfs["weight_max_rel"] < 1e-5).all()
    assert real_table.set_index("plugin").loc["microfacet ggx 0.1 visible", "weight"] == "n/a"


@pytest.mark.slow
def test_microfacet_models_fail_samples_where_the_pdf_says():
    # visible-normal GGX at 80 degrees: the reflected direction goes below the horizon for
    # about 3.6 % of the samples; the pdf's missing mass must match (binomial test inside)
    s = ms.bsdf_sampler({"type": "roughconductor", "distribution": "ggx", "alpha": 0.1}, wi=80)
    r = checks.check_mitsuba_sampler(s, sample_count=N, seed=0, alpha=ALPHA)
    assert r.passed, str(r)
    assert 0.95 < r.normalization[0] < 0.98


WRONG = {
    "roughconductor ggx α=0.1, pdf × 1.005 θi=45°": "chi2",        # caught by the failure count
    "diffuse, pdf × 0.995 θi=45°": "chi2",                          # caught by the failure count
    "roughconductor ggx samples α=0.11, pdf α=0.1 θi=45°": "chi2",
    "microfacet ggx visible samples α=0.11, pdf α=0.1 θi=45°": "chi2",
    "envmap, pdf × 1.005": "chi2",                                  # normalisation, deterministic
    "envmap, pdf of the map with the sun 1° away": "chi2",
    "roughconductor ggx α=0.1, weight without cos θo θi=45°": "weight",
    "roughplastic ggx α=0.1, weight × 1.001 θi=45°": "weight",
}


@pytest.mark.slow
def test_planted_faults_are_caught():
    entries = [e for e in cat.wrong_catalogue() if e.label in WRONG]
    assert len(entries) == len(WRONG)
    table = cat.run_catalogue(entries, sample_count=N, seed=0, alpha=ALPHA, weight_samples=20_000)
    for _, row in table.iterrows():
        assert row[WRONG[row["label"]]] == "FAIL", row.to_string()
    # only the weight is wrong: the chi-square cannot see it, the weight check must
    weight_only = table[table["fault"].str.startswith("weight")]
    assert (weight_only["chi2"] == "pass").all() and (weight_only["weight"] == "FAIL").all()
    envmap_scaled = table.set_index("label").loc["envmap, pdf × 1.005"]
    assert "normalization" in envmap_scaled["failures"]


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


# --- adapter mechanics -------------------------------------------------------------------------
def test_libllvm_is_found_in_one_place_and_a_users_path_is_kept(monkeypatch):
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", "/opt/llvm/lib/libLLVM.so")
    assert runtime.use_libllvm() == "/opt/llvm/lib/libLLVM.so"
    monkeypatch.delenv("DRJIT_LIBLLVM_PATH")
    found = runtime.use_libllvm()
    if found is not None:  # Debian's libLLVM-19 (installed where these tests run)
        assert os.path.isfile(found) and os.environ["DRJIT_LIBLLVM_PATH"] == found and "LLVM" in found


def test_directions_in_the_local_frame_and_failed_rows_nan():
    s = ms.bsdf_sampler({"type": "roughconductor", "distribution": "ggx", "alpha": 0.5}, wi=80)
    u = np.random.default_rng(0).random((10_000, 3))
    x = s.sample(u)
    ok = np.all(np.isfinite(x), axis=1)
    assert 0.85 < ok.mean() < 0.99
    assert np.all(x[ok, 2] > 0)
    np.testing.assert_allclose(np.linalg.norm(x[ok], axis=1), 1, atol=1e-6)
    assert np.all(s.pdf(x[ok]) > 0)
    assert s.pdf(np.array([[0.0, 0.0, -1.0], [np.nan, 0, 1]])).tolist() == [0.0, 0.0]
    # mirror-like lobe: the mean direction is near the mirror direction of wi for small alpha
    m = ms.bsdf_sampler({"type": "roughconductor", "alpha": 0.01}, wi=45).sample(u)
    mean = np.nanmean(m, axis=0)
    np.testing.assert_allclose(mean / np.linalg.norm(mean), [-math.sqrt(0.5), 0, math.sqrt(0.5)], atol=0.01)


def test_dielectric_samples_both_hemispheres():
    s = ms.bsdf_sampler({"type": "roughdielectric", "alpha": 0.1, "int_ior": 1.5}, wi=45)
    assert s.domain == "sphere" and s.transmits
    x = s.sample(np.random.default_rng(1).random((20_000, 3)))
    z = x[np.all(np.isfinite(x), axis=1), 2]
    assert 0.02 < np.mean(z > 0) < 0.2          # Fresnel reflectance near 45 degrees, 1.5: about 5 %
    assert np.mean(z < 0) > 0.8


def test_survives_another_callers_variant_switch():
    import mitsuba as mi

    s = ms.bsdf_sampler({"type": "roughplastic", "alpha": 0.1}, wi=30)
    u = np.random.default_rng(2).random((1000, 3))
    before = s.sample(u)
    with runtime.VARIANT_LOCK:
        mi.set_variant("scalar_rgb")             # what another adapter may do between our calls
    np.testing.assert_array_equal(s.sample(u), before)
    assert mi.variant() == "llvm_ad_rgb"


def test_scalar_variant_agrees_with_llvm_on_few_samples():
    plugin = {"type": "roughconductor", "distribution": "ggx", "alpha": 0.3}
    scalar = ms.bsdf_sampler(plugin, wi=45, variant="scalar_rgb")
    llvm = ms.bsdf_sampler(plugin, wi=45, variant="llvm_ad_rgb")
    u = np.random.default_rng(3).random((300, 3))
    a, b = scalar.sample_batch(u), llvm.sample_batch(u)
    np.testing.assert_array_equal(a.valid, b.valid)
    np.testing.assert_allclose(a.x[a.valid], b.x[b.valid], atol=2e-6)
    np.testing.assert_allclose(a.weight[a.valid], b.weight[b.valid], rtol=1e-5)
    np.testing.assert_allclose(scalar.pdf(b.x[b.valid]), llvm.pdf(b.x[b.valid]), rtol=1e-5)
    assert checks.weight_consistency(scalar, sample_count=300, seed=0).passed


def test_scalar_variant_is_refused_by_the_chi_square_check():
    s = ms.bsdf_sampler({"type": "diffuse"}, variant="scalar_rgb")
    with pytest.raises(ValueError, match="needs a JIT variant"):
        checks.check_mitsuba_sampler(s, sample_count=10_000)


def test_make_sampler_from_a_suite_table():
    s = ms.make_sampler({"plugin": {"type": "roughconductor", "distribution": "beckmann", "alpha": 0.1},
                         "wi": 45})
    assert isinstance(s, ms.BSDFSampler) and s.domain == "hemisphere" and s.udim == 3
    np.testing.assert_allclose(s.wi, [math.sqrt(0.5), 0, math.sqrt(0.5)])
    m = ms.make_sampler({"plugin": {"type": "microfacet", "distribution": "ggx", "alpha": 0.2,
                                    "sample_visible": False}})
    assert isinstance(m, ms.MicrofacetSampler) and not m.visible and m.udim == 2
    e = ms.make_sampler({"plugin": {"type": "envmap", "scale": 2.0}})
    assert isinstance(e, ms.EnvmapSampler) and e.domain == "sphere"
    fp = s.fingerprint()
    assert fp["plugin"]["distribution"] == "beckmann" and fp["variant"] == "llvm_ad_rgb"


@pytest.mark.parametrize("spec, match", [
    ({"plugin": {"type": "diffuse"}, "theta": 3}, "'theta': unknown key"),
    ({"plugin": "diffuse"}, "'plugin': expected a table"),
    ({"plugin": {"type": "no_such_bsdf"}}, "'plugin': Mitsuba cannot build"),
    ({"plugin": {"type": "conductor"}}, "Dirac delta"),
    ({"plugin": {"type": "diffuse"}, "wi": 95}, "'wi' as an angle"),
    ({"plugin": {"type": "diffuse"}, "wi": [0, 0, -1]}, "'wi' must be"),
    ({"plugin": {"type": "diffuse"}, "variant": "llvm_ad_spectral"}, "RGB or mono"),
    ({"plugin": {"type": "diffuse"}, "variant": "nope"}, "installed Mitsuba variant"),
    ({"plugin": {"type": "microfacet", "alpha": 0.1, "roughness": 2}}, "unknown key 'roughness'"),
    ({"plugin": {"type": "microfacet", "distribution": "phong"}}, "'distribution' must be"),
])
def test_make_sampler_errors_name_the_key(spec, match):
    with pytest.raises(ValueError, match=match):
        ms.make_sampler(spec)


# --- suite wiring: [[sampler]] tables with adapter = "mitsuba" ---------------------------------
def test_suite_sampler_tables_run_mitsuba_checks(tmp_path):
    from harness.suite.parse import load_suite
    from harness.suite.run import run_suite

    path = tmp_path / "samplers.toml"
    path.write_text(
        '[suite]\nname = "ms"\nsamples = 200_000\n'
        '[[sampler]]\nadapter = "mitsuba"\n'
        'plugin = { type = "roughconductor", distribution = "ggx", alpha = 0.1 }\n'
        'wi = 45\n'
        '[[sampler]]\nadapter = "mitsuba"\n'
        'plugin = { type = "microfacet", distribution = "ggx", alpha = 0.5 }\n'
        '[[sampler]]\nadapter = "mitsuba"\nplugin = { type = "envmap" }\n')
    suite = load_suite(path)
    assert [sc.measurements for sc in suite.samplers] == [("chi_square", "weight"), ("chi_square",),
                                                          ("chi_square", "weight")]
    assert suite.samplers[0].domain == "hemisphere" and suite.samplers[2].domain == "sphere"
    summary = run_suite(suite, tmp_path / "ms.sqlite")
    verdicts = summary["sampler"].verdicts
    assert verdicts[0]["chi_square"] == verdicts[0]["weight"] == "passed"
    assert verdicts[1]["chi_square"] == "passed"
    # the environment map's weights differ from eval/pdf on the sun's rim (float32 in Mitsuba)
    assert verdicts[2]["chi_square"] == "passed" and verdicts[2]["weight"] == "failed"
    w = summary["sampler"].results[2].checks["weight"]
    assert w["failures"][0]["check"] == "weight_mismatch" and w["failures"][0]["examples"]
    assert run_suite(suite, tmp_path / "ms.sqlite").units_run == 0


@pytest.mark.parametrize("body, key", [
    ('plugin = { type = "nosuchbsdf" }', "plugin"),
    ('plugin = { type = "diffuse" }\nwi = 95', "wi"),
    ('plugin = { type = "diffuse" }\nvariant = "bogus"', "variant"),
    ('plugin = { type = "diffuse" }\nmeasurements = ["mcmc"]', "measurements"),
    ('plugin = { type = "microfacet" }\nmeasurements = ["weight"]', "measurements"),
    ('plugin = { type = "diffuse" }\nsamples = 10', "samples"),
    ('plugin = { type = "diffuse" }\nfoo = 1', "foo"),
])
def test_suite_sampler_table_errors_name_the_key(tmp_path, body, key):
    from harness.suite.parse import SuiteError, load_suite

    path = tmp_path / "bad.toml"
    path.write_text(f'[[sampler]]\nadapter = "mitsuba"\n{body}\n')
    with pytest.raises(SuiteError, match=rf"bad\.toml:\d+: {key}: "):
        load_suite(path)
