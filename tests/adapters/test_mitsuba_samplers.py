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

import reference_estimators as rest

from harness.adapters.mitsuba import catalogue as cat
from harness.adapters.mitsuba import checks, faults, runtime
from harness.adapters.mitsuba import samplers as ms
from harness.adapters.mitsuba.batch import float32_pdf_of
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


def test_a_check_runs_with_the_samplers_drjit_threads_and_restores_them():
    """A diffuse BSDF's check runs its kernels on one drjit worker (check_threads), an area
    light's on drjit's own count; the count before is restored after, also when the check
    raises; a sampler of the user's own (no check_threads) leaves it alone."""
    import drjit as dr

    seen = []

    class Recorded(ms.BSDFSampler):
        def pdf(self, x):
            seen.append(dr.thread_count())
            return super().pdf(x)

    before = dr.thread_count()
    s = Recorded({"type": "diffuse"}, wi=(0.0, 0.0, 1.0))
    assert checks.check_mitsuba_sampler(s, sample_count=20_000, seed=0).passed
    assert set(seen) == {1} and dr.thread_count() == before

    class Failing(Recorded):
        def pdf(self, x):
            raise RuntimeError("planted")

    with pytest.raises(Exception, match="planted"):
        checks.check_mitsuba_sampler(Failing({"type": "diffuse"}, wi=(0.0, 0.0, 1.0)), sample_count=20_000)
    assert dr.thread_count() == before
    seen.clear()
    capped = _Capped(0.1)
    capped.pdf = lambda x: (seen.append(dr.thread_count()), _Capped.pdf(capped, x))[1]
    checks.check_mitsuba_sampler(capped, sample_count=20_000, seed=0)
    assert set(seen) == {before}
    from harness.adapters.mitsuba import emitters as em
    assert ms.area_emitter_sampler(em.sphere_light([1.0, 2.0, 3.0]), ref=(0, 0, 0)).check_threads is None


def test_the_cubature_reaches_the_plugin_as_float32_columns_or_through_a_replaced_pdf():
    """check_mitsuba_sampler integrates the plugin's pdf through float32_pdf (float32 columns,
    2^19 directions a call: pdf_batch): the same verdict and p-values, bit for bit, as through
    pdf; a subclass that replaces pdf alone (here 2 % too large) is integrated through its pdf,
    and so is an instance's own pdf, so that the fault is seen as a normalisation failure."""
    columns = []

    class Counted(ms.BSDFSampler):
        def float32_pdf(self, c):
            columns.append(c.shape[1])
            return super().float32_pdf(c)

    spec, wi = {"type": "roughconductor", "alpha": 0.3}, (0.5, 0.0, math.sqrt(0.75))
    fast = checks.check_mitsuba_sampler(Counted(spec, wi=wi), sample_count=N, seed=0)
    assert columns and max(columns) == 2**19
    s = ms.BSDFSampler(spec, wi=wi)
    with runtime.jit_threads(1):
        via_pdf = checks.check_with_missing(s.sample_with_pdf, s.pdf, s.domain, sample_count=N, seed=0,
                                            udim=s.udim)
    np.testing.assert_array_equal(fast.tests["pvalue"].to_numpy(), via_pdf.tests["pvalue"].to_numpy())
    assert fast.passed and via_pdf.passed and fast.normalization == via_pdf.normalization

    class TooLarge(ms.BSDFSampler):
        def pdf(self, x):
            return 1.02 * super().pdf(x)

    too_large = TooLarge(spec, wi=wi)
    assert float32_pdf_of(too_large) is None
    r = checks.check_mitsuba_sampler(too_large, sample_count=N, seed=0)
    assert not r.passed and abs(r.normalization[0] - 1.02 * fast.normalization[0]) < 1e-3
    own = ms.BSDFSampler(spec, wi=wi)
    own.pdf = lambda x: 1.02 * ms.BSDFSampler.pdf(own, x)
    assert float32_pdf_of(own) is None
    # a mutant takes its pdf_from's float32_pdf only where that is pdf_from's pdf
    mutant = faults.Mutant(s, "2 % too large", pdf_scale=1.02)
    x = s.sample(np.random.default_rng(0).random((1000, s.udim)))
    x = x[np.isfinite(x).all(axis=1)]
    cols = np.ascontiguousarray(x.T, dtype=np.float32)
    np.testing.assert_array_equal(float32_pdf_of(mutant)(cols), mutant.pdf(cols.T.astype(float)))
    for pdf_from in (too_large, own):
        assert float32_pdf_of(faults.Mutant(s, "its pdf", pdf_from=pdf_from)) is None

    class Wrapper:   # a sampler of the user's own that forwards all but pdf
        def __init__(self, inner):
            self.inner = inner

        def __getattr__(self, name):
            return getattr(self.inner, name)

        def pdf(self, x):
            return self.inner.pdf(x)

    assert float32_pdf_of(Wrapper(s)) is None


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


