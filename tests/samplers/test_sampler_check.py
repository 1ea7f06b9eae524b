"""check_sampler: false alarms and power on the sampler zoo, the
deterministic checks, and the command line."""
from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

import reference_estimators as rest

from harness.samplers import Domain, SamplerTest, as_domain, check_sampler, zoo
from harness.samplers.domains import ParamDensity
from harness.samplers.reported import reported_pdf_failure
from harness.stats import ConfidenceInterval, Failure
from harness.usercode import UserCodeError

# the zoo by name: the tests build the samplers they use, so that no parameter of a test holds
# a core sampler (pytest keeps deselected tests' parameters to the end of the process, past the
# core's teardown, where nanobind reports them as leaked)
CORRECT = [z.name for z in zoo.correct()]
WRONG = [z.name for z in zoo.wrong()]


def correct(name: str) -> zoo.ZooSampler:
    return next(z for z in zoo.correct() if z.name == name)


def wrong(name: str) -> zoo.ZooSampler:
    return next(z for z in zoo.wrong() if z.name == name)


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


def test_domains_by_name():
    assert as_domain("disk") == Domain("disk")
    assert as_domain(("interval", -1, 2)) == Domain("interval", -1.0, 2.0)
    d = Domain("hemisphere")
    s = np.array([[0.3, 0.2], [0.9, 0.7]])
    back, inside = d.to_params(d.to_points(s))
    np.testing.assert_allclose(back, s)
    assert inside.all()


@pytest.mark.parametrize("domain", [("interval", -1, 2), "half_line", "square", "disk", "hemisphere",
                                    "sphere"])
def test_a_density_integrates_itself_as_the_rule_on_its_values_at_the_nodes(domain):
    """ParamDensity.rule_integrals (the core maps the rule's nodes to domain points directly,
    a constant Jacobian multiplies each box's sum) gives the tensor rule on q(s) = pdf(x(s))
    |dx/ds| at the nodes, to rounding, columns included; on the half line its Jacobian
    (1 + x)^2 is 1 / (1 - s)^2 to rounding."""
    dom = as_domain(domain)
    rng = np.random.default_rng(8)
    lo = rng.random((300, dom.k)) * 0.9
    hi = lo + 0.05
    nodes = np.array([0.1, 0.5, 0.8])
    w1 = np.array([0.3, 0.5, 0.2])
    weights = w1 if dom.k == 1 else np.outer(w1, w1).reshape(-1)

    def pdf(x):
        return 1.0 + np.sum(np.reshape(x, (x.shape[0], -1)) ** 2, axis=1)

    s = rest.cubature_nodes(lo, hi, nodes)
    q = pdf(dom.to_points(s)) * dom.jacobian(s)
    squares = (lambda v: np.column_stack([v, v * v]), np.column_stack([q, q * q]))
    for columns, ref in [(None, q[:, None]), squares]:
        density = ParamDensity(dom, pdf, columns)
        want = rest.cubature_sums(lo, hi, ref, weights)
        np.testing.assert_allclose(density.rule_integrals(lo, hi, nodes, weights), want, rtol=4e-15)
        np.testing.assert_allclose(density(s), ref[:, 0] if columns is None else ref, rtol=4e-15)


@pytest.mark.parametrize("kwargs, error, message", [
    ({"domain": "cube"}, ValueError,
     r"'domain' must be one of \('interval', 'half_line', 'square', 'disk', 'hemisphere', 'sphere'\)"),
    ({"domain": ("interval", 2, 1)}, ValueError, r"\('interval', a, b\) with a < b"),
    ({"sample_count": 10}, ValueError, r"'sample_count' must be at least 1000, got 10"),
    ({"alpha": 0.0}, ValueError, r"'alpha' must be in \(0, 1\)"),
])
def test_bad_arguments(kwargs, error, message):
    s = correct(CORRECT[0])
    args = {"domain": s.domain, **kwargs}
    with pytest.raises(error, match=message):
        check_sampler(s.sample, s.pdf, **args)


def test_wrong_point_shapes_are_named():
    with pytest.raises(ValueError,
                       match=r"<lambda> returned points of shape \(5000, 2\) for uniforms of shape "
                             r"\(5000, 2\); expected shape \(5000, 3\) on the hemisphere"):
        check_sampler(lambda u: u, lambda x: np.ones(len(x)), "hemisphere", sample_count=5000)


