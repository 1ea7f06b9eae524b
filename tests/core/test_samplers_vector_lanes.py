"""Direction, 1-D, uniform-square and MIS samplers in vector lanes: their screening, and the same bits as
one point at a time."""
from __future__ import annotations

import numpy as np
import pytest

import reference_estimators as rest


@pytest.mark.parametrize("integrand, hemisphere", [("ggx_lobe", True), ("spherical_cap", False)])
def test_directions_off_the_sphere_are_counted_in_vector_bodies_and_tails(integrand, hemisphere):
    """Membership (|w|^2 within 1e-5 of 1, z >= 0 on the hemisphere) is counted kWidth directions
    at a time: planted points in every lane position and in the tail, against numpy's count."""
    s = rest.sampler("cosine_hemisphere" if hemisphere else "uniform_sphere")
    w, p = s.sample(np.random.default_rng(5).random((1003, 2)))
    w = w.copy()
    w[[0, 5, 10, 15, 1001]] *= 1.0001                    # off by 2e-4 in |w|^2
    w[[1, 6, 11, 1002], 2] = np.nan
    w[[2, 7], :] *= 1 + 4e-6                              # within the tolerance: on the sphere
    w[[3, 8, 13], 2] = -np.abs(w[[3, 8, 13], 2]) - 1e-3   # below the horizon (renormalised)
    w[[3, 8, 13]] /= np.linalg.norm(w[[3, 8, 13]], axis=1)[:, None]
    r2 = np.sum(w * w, axis=1)
    with np.errstate(invalid="ignore"):
        on = (np.abs(r2 - 1) <= 1e-5) & ((w[:, 2] >= 0) | (not hemisphere))
    est = rest.estimate_from_samples(integrand, w, p)
    assert est.counts["outside_domain"] == int((~on).sum()) == (12 if hemisphere else 9)


@pytest.mark.parametrize("threads", [1, 2])
def test_direction_samplers_screen_their_points_in_their_own_pass(threads):
    """The direction samplers count bad pdfs and points off their domain in the vector lanes
    that draw them (Sampler::sample_valid); what they find is reported exactly as the separate
    screening of given points reports it: the same counts, the same examples."""
    s = rest.sampler("ggx", alpha=1e-155)   # alpha^2 is subnormal: D's pdf overflows at every z = 1
    n = 3 * 2048 + 5                         # whole vectors and a scalar tail
    est = rest.integrate("ggx_lobe", rest.importance(s), n, threads=threads)
    x, p = s.sample(rest.points(n, 2))
    ref = rest.estimate_from_samples("ggx_lobe", x, p, sampler=s)
    assert est.issues == ref.issues == {"bad_pdf": n}
    assert est.examples == ref.examples and est.n == 0


@pytest.mark.parametrize("kind", ["random", "sobol", "stratified"])
@pytest.mark.parametrize("n", [1, 7, 2048, 65545, 70001])
def test_an_mis_pair_of_square_samplers_is_its_samplers_and_the_balance_heuristic(n, kind):
    """The general path's MIS of the uniform square and the 2-D table sampler (which screen
    their points in the lanes that draw them; their uniforms, from random points, drawn
    straight into each one's columns, whole generator rows and one value at a time after
    them, and from Sobol' or stratified points taken out of the block's rows by shuffles):
    each contribution is f / (p_0 + p_1) at each technique's point, recomputed from the
    samplers' own batches on the point set's uniforms, bit for bit, at chunk, block, row and
    vector tails."""
    name = "mis_balance:uniform_box+piecewise_constant_2d"
    technique = rest.techniques("gaussian2d")[name]
    box, table = technique.mis
    f = rest.integrand("gaussian2d")
    u = rest.points(n, 4, kind, seed=3)
    x0, p0 = box.sample(u[:, :2])
    x1, p1 = table.sample(u[:, 2:])
    np.testing.assert_array_equal(x0, u[:, :2])   # 0 + 1 u on the unit square
    np.testing.assert_array_equal(p0, np.ones(n))
    f0, f1 = f.eval(x0), f.eval(x1)
    assert np.all(f0 > 0) and np.all(f1 > 0)
    y = (0.0 + f0 / ((0.0 + p0) + table.pdf(x0))) + f1 / ((0.0 + box.pdf(x1)) + p1)
    points = technique if kind == "random" else rest.with_points(technique, kind)
    c = rest.contributions("gaussian2d", points, n, seed=3)
    np.testing.assert_array_equal(c.view(np.uint64), y.view(np.uint64))


def test_the_uniform_square_samples_and_rates_its_points_in_vector_lanes():
    """The uniform square's batches (vector lanes, a scalar tail): lo + (hi - lo) u and pdf 1
    inside, 0 outside, at the edges, just past them, and at NaN, in any lane."""
    box = rest.techniques("gaussian2d")["mis_balance:uniform_box+piecewise_constant_2d"].mis[0]
    u = np.random.default_rng(8).random((1003, 2))
    u[:4] = [[0.0, 0.0], [1.0, 1.0], [0.0, 1.0], [np.nextafter(1.0, 0.0), 0.5]]
    x, p = box.sample(u)
    np.testing.assert_array_equal(x, u)
    np.testing.assert_array_equal(p, np.ones(len(u)))
    edges = [0.0, -0.0, 1.0, np.nextafter(0.0, -1.0), np.nextafter(1.0, 2.0), np.nan, -np.inf, np.inf, 0.5]
    pts = np.array([(a, b) for a in edges for b in edges])
    pts = np.concatenate([pts, pts[::-1][:13]])           # 94 points: whole vectors and a tail
    inside = (pts >= 0.0).all(axis=1) & (pts <= 1.0).all(axis=1)
    np.testing.assert_array_equal(box.pdf(pts), np.where(inside, 1.0, 0.0))


@pytest.mark.parametrize("name, params", [
    ("exponential", {}), ("exponential", {"rate": 7.5}), ("linear", {}), ("linear", {"a": 0.0, "b": 1.0}),
    ("power", {}), ("power", {"k": -0.9}), ("power", {"k": 3.0}), ("lomax", {}),
    ("trimmed_logistic", {}), ("trimmed_logistic", {"mu": 0.3, "s": 0.001}),
])
def test_one_dimensional_samplers_agree_in_vector_lanes_and_one_at_a_time(name, params):
    """The 1-D inversion samplers run whole vectors of points and a scalar tail (the same
    templates): a batch against the same uniforms passed one at a time (all tail) gives the
    same points and pdfs bit for bit, u = 0 and points outside the support included."""
    s = rest.sampler(name, **params)
    u = np.concatenate([[0.0, 0.5, np.nextafter(1.0, 0.0)], np.random.default_rng(4).random(2045)])
    x, p = s.sample(u[:, None])
    one = [s.sample(u[i:i + 1, None]) for i in range(u.size)]
    np.testing.assert_array_equal(x, np.concatenate([o[0] for o in one]))
    np.testing.assert_array_equal(p, np.concatenate([o[1] for o in one]))
    probe = np.concatenate([x.ravel(), [-1.0, -0.0, 0.0, 1.0, 1.5, np.inf, np.nan]])
    one_pdf = np.concatenate([s.pdf(probe[i:i + 1, None]) for i in range(probe.size)])
    np.testing.assert_array_equal(s.pdf(probe[:, None]), one_pdf)