def test_the_sample_calls_uniforms_are_float32_columns_below_one():
    """The uniforms a sample call takes: the first udim columns of u as float32, each rounded
    and then capped below 1 (batch.uniforms, one core pass), bit for bit numpy's minimum with
    dtype float32, from a wider, column-major u; too few columns are refused."""
    from harness.adapters.mitsuba.batch import uniforms

    cap = np.float32(1.0) - np.float32(2.0**-24)
    u = np.asfortranarray(np.random.default_rng(3).random((1001, 3)))
    u[:4, 0] = [1.0, np.nextafter(1.0, 0.0), float(cap), 0.0]
    cols = uniforms(u, 2)
    assert len(cols) == 2 and all(c.dtype == np.float32 and c.flags["C_CONTIGUOUS"] for c in cols)
    for j, c in enumerate(cols):
        want = np.minimum(u[:, j], cap, dtype=np.float32)
        np.testing.assert_array_equal(c.view(np.uint32), want.view(np.uint32))
    assert np.all(cols[0] < 1) and cols[0][0] == cap
    with pytest.raises(ValueError, match=r"shape \(N, 4\)"):
        uniforms(u, 4)


@pytest.mark.parametrize("n", [1, 1000])
def test_drjit_vectors_become_float64_rows_bit_for_bit(n):
    """A JIT vector's components are read in place where each holds N values; one with a
    literal component, a constant colour and a scalar go through drjit's own copy: every one
    the same float64 rows as numpy's cast of drjit's (channels, N) array; a mono variant's
    one-channel spectrum too."""
    from harness.adapters.mitsuba.batch import _to_numpy

    v = np.random.default_rng(4).normal(size=(3, n)).astype(np.float32)
    odd = np.array([[-0.0, np.inf, np.nan], [1e-45, -np.inf, 0.5], [np.float32(3.4e38), -1e-38, 2.0]])
    v[:, :3] = odd[:, :n]
    with runtime.using_variant("llvm_ad_mono") as mi:
        mono = mi.Spectrum(mi.Float(v[0]))
        got, want = _to_numpy(mono, n), np.asarray(mono).reshape(1, -1).T.astype(np.float64)
        assert got.shape == (n, 1)
        np.testing.assert_array_equal(got.view(np.uint64), want.view(np.uint64))
    with runtime.using_variant("llvm_ad_rgb") as mi:
        import drjit as dr

        full, partial = mi.Vector3f(*v), mi.Vector3f(mi.Float(v[0]), 1.0, mi.Float(v[2]))
        colour, scalar = mi.Color3f(0.25, 0.5, 2.0), mi.Float(v[1])
        dr.eval(full, partial, colour, scalar)
        for value in (full, partial, colour):
            want = np.broadcast_to(np.asarray(value).T.astype(np.float64), (n, 3))
            got = _to_numpy(value, n)
            assert got.shape == (n, 3) and got.dtype == np.float64
            np.testing.assert_array_equal(got.view(np.uint64), np.ascontiguousarray(want).view(np.uint64))
        if n > 1:
            assert _to_numpy(colour, n).strides[0] == 0    # a constant stays a broadcast view
        np.testing.assert_array_equal(_to_numpy(scalar, n), v[1].astype(np.float64))
        assert _to_numpy(scalar, n, widen=False).dtype == np.float32
        dynamic = dr.llvm.ad.ArrayXf(mi.Float(v[0]), mi.Float(v[2]))   # no static size: drjit's copy
        np.testing.assert_array_equal(_to_numpy(dynamic, n), v[[0, 2]].T.astype(np.float64))


def test_a_weight_check_of_a_sampler_that_produced_nothing_compares_nothing():
    """Every sample failed: the weight check calls eval and pdf on no rows and reports nothing
    produced, nothing compared (the failure count is the sampler check's to judge)."""
    import dataclasses

    s = ms.bsdf_sampler({"type": "roughconductor", "alpha": 0.1}, wi=30)
    draw = s.sample_batch
    s.sample_batch = lambda u: dataclasses.replace(draw(u), valid=np.zeros(len(u), dtype=bool))
    assert s.eval(np.zeros((0, 3))).shape == (0, 3)
    none = draw(np.zeros((0, 3)))      # a sample call on no uniforms: no rows of every output
    assert none.x.shape == (0, 3) and none.weight.shape == (0, 3) and none.valid.shape == (0,)
    r = checks.weight_consistency(s, sample_count=1000)
    assert (r.passed, r.n, r.produced, r.mismatches, r.bad_weights) == (True, 1000, 0, 0, 0)
    assert r.max_rel_error == 0.0 and r.max_pdf_rel_error == 0.0 and not r.examples