def test_cli_check_sampler(tmp_path):
    mod = tmp_path / "my_sampler.py"
    mod.write_text("import numpy as np, math\n"
                   "import reference_estimators as rest\n"
                   "_s = rest.sampler('ggx', alpha=0.1)\n"
                   "def good():\n    return (lambda u: _s.sample(u)[0], _s.pdf, 'hemisphere')\n"
                   "def bad():\n"
                   "    return (lambda u: _s.sample(u)[0], lambda w: 1.01 * _s.pdf(w), 'hemisphere')\n"
                   "class Turned:\n"   # GGX about +y, on the sphere with its pole at +y
                   "    domain, pole = 'sphere', 'y'\n"
                   "    def sample(self, u):\n        return _s.sample(u)[0][:, [1, 2, 0]]\n"
                   "    def pdf(self, w):\n        return _s.pdf(w[:, [2, 0, 1]])\n"
                   "class BadBreaks(Turned):\n    breaks = ([2.0], None)\n")
    (tmp_path / "raises.py").write_text("raise RuntimeError('no GPU here')\n")
    harness = str(Path(sys.executable).with_name("harness"))

    def run(*args: str) -> subprocess.CompletedProcess:  # as a user runs it: in the repository, no PYTHONPATH
        return subprocess.run([harness, "check-sampler", *args], capture_output=True, text=True, cwd=tmp_path,
                              timeout=300)

    for target in ("my_sampler:good", "./my_sampler.py:good"):
        r = run(target, "--samples", "200000")
        assert r.returncode == 0 and "PASSED" in r.stdout, r.stdout + r.stderr
        assert "summary: 1 passed, 0 failed" in r.stdout, r.stdout + r.stderr
    r = run("my_sampler:bad", "--samples", "200000")
    assert r.returncode == 1 and "normalization" in r.stdout and "1.010000" in r.stdout
    r = run("my_sampler:Turned", "--samples", "200000")
    assert r.returncode == 0 and "PASSED" in r.stdout, r.stdout + r.stderr
    r = run("my_sampler:BadBreaks", "--samples", "200000")
    assert r.returncode == 2 and "harness: 'breaks'[0]: 1 of 1 coordinates are not finite numbers in [0, 1]" \
        in r.stderr and "Traceback" not in r.stderr, r.stderr
    for target, said in [("my_sampler:nope", "'my_sampler:nope': my_sampler has no attribute 'nope'"),
                         ("nothere:good", "'nothere:good': cannot import 'nothere'"),
                         ("./nothere.py:good", "'./nothere.py:good': no file"),
                         ("raises:good",
                          "'raises:good': importing 'raises' raised RuntimeError: no GPU here"),
                         ("my_sampler", "'my_sampler': expected module:attribute")]:
        r = run(target)
        assert r.returncode == 2 and f"harness: cannot load {said}" in r.stderr, r.stderr
        assert "Traceback" not in r.stderr


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


# --- the cubature ------------------------------------------------------------------------------
@pytest.mark.parametrize("a", [0.5, 0.75, 0.9])
@pytest.mark.parametrize("depth", [3, 6, 24])
def test_the_cubature_error_bounds_a_singularity_it_stops_short_of(a, depth):
    """x^-a y on 4 x 4 cells (singular along x = 0, refined to the depth limit): every cell's
    integral is within its error bound of the exact one.  The bare change of the last split
    understates what is left at a singularity r / (1 - r) times, r = 2^(a-1) (2.4 times at
    a = 1/2, 14 at 0.9); the bound extrapolates it, and stays within 8 times the true error."""
    from harness.samplers.cubature import cell_integrals

    val, err = cell_integrals(lambda x: x[:, 0] ** -a * x[:, 1], (4, 4), 1e-14, max_depth=depth)
    x0, y0 = np.meshgrid(np.arange(4) / 4, np.arange(4) / 4, indexing="ij")
    exact = (((x0 + 0.25) ** (1 - a) - x0 ** (1 - a)) / (1 - a) * ((y0 + 0.25) ** 2 - y0**2) / 2).reshape(-1)
    miss = np.abs(val[:, 0] - exact)
    assert np.all(miss <= err[:, 0]), (miss, err[:, 0])
    singular = slice(0, 4)   # the cells along x = 0
    assert np.all(err[singular, 0] <= 8 * miss[singular]), (miss[singular], err[singular, 0])


