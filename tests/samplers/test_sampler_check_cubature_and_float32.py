"""The check's cubature (rule integrals, error bounds, the float32 rounding floor) and its dithering of
float32 points."""
from __future__ import annotations

import math

import numpy as np
import pytest

import reference_estimators as rest

from harness.samplers import Domain, SamplerTest, as_domain
from harness.samplers.domains import ParamDensity
from tests.samplers.zoo_samplers import correct


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