@pytest.mark.parametrize("plugin", [{"type": "hg", "g": 0.3}, {"type": "rayleigh"}], ids=lambda p: p["type"])
def test_a_constant_weight_decides_validity_by_its_one_row(plugin):
    """A phase function's weight is one constant, kept a read-only broadcast view: its one row
    says whether the samples are in the density, as every row of it would."""
    from harness.adapters.mitsuba.phase import phase_sampler

    s = phase_sampler(plugin, wi=30)
    b = s.sample_batch(np.random.default_rng(2).random((4096, s.udim)))
    assert b.weight.strides[0] == 0
    want = np.all(np.isfinite(b.x), axis=1) & (b.sample_pdf > 0) & np.any(np.asarray(b.weight) != 0, axis=1)
    np.testing.assert_array_equal(b.valid, want)
    assert b.valid.all()


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
    ({"plugin": {"type": "diffuse"}, "texel_breaks": True}, "'texel_breaks': .* for an envmap only"),
    ({"plugin": {"type": "diffuse"}, "texel_breaks": False}, "'texel_breaks': .* for an envmap only"),
    ({"plugin": {"type": "envmap"}, "texel_breaks": "yes"}, "'texel_breaks': true or false"),
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
    # the environment map fails on the sun's rim, float32 in Mitsuba: its weights differ from
    # eval/pdf, and the pdf sample_direction reports from pdf_direction (the reported-pdf
    # check, deterministic, part of the chi_square measurement); the histogram tests pass
    assert verdicts[2]["chi_square"] == "failed" and verdicts[2]["weight"] == "failed"
    c = summary["sampler"].results[2].checks["chi_square"]
    assert [f["check"] for f in c["failures"]] == ["reported_pdf"] and c["failures"][0]["examples"]
    assert min(t["adjusted"] for t in c["tests"]) > 0.01
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
    ('plugin = { type = "diffuse" }\ntexel_breaks = true', "texel_breaks"),
])
def test_suite_sampler_table_errors_name_the_key(tmp_path, body, key):
    from harness.suite.parse import SuiteError, load_suite

    path = tmp_path / "bad.toml"
    path.write_text(f'[[sampler]]\nadapter = "mitsuba"\n{body}\n')
    with pytest.raises(SuiteError, match=rf"bad\.toml:\d+: {key}: "):
        load_suite(path)


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


# --- composite and layered BSDFs ------------------------------------------------------------------
def test_mask_pass_through_is_missing_mass_and_the_rest_passes():
    s = ms.bsdf_sampler(cat.MASK, wi=45)
    assert s.delta_lobes and s.domain == "hemisphere"
    b = s.sample_batch(np.random.default_rng(0).random((20_000, 3)))
    assert 0.67 < b.delta.mean() < 0.73 and not np.any(b.valid & b.delta)
    np.testing.assert_allclose(b.x[b.delta], np.tile([-s.wi[0], -s.wi[1], -s.wi[2]], (b.delta.sum(), 1)),
                               atol=1e-6)   # the pass-through: wo = -wi, no density
    r = checks.check_mitsuba_sampler(s, sample_count=N, seed=0, alpha=ALPHA)
    assert r.passed, str(r)
    assert r.normalization[0] == pytest.approx(0.3, abs=1e-6)
    w = checks.weight_consistency(s, sample_count=20_000, seed=0)
    assert w.passed and w.max_pdf_rel_error == 0 and 0.67 * 20_000 < w.delta < 0.73 * 20_000


def test_twosided_is_lit_from_below():
    s = ms.bsdf_sampler({"type": "twosided", "bsdf": {"type": "roughconductor", "alpha": 0.2}}, wi=135)
    assert s.domain == "sphere" and s.wi[2] < 0
    x = s.sample(np.random.default_rng(4).random((5000, 3)))
    ok = np.all(np.isfinite(x), axis=1)
    assert ok.mean() > 0.95 and np.all(x[ok, 2] < 0)
    with pytest.raises(ValueError, match="one-sided"):
        ms.bsdf_sampler({"type": "roughconductor"}, wi=135)


# --- phase functions ---------------------------------------------------------------------------------
def test_phase_function_conventions():
    u = np.random.default_rng(5).random((50_000, 3))
    for g in (-0.7, 0.3, 0.9):
        s = ms.phase_sampler({"type": "hg", "g": g}, wi=60)
        x = s.sample(u)
        assert s.domain == "sphere" and np.all(np.isfinite(x))
        assert np.mean(x @ np.array(s.wi)) == pytest.approx(-g, abs=0.01)   # E<wo, wi> = -g
        np.testing.assert_allclose(s.eval(x)[:, 0], s.pdf(x), rtol=1e-5)   # HG: value = pdf, weight 1
    with pytest.raises(ValueError, match="'wi' as an angle"):
        ms.phase_sampler({"type": "hg"}, wi=200)
    with pytest.raises(ValueError, match="not a phase function"):
        ms.phase_sampler({"type": "diffuse"})