# --- a float32 pdf ----------------------------------------------------------------------------
def test_a_float32_pdf_is_integrated_to_its_rounding_not_chased_below_it():
    """A float32 renderer's pdf (GGX at alpha 0.01, values rounded to float32): the cubature
    stops refining where a split changes a box by less than the float32 floor, so it costs no
    more pdf calls than the float64 pdf and keeps the tabulation's error bound at the float64
    one's scale (chasing the rounding noise took 93 million calls and left a bound of 0.16:
    the transform tests without power)."""
    from harness.samplers.cubature import FLOAT32_FLOOR

    s = correct("ggx(alpha=0.01)")
    calls = {}

    def counted(f32):
        def pdf(x):
            calls[f32] = calls.get(f32, 0) + len(x)
            v = s.pdf(x)
            return v.astype(np.float32) if f32 else v
        return pdf

    t64 = SamplerTest(counted(False), s.domain, sample_count=1_000_000)
    t32 = SamplerTest(counted(True), s.domain, sample_count=1_000_000)
    assert t64.floor == 0 and t32.floor == FLOAT32_FLOOR
    assert calls[True] <= 1.1 * calls[False], calls
    assert t32.transform.error <= 0.02 / math.sqrt(1_000_000) / 2
    assert t32.check(s.sample, seed=1).passed


def test_the_rounding_floor_is_read_from_the_pdf_values():
    from harness.samplers.cubature import FLOAT32_FLOOR, rounding_floor

    v = np.random.default_rng(0).random(1000)
    assert rounding_floor(v) == 0
    assert rounding_floor(v.astype(np.float32)) == FLOAT32_FLOOR               # float32 array
    assert rounding_floor(v.astype(np.float32).astype(float)) == FLOAT32_FLOOR  # float32 values
    assert rounding_floor(np.r_[v.astype(np.float32), np.nan, np.inf, 0.0].astype(float)) == FLOAT32_FLOOR
    assert rounding_floor(np.zeros(10)) == 0 and rounding_floor(np.array([0.1])) == 0


def test_a_declared_float32_pdf_gets_the_float32_floor_where_the_pre_grid_sees_only_zeros():
    """A lobe at the pole narrower than the pre-grid's cells (kappa 1e4, evaluated in float32 as
    a renderer does: zero at every one of the 32 x 64 centres) cannot be judged float32 from its
    values there; declared (Float32DirectionPdf) it gets the float32 floor, and its cubature
    stops at its rounding where the undeclared one chased the noise of float32 z near 1: a
    tenth of the pdf calls for a table as tight and the same integral within its bound."""
    from harness.samplers import Float32DirectionPdf
    from harness.samplers.cubature import FLOAT32_FLOOR

    def lobe(x, y, z):
        k = np.float32(1e4)
        return k / np.float32(2 * math.pi) * np.exp(k * (z - np.float32(1)))

    calls = {"pdf": 0, "columns": 0}

    def pdf(x):
        calls["pdf"] += x.shape[0]
        c = x.astype(np.float32)
        return lobe(c[:, 0], c[:, 1], c[:, 2]).astype(float)

    def columns(c):
        calls["columns"] += c.shape[1]
        return lobe(c[0], c[1], c[2])

    plain = SamplerTest(pdf, "sphere", sample_count=100_000)
    plain_calls, calls["pdf"] = calls["pdf"], 0
    declared = SamplerTest(Float32DirectionPdf(pdf, columns), "sphere", sample_count=100_000)
    assert plain.floor == 0 and declared.floor == FLOAT32_FLOOR
    assert calls["pdf"] + calls["columns"] <= plain_calls / 5, (calls, plain_calls)
    assert declared.transform.error <= 1.01 * plain.transform.error
    for t in (plain, declared):
        total, err = t.normalization
        assert abs(total - 1) <= max(err, 1e-6), t.normalization


def test_a_float32_shaders_narrow_lobe_passes_its_points_dithered_within_their_rounding():
    """GGX at alpha 0.01 sampled in float32 arithmetic, as a shader does: z near 1 takes a few
    thousand float32 values across the lobe, and cells of equal claimed probability hold
    whole steps of that grid (undithered, 2 of these 3 seeds failed the equiprobable
    chi-square at p = 7e-4 and 1e-4)."""
    s = correct("ggx(alpha=0.01)")
    a = np.float32(0.01)

    def float32_ggx(u):
        u0, u1 = u[:, 0].astype(np.float32), u[:, 1].astype(np.float32)
        t2 = a * a * u0 / (np.float32(1) - u0)
        z = np.float32(1) / np.sqrt(np.float32(1) + t2)
        r, phi = np.sqrt(t2) * z, np.float32(2 * np.pi) * u1
        return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)

    t = SamplerTest(s.pdf, s.domain, sample_count=1_000_000, breaks=s.breaks)
    results = [t.check(float32_ggx, seed=seed) for seed in range(3)]
    assert all(r.passed for r in results), [str(r) for r in results]


