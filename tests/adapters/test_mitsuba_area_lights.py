"""Mitsuba emitters on shapes: their pdfs, and the cap and rectangle maps they are tested in."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

import reference_estimators as rest

from harness.adapters.mitsuba import catalogue as cat
from harness.adapters.mitsuba import checks, faults, runtime
from harness.adapters.mitsuba import samplers as ms
from tests.adapters.mitsuba_helpers import N


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
    with runtime.using_variant("llvm_ad_rgb") as mi:   # one float32 ulp further: another key
        nudged = {**moved, "to_world": mi.ScalarTransform4f().translate([0.5, 0.0, 2.0000002])}
    keys = [json.dumps(ms.area_emitter_sampler(p, ref=cat.REFS[0]).fingerprint(), sort_keys=True)
            for p in (moved, nudged)]   # plain JSON: no str() of an object, whose digits are rounded
    assert keys[0] != keys[1] and '"inverse_transpose": [[1.0, 0.0, 0.0, 0.0]' in keys[0]
    with runtime.using_variant("llvm_ad_rgb") as mi:   # a bitmap: its pixels' digest and its format
        linear = mi.Bitmap(em.light_bitmap())
        srgb = mi.Bitmap(em.light_bitmap())
        srgb.set_srgb_gamma(True)
    prints = [ms.area_emitter_sampler(em.rectangle_light({"type": "bitmap", "bitmap": b}),
                                      ref=cat.REFS[0]).fingerprint() for b in (linear, srgb)]
    assert prints[0] != prints[1] and len(json.dumps(prints[0])) < 2000
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