# --- emitters on shapes -------------------------------------------------------------------------------
def test_area_light_pdf_is_zero_off_the_shape_and_solid_angle_on_it():
    from harness.adapters.mitsuba import emitters as em

    s = ms.area_emitter_sampler(em.sphere_light([1.0, 2.0, 3.0]), ref=(0, 0, 0), mapping=None)
    assert s.domain == "sphere"
    c = np.array([1.0, 0.6, 1.6])
    d = c / np.linalg.norm(c)
    cos_cone = math.sqrt(1 - (0.5 / np.linalg.norm(c)) ** 2)
    # Mitsuba samples the cone a sphere subtends uniformly: pdf 1 / (2 pi (1 - cos))
    assert s.pdf(d[None])[0] == pytest.approx(1 / (2 * math.pi * (1 - cos_cone)), rel=1e-4)
    assert s.pdf(np.array([[0.0, 0.0, -1.0], [-d[0], -d[1], -d[2]]])).tolist() == [0.0, 0.0]
    np.testing.assert_allclose(s.eval(d[None]), [[1.0, 2.0, 3.0]], rtol=1e-6)
    assert s.eval(np.array([[0.0, 0.0, -1.0]])).tolist() == [[0.0, 0.0, 0.0]]
    x = s.sample(np.random.default_rng(6).random((5000, 2)))
    assert np.all(x @ d >= cos_cone - 1e-5)


def test_area_light_in_the_equal_area_map_of_its_cap():
    # the sphere's cone maps onto the hemisphere; the uniform cone density becomes 1 / (2 pi)
    from harness.adapters.mitsuba import emitters as em
    from harness.adapters.mitsuba.cap import Cap, CapView

    s = ms.area_emitter_sampler(em.sphere_light([1.0, 2.0, 3.0]), ref=(0, 0, 0))
    assert s.domain == "sphere" and isinstance(s.mapping, Cap)
    view = s.mapping.view(s)
    assert isinstance(view, CapView)
    u = np.random.default_rng(8).random((5000, 2))
    h = view.sample(u)
    assert view.domain == "hemisphere" and np.all(h[:, 2] >= 0)
    np.testing.assert_allclose(s.mapping.to_world(h), s.sample(u), atol=1e-7)
    np.testing.assert_allclose(view.pdf(h), 1 / (2 * math.pi), rtol=1e-4)
    # a point of the draw is evaluated at the float32 direction Mitsuba returned, exactly, the
    # density in float32 (the world pdf's precision): the whole draw, or a few of its rows
    world = s.sample(u)

    def expected(w):
        return (s.pdf(w).astype(np.float32) * np.float32(s.mapping.scale)).astype(float)

    np.testing.assert_array_equal(view.pdf(h), expected(world))
    np.testing.assert_array_equal(view.pdf(h[:10]), expected(world[:10]))
    assert view.pdf(np.array([[0.0, 0.0, -1.0]])).tolist() == [0.0]    # below the horizon: outside the cap
    # the cubature's nodes as the float32 renderer takes them: pdf's densities, bit for bit, in
    # the core's interleaved order; up to 4096 nodes declined (pdf looks them up in the draw)
    rng = np.random.default_rng(9)
    lo = rng.random((700, 2)) * 0.9
    hi = lo + 0.05
    nodes = (np.polynomial.legendre.leggauss(4)[0] + 1) / 2
    columns, ok = view.float32_directions(lo, hi, nodes)
    density = view.float32_density(columns)
    assert ok.all() and density.dtype == np.float32
    want = view.pdf(rest.cubature_points("hemisphere", lo, hi, nodes))
    np.testing.assert_array_equal(density.astype(float), want[rest.interleaved_order(700, 16)])
    assert view.float32_directions(lo[:256], hi[:256], nodes) is None