def test_dithering_moves_float32_points_within_their_rounding_interval_only():
    from harness.samplers.check import DITHER_CASE, _float32_points

    x = np.random.default_rng(1).normal(size=(10_000, 3)).astype(np.float32).astype(float)
    x[0] = [np.nan, np.inf, 0.0]

    def dithered(points: np.ndarray, seed: int) -> np.ndarray:
        return rest.dither_float32(points, rest.points(len(points), 3, seed=seed, case_id=DITHER_CASE))

    d = dithered(x, seed=3)
    fin = np.isfinite(x)
    assert np.array_equal(d[~fin], x[~fin], equal_nan=True) and np.array_equal(d, dithered(x, seed=3),
                                                                             equal_nan=True)
    assert np.all(d[fin].astype(np.float32) == x[fin].astype(np.float32))   # rounds back to the point
    assert np.mean(d[fin] != x[fin]) > 0.99
    assert _float32_points(x) and not _float32_points(x + 1e-12) and not _float32_points(np.full(3, np.nan))


@pytest.mark.parametrize("kind", ["hemisphere", "half_line"])
def test_the_check_dithers_float32_points_with_its_own_stream(kind, monkeypatch):
    """check_points dithers float32 points with the uniforms of stream (seed, DITHER_CASE),
    on the half line as elsewhere: the stream the check's docs define, no other."""
    from harness.samplers import domains
    from harness.samplers.check import DITHER_CASE

    seen = []
    dithered = domains.Domain.dithered_params

    def spy(self, x, u=None, *, stream=None):
        seen.append((u is None, stream))
        return dithered(self, x, u, stream=stream)

    monkeypatch.setattr(domains.Domain, "dithered_params", spy)
    u = rest.points(20_000, 2, seed=1)
    if kind == "hemisphere":
        s = correct("cosine_hemisphere")
        pdf, x = s.pdf, s.sample(u)
    else:   # the exponential law on the half line
        pdf, x = (lambda t: np.exp(-t)), -np.log1p(-u[:, 0])
    x = x.astype(np.float32).astype(float)
    SamplerTest(pdf, kind, sample_count=len(x)).check_points(x, seed=5)
    assert seen == [(True, (5, DITHER_CASE))]


@pytest.mark.parametrize("domain", [Domain("interval", -1.0, 2.0), Domain("half_line"), Domain("square"),
                                    Domain("disk"), Domain("hemisphere"), Domain("sphere"),
                                    Domain("sphere", pole="y")], ids=repr)
def test_dithered_params_are_the_params_of_the_dithered_points_and_the_mask_of_the_drawn(domain):
    """The check's one pass for float32 points: the parameters of the points dithered, and
    which points as drawn lie inside (a dithered point may cross an edge the drawn one is on)."""
    rng = np.random.default_rng(4)
    n = 70_001           # more than one of the core's chunks, an odd tail
    x = {1: rng.random(n) * 3 - 1, 2: rng.random((n, 2)) * 2.2 - 1.1}.get(domain.point_dim)
    if x is None:
        x = rng.normal(size=(n, 3))
        x /= np.linalg.norm(x, axis=1)[:, None]
    x = x.astype(np.float32).astype(float)
    x[:3] = np.nan if x.ndim == 1 else [np.nan, np.inf, 0.0][: x.shape[1]]
    # points on the domain's edge, which dithering may move out: the mask is the drawn point's
    edge = {"interval": 2.0, "half_line": 0.0, "square": [1.0, 0.5], "disk": [0.6, 0.8]}.get(domain.kind)
    if edge is not None:
        x[3:6] = edge
    assert x.dtype == np.float64
    u = rng.random(x.shape)
    s, inside = domain.dithered_params(x, u)
    want_s, _ = domain.to_params(rest.dither_float32(x, u))
    _, want_inside = domain.to_params(x)
    np.testing.assert_array_equal(s.view(np.uint64), want_s.view(np.uint64))
    np.testing.assert_array_equal(inside, want_inside)
    assert 0 < inside.sum() < n
    # the uniforms of a stream, drawn inside the pass: the same bits as those points() gives
    drawn = rest.points(n, domain.point_dim, seed=7, case_id=11)
    s, inside = domain.dithered_params(x, stream=(7, 11))
    want_s, want_inside = domain.dithered_params(x, drawn.reshape(x.shape))
    np.testing.assert_array_equal(s.view(np.uint64), want_s.view(np.uint64))
    np.testing.assert_array_equal(inside, want_inside)
    with pytest.raises(ValueError, match="one of them"):
        domain.dithered_params(x)
    for bad in ((7, 11, 0), (7,), 7, (-1, 11)):
        with pytest.raises(ValueError, match="'stream' must be a pair|'seed' must be"):
            domain.dithered_params(x, stream=bad)


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
