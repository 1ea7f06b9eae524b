"""check_mitsuba_sampler's failure-aware check (failed samples against the pdf's mass), its drjit threads
and its pdf path."""
from __future__ import annotations

import math

import numpy as np
import pytest

from harness.adapters.mitsuba import checks, faults, runtime
from harness.adapters.mitsuba import samplers as ms
from harness.adapters.mitsuba.batch import float32_pdf_of
from harness.samplers import check_sampler
from harness.samplers.check import failure_pvalue
from tests.adapters.mitsuba_helpers import ALPHA, N


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