def test_rectangle_light_in_its_own_square():
    """A rectangle of constant radiance is sampled uniformly by area: in its own square the
    density is 1; the draw maps back to the directions returned; the pdf at the draw's points is
    the world pdf at those very directions times the map's Jacobian, both in float32."""
    from harness.adapters.mitsuba import emitters as em
    from harness.adapters.mitsuba.rectangle import Rectangle
    from harness.adapters.mitsuba.views import MappedView

    s = ms.area_emitter_sampler(em.rectangle_light([1.0, 2.0, 3.0]), ref=cat.REFS[1])
    assert isinstance(s.mapping, Rectangle) and s.mapping.breaks is None
    view = s.mapping.view(s)
    assert type(view) is MappedView and view.domain == "square" and view.breaks is None
    u = np.random.default_rng(12).random((20_000, 2))
    x = view.sample(u)
    world = s.sample(u)
    assert np.all((x >= 0) & (x <= 1))
    np.testing.assert_allclose(s.mapping.to_world(x), world, atol=1e-6)
    np.testing.assert_allclose(view.pdf(x), 1.0, rtol=1e-4)
    want = s.mapping.density(x, s.pdf(world))
    np.testing.assert_array_equal(view.pdf(x), want)
    np.testing.assert_array_equal(view.pdf(x[:10]), want[:10])
    assert view.pdf(np.array([[1.5, 0.5], [0.5, -0.1]])).tolist() == [0.0, 0.0]   # off the light
    assert s.mapping.to_domain(np.array([[0.0, 0.0, -1.0]])).tolist() == [[-1.0, -1.0]]   # misses the plane
    # the check's reported-pdf check reads the pdfs of the one draw: a single sample call
    calls = []
    batch = s.sample_batch
    s.sample_batch = lambda u: (calls.append(len(u)), batch(u))[1]
    r = checks.check_mitsuba_sampler(s, sample_count=N, seed=0)
    assert calls == [N] and r.passed


def test_a_rectangle_far_from_the_origin_keeps_its_edge_samples_on_the_square():
    """Mitsuba holds the light's transform and the reference point in float32: a light 100 units
    from the origin sits up to 2e-6 of a side off the float64 one.  The square is built from
    them rounded as Mitsuba rounds them, and its slack covers the sampled points' own rounding:
    samples drawn at the edges all land on the square.  At 1000 units that rounding could pass
    1e-4 of a side: the light is tested in its cap."""
    from harness.adapters.mitsuba import emitters as em
    from harness.adapters.mitsuba.cap import Cap
    from harness.adapters.mitsuba.rectangle import Rectangle

    far = ms.area_emitter_sampler(em.rectangle_light(1.0, center=(1e3, 1e3, 1.0)), ref=(1e3, 1e3, 0.05))
    assert isinstance(far.mapping, Cap)
    for at in (0.0, 100.0):
        light = em.rectangle_light(1.0, center=(at, at, 1.0))
        s = ms.area_emitter_sampler(light, ref=(at + 0.1, at + 0.2, 0.05))
        assert isinstance(s.mapping, Rectangle)
        u = np.random.default_rng(13).random((40_000, 2))
        u[:, 0] = np.where(u[:, 0] < 0.5, 1e-7 * u[:, 0], 1 - 1e-7 * u[:, 0])   # on the edges s0 = 0, 1
        x = s.mapping.to_domain(s.sample(u))
        produced = np.isfinite(x).all(axis=1)
        assert produced.mean() > 0.99 and np.all((x[produced] >= 0) & (x[produced] <= 1)), at


def test_an_area_lights_reported_pdf_check_reads_the_checks_own_draw():
    """check_mitsuba_sampler's reported-pdf check on a light reads the pdfs its one draw
    reported and the world pdf the check asked there, samples not produced (NaN rows) among
    them: a planted per-area density fails at the produced samples (but where dist^3 / height
    is near 1, as reported_pdf_failure on a second draw of the same uniforms finds), the
    examples' u the draw's."""
    import dataclasses

    from harness.adapters.mitsuba import emitters as em
    from harness.samplers.check import SAMPLE_CASE
    from harness.samplers.reported import reported_pdf_failure

    class EveryTenthFails(faults.Mutant):
        def sample_batch(self, u):
            b = super().sample_batch(u)
            valid = b.valid.copy()
            valid[::10] = False
            return dataclasses.replace(b, valid=valid)

    base = ms.area_emitter_sampler(em.rectangle_light([1.0, 2.0, 3.0]), ref=cat.REFS[1])
    mutant = EveryTenthFails(base, "area", reported_fault=faults.area_density_reported)
    calls = []
    batch = base.sample_batch
    base.sample_batch = lambda u: (calls.append(len(u)), batch(u))[1]
    r = checks.check_mitsuba_sampler(mutant, sample_count=N, seed=0)
    assert calls == [N]
    f = {x.check: x for x in r.failures}["reported_pdf"]
    u = rest.points(N, 2, seed=0, case_id=SAMPLE_CASE)
    again = reported_pdf_failure(*mutant.sample_with_pdf(u), mutant.pdf)
    assert f.count == again.count > 0.999 * (N - N // 10) and f.detail == again.detail
    assert [ex["index"] for ex in f.examples] == [ex["index"] for ex in again.examples]
    assert all(ex["index"] % 10 and ex["u"] == u[ex["index"]].tolist() for ex in f.examples)


def test_area_lights_choose_their_map():
    """A nearest-filtered bitmap on a rectangle: its square, the texel lines and centres as
    breaks; a bilinear one: the cap (its float32 pdf's noise makes the square's tables dear);
    a sphere: its cone; a point in the rectangle's plane (and its box): none."""
    from harness.adapters.mitsuba import emitters as em
    from harness.adapters.mitsuba.cap import Cap
    from harness.adapters.mitsuba.rectangle import Rectangle

    def light(filt):
        return em.rectangle_light({"type": "bitmap", "bitmap": em.light_bitmap(), "filter_type": filt})

    nearest = ms.area_emitter_sampler(light("nearest"), ref=cat.REFS[0])
    assert isinstance(nearest.mapping, Rectangle) and nearest.mapping.texels == (32, 16)
    b0, b1 = nearest.mapping.breaks
    np.testing.assert_array_equal(b0, np.sort(np.r_[np.arange(1, 32) / 32, (np.arange(32) + 0.5) / 32]))
    assert b1.size == 31 and b1[0] == 0.5 / 16
    assert isinstance(ms.area_emitter_sampler(light("bilinear"), ref=cat.REFS[0]).mapping, Cap)
    assert isinstance(ms.area_emitter_sampler(em.sphere_light(1.0), ref=cat.REFS[0]).mapping, Cap)
    assert ms.area_emitter_sampler(em.rectangle_light(1.0), ref=(0.2, 0.3, 1.0)).mapping is None
    checker = em.rectangle_light({"type": "checkerboard"})       # a texture whose grid is unknown
    assert isinstance(ms.area_emitter_sampler(checker, ref=cat.REFS[0]).mapping, Cap)
    # a Mitsuba transform as the shape's to_world: its matrix
    with runtime.using_variant("llvm_ad_rgb") as mi:
        moved = {**em.rectangle_light(1.0), "to_world": mi.ScalarTransform4f().translate([0.5, 0.0, 2.0])}
    rect = ms.area_emitter_sampler(moved, ref=cat.REFS[0]).mapping
    assert isinstance(rect, Rectangle)
    np.testing.assert_allclose(rect.corner, [-0.5, -1.0, 2.0])
    assert rect.height == pytest.approx(2.0)
    # seen at a grazing rise (0.25 % over 20 units, 10 sides) a sample's float32 rounding could
    # land 1e-3 of a side off the square: the cap; from the catalogue's points the slack is 1e-6
    assert isinstance(ms.area_emitter_sampler(em.rectangle_light(1.0), ref=(20, 0, 0.95)).mapping, Cap)
    assert 1e-6 <= ms.area_emitter_sampler(em.rectangle_light(1.0), ref=cat.REFS[1]).mapping.slack < 1.1e-6
    with runtime.using_variant("llvm_ad_rgb") as mi:   # a bitmap moved in uv: its grid unknown here
        shifted = {"type": "bitmap", "bitmap": em.light_bitmap(), "filter_type": "nearest",
                   "to_uv": mi.ScalarTransform4f().scale([2.0, 2.0, 1.0])}
    assert isinstance(ms.area_emitter_sampler(em.rectangle_light(shifted), ref=cat.REFS[0]).mapping, Cap)
    with pytest.raises(ValueError, match="'mapping' must be"):
        ms.area_emitter_sampler(em.rectangle_light(1.0), mapping="cap")
    with pytest.raises(ValueError, match="edge-on"):
        Rectangle((0, 0, 1), (-1, -1, 1), (2, 0, 0), (0, 2, 0))


def test_an_area_lights_check_is_the_same_bits_through_its_float32_directions(monkeypatch):
    """An area light's tables take their nodes' world directions as float32 columns
    (CapView.float32_directions): the check's p-values are those of the float64 path, bit for
    bit.  (A bilinear bitmap on a rectangle: tested in its cap's map, see _auto_mapping.)"""
    from harness.adapters.mitsuba import emitters as em
    from harness.adapters.mitsuba.cap import Cap, CapView

    light = em.rectangle_light({"type": "bitmap", "bitmap": em.light_bitmap(), "filter_type": "bilinear"})
    s = ms.area_emitter_sampler(light, ref=(0.6, -0.4, 0.3))
    assert isinstance(s.mapping, Cap)
    fast = checks.check_mitsuba_sampler(s, sample_count=N, seed=0)
    monkeypatch.setattr(CapView, "float32_directions", lambda self, lo, hi, nodes: None)
    slow = checks.check_mitsuba_sampler(s, sample_count=N, seed=0)
    np.testing.assert_array_equal(fast.tests["pvalue"].to_numpy(), slow.tests["pvalue"].to_numpy())
    assert fast.passed == slow.passed and fast.normalization == slow.normalization


def test_area_light_rectangle_bitmap_reports_its_pdf_and_weight():
    # the deterministic checks (its chi-square: the benchmark)
    from harness.adapters.mitsuba import emitters as em
    from harness.samplers.reported import reported_pdf_failure

    for filt in ("nearest", "bilinear"):
        light = em.rectangle_light({"type": "bitmap", "bitmap": em.light_bitmap(), "filter_type": filt})
        s = ms.area_emitter_sampler(light, ref=cat.REFS[1])
        assert s.domain == "sphere" and s.mapping is not None
        u = np.random.default_rng(11).random((20_000, 2))
        assert reported_pdf_failure(*s.sample_with_pdf(u), s.pdf) is None
        assert checks.weight_consistency(s, sample_count=20_000, seed=0).passed


@pytest.mark.parametrize("spec, match", [
    ({"plugin": {"type": "spot", "cutoff_angle": 20}}, "Dirac delta in position"),
    ({"plugin": {"type": "point"}}, "Dirac delta in position"),
    ({"plugin": {"type": "rectangle"}}, "needs an 'emitter'"),
    ({"plugin": {"type": "sphere", "emitter": {"type": "area"}}, "ref": [0, 0]}, "'ref' must be"),
    ({"plugin": {"type": "diffuse"}, "ref": [0, 0, 0]}, "'ref': only emitters on shapes"),
    ({"plugin": {"type": "mask", "bsdf": {"type": "conductor"}}}, "only Dirac delta lobes"),
])
def test_untestable_and_malformed_plugins_are_refused_by_name(spec, match):
    with pytest.raises(ValueError, match=match):
        ms.make_sampler(spec)


def test_make_sampler_builds_phase_functions_and_area_lights():
    p = ms.make_sampler({"plugin": {"type": "hg", "g": 0.5}, "wi": 120})
    assert isinstance(p, ms.PhaseSampler) and p.domain == "sphere" and p.udim == 3
    a = ms.make_sampler({"plugin": {"type": "rectangle", "emitter": {"type": "area", "radiance": 2.0},
                                    "to_world": [[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 1], [0, 0, 0, 1]]},
                         "ref": [0, 0, 0]})
    assert isinstance(a, ms.AreaEmitterSampler) and a.udim == 2 and a.domain == "sphere"
    # a rectangle of constant radiance is tested in its own square
    np.testing.assert_allclose(a.mapping.normal, [0, 0, -1], atol=1e-12)
    assert a.mapping.height == pytest.approx(-1.0) and a.mapping.texels is None
    # dist^2 / (area cos) per steradian: a 2 x 2 square at distance 1, head on
    assert a.pdf(np.array([[0.0, 0.0, 1.0]]))[0] == pytest.approx(1 / 4, rel=1e-5)
    fp = a.fingerprint()
    assert fp["ref"] == [0.0, 0.0, 0.0] and fp["plugin"]["to_world"][2] == [0, 0, -1, 1]


def test_cap_map_is_an_equal_area_bijection():
    from harness.adapters.mitsuba.cap import Cap, box_cap

    cap = Cap([0.3, -0.2, 1.0], 0.8)
    rng = np.random.default_rng(9)
    h = rng.normal(size=(10_000, 3))
    h[:, 2] = np.abs(h[:, 2])
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    w = cap.to_world(h)
    assert np.all(w @ cap.axis >= 0.8 - 1e-12)
    np.testing.assert_allclose(cap.to_hemisphere(w), h, atol=1e-9)
    # uniform on the hemisphere <-> uniform on the cap: z' is uniform, so is <d, axis>
    assert abs(np.mean(w @ cap.axis) - 0.9) < 0.005
    assert box_cap((0, 0, 0), (-1, -1, 1), (1, 1, 1)).cos_alpha == pytest.approx(1 / math.sqrt(3), abs=1e-5)
    assert box_cap((0, 0, 1), (-1, -1, 1), (1, 1, 1)) is None      # the point is in the box
    with pytest.raises(ValueError, match="'cos_alpha'"):
        Cap([0, 0, 1], 1.0)


# --- the catalogue: every kind of sampler and planted fault ----------------------------------------
# A representative subset (each kind of plugin, grazing incidence, lit from below, a light seen
# obliquely) through all three checks at 1e5 samples, the chi-square's alpha Bonferroni-split so
# that the subset as a family keeps ALPHA; the whole catalogue (every plugin at every incident
# angle, every planted fault) runs in benchmarks/mitsuba_samplers.py at 1e6.  A plugin with a
# documented Mitsuba finding must fail exactly the checks its catalogue entry names.
SUBSET = [
    "diffuse θi=45°",
    "roughconductor ggx α=0.1 visible=True θi=80°",
    "roughdielectric ggx α=0.5 ior=1.5 θi=45°",
    "twosided (roughconductor ggx α=0.1) θi=135°",
    "blendbsdf weight=0.3 (diffuse, roughconductor ggx α=0.1) θi=45°",
    "mask opacity=0.3 (diffuse) θi=80°",
    "principled roughness=0.3 spec_trans=0.5 θi=135°",
    "plastic θi=80°",
    "roughplastic beckmann α=0.3 θi=80°",
    "microfacet ggx α=0.5 visible θi=80°",
    "hg g=-0.7 θi=0°",
    "rayleigh θi=60°",
    "blendphase weight=0.3 (hg g=0.9, hg g=-0.7) θi=60°",
    "area sphere constant from (0.6, -0.4, 0.3)",
]
# (the envmap's three checks run in test_suite_sampler_tables_run_mitsuba_checks)


def _entries(labels, entries):
    by_label = {e.label: e for e in entries}
    return [by_label[label] for label in labels]


@pytest.mark.slow
@pytest.mark.parametrize("entry", _entries(SUBSET, cat.catalogue()), ids=lambda e: e.label)
def test_catalogue_plugin_passes_or_fails_as_documented(entry):
    s = entry.make()
    r = checks.check_mitsuba_sampler(s, sample_count=N, seed=0, alpha=ALPHA / len(SUBSET))
    w = checks.weight_consistency(s, sample_count=N, seed=0)
    reported = any(f.check == "reported_pdf" for f in r.failures)
    chi2 = r.pvalue <= r.alpha or any(f.check != "reported_pdf" for f in r.failures)
    verdicts = {"chi2": chi2, "reported": reported, "weight": not w.passed}
    failing = {c for c, failed in verdicts.items() if failed}
    why = entry.finding or "documented to pass"
    assert entry.documented(failing, N), f"{entry.label}: {failing} {why}\n{r}\n{w}"


def _fault_entries(check):
    return [e for e in cat.wrong_catalogue() if e.fails == (check,)]


# pdf faults are the chi-square's: a subset here (each costs the pdf's cubature), all in the benchmark
PDF_FAULTS = [
    "diffuse, pdf × 0.995 θi=45°",
    "roughconductor ggx samples α=0.11, pdf α=0.1 θi=45°",
    "mask opacity=0.3 (diffuse), pdf() without the opacity θi=45°",
]


@pytest.mark.slow
@pytest.mark.parametrize("entry", _entries(PDF_FAULTS, _fault_entries("chi2")), ids=lambda e: e.label)
def test_planted_pdf_fault_is_caught_by_the_chi_square(entry):
    r = checks.check_mitsuba_sampler(entry.make(), sample_count=N, seed=0, alpha=ALPHA)
    assert not r.passed and not any(f.check == "reported_pdf" for f in r.failures), str(r)


@pytest.mark.parametrize("entry", _fault_entries("weight"), ids=lambda e: e.label)
def test_planted_weight_fault_is_caught_by_the_weight_check(entry):
    w = checks.weight_consistency(entry.make(), sample_count=20_000, seed=0)
    assert not w.passed and w.mismatches > 0.9 * w.produced, str(w)


@pytest.mark.parametrize("entry", _fault_entries("reported"), ids=lambda e: e.label)
def test_planted_reported_pdf_fault_is_caught_by_the_reported_pdf_check(entry):
    # check_mitsuba_sampler's reported-pdf check, without the chi-square's cubature
    from harness.samplers.reported import reported_pdf_failure

    s = entry.make()
    x, reported = s.sample_with_pdf(np.random.default_rng(12).random((20_000, s.udim)))
    f = reported_pdf_failure(x, reported, s.pdf)
    produced = int(np.all(np.isfinite(x), axis=1).sum())
    assert f is not None and f.count > 0.9 * produced, f"{entry.label}: {f}"


def test_the_catalogue_lists_every_kind_and_documents_its_findings():
    real, wrong = cat.catalogue(), cat.wrong_catalogue()
    kinds = {"diffuse", "roughconductor", "roughdielectric", "roughplastic", "mask", "twosided", "blendbsdf",
             "principled", "plastic", "microfacet", "phase", "envmap", "emitter"}
    assert {e.group for e in real} >= kinds
    assert {e.fails for e in wrong} == {("chi2",), ("weight",), ("reported",)}
    assert all(e.finding for e in real if e.fails) and all(set(e.fails) <= set(cat.CHECKS) for e in real)
    assert all(e.finding and set(e.may_fail) <= set(cat.CHECKS) - set(e.fails) for e in real if e.may_fail)
    assert set(cat.CHANCE) <= {e.label for e in real}
    rim = next(e for e in real if e.label == "area sphere constant from (0, 0, 0)")
    assert (rim.fails, rim.may_fail, rim.fails_from) == (("weight",), ("chi2",), 1_000_000)
    assert rim.documented({"weight"}, 10**6) and rim.documented({"weight", "chi2"}, 10**6)
    assert not any(rim.documented(f, 10**6) for f in ({"chi2"}, set(), {"weight", "reported"}))
    assert rim.documented(set(), 10**5) and not rim.documented({"chi2"}, 10**5)
    assert set(cat.FINDINGS) <= {e.label for e in real}
    assert len({e.label for e in real + wrong}) == len(real) + len(wrong)
