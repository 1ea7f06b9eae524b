"""The tabulated CDFs within their stated error bound: singularities, steps, texel tables, and tabulations
stopped by a budget or a useless bound."""
from __future__ import annotations

import math

import numpy as np
import pytest

import reference_estimators as rest

import harness.samplers.cdf_tables as cdf_tables
from harness.samplers import SamplerTest, zoo
from harness.samplers.transform import STRIPS, Transform


def test_tabulated_marginal_is_within_its_bound_of_the_exact_cdf():
    # cosine hemisphere: q(s) = 2 pi cos(theta) / pi = 2 s0 in s0 = cos(theta), so F0(c) = c^2
    cos = rest.sampler("cosine_hemisphere")
    n = 100_000
    t = SamplerTest(cos.pdf, "hemisphere", sample_count=n).transform
    c = np.linspace(0, 1, 10_001)
    s = np.column_stack([c, np.full_like(c, 0.3)])
    u = t(s)
    assert t.marginal.error <= 0.02 / math.sqrt(n)
    assert np.max(np.abs(u[:, 0] - c * c)) <= t.marginal.error + 1e-12
    # the azimuth is uniform in every strip: u1 = s1
    assert np.max(np.abs(u[:, 1] - 0.3)) <= t.conditional.error + 1e-12
    assert t.probability.shape == (STRIPS,) and t.probability.sum() == pytest.approx(1.0, abs=1e-12)


def test_a_singularity_and_a_narrow_lobe_on_the_interval_are_tabulated_within_the_bound():
    n = 100_000
    for name, params, cdf in [("power", {"k": -0.5}, np.sqrt),
                              ("linear", {"a": 1.0, "b": 0.37}, None)]:
        sm = rest.sampler(name, **params)
        t = Transform.build(lambda sp, sm=sm: sm.pdf(sp[:, 0]), 1, n)
        x = np.linspace(0, 1, 20_001)
        exact = cdf(x) if cdf is not None else np.concatenate([[0], np.cumsum(
            (sm.pdf(x[1:]) + sm.pdf(x[:-1])) / 2 * np.diff(x))])
        tol = t.error + (0 if cdf is not None else 1e-8)   # the trapezoid's own error on a line
        assert np.max(np.abs(t(x[:, None])[:, 0] - exact)) <= tol, name
        assert t.error * math.sqrt(n) <= 0.01, name   # the carry moves sqrt(n W^2) by <= 0.01


@pytest.mark.parametrize("prefix, cdf", [
    ("uniform_theta_sphere", lambda s: np.arccos(1 - 2 * s) / math.pi),   # s0 = (1 - cos theta) / 2
    ("disk, r = u", np.sqrt),                                           # s0 = r^2
    ("uniform_cone(cos_max=0.9)", lambda s: np.minimum(s / 0.05, 1.0)),
])
def test_singular_and_stepped_marginals_carry_only_their_kept_leaves_error(prefix, cdf):
    """Pole and centre singularities and a cone's edge: the marginal is within its bound of the
    exact CDF, and the bound (the kept leaves' cubature error and interpolation bound; summing
    the refined-away leaves' too had given 3.5e-4, 2.8e-4 and 2.8e-5 at 1e6 samples) moves
    sqrt(n W^2) by at most 0.02, so Cramer-von Mises on u0 keeps its power."""
    s = next(z for z in zoo.correct() if z.name.startswith(prefix))
    n = 1_000_000
    m = SamplerTest(s.pdf, s.domain, sample_count=n, breaks=s.breaks).transform.marginal
    x = np.concatenate([np.linspace(0, 1, 100_001), m.lo, m.hi, np.geomspace(1e-12, 1, 2001)])
    got = m(np.zeros(x.size, dtype=np.int64), x)
    assert np.max(np.abs(got - cdf(x))) <= m.error
    assert m.error * math.sqrt(n) <= 0.02


@pytest.mark.parametrize("prefix", ["uniform_theta_sphere", "disk, r = u", "uniform_cone(cos_max=0.9)"])
def test_conditionals_at_poles_and_edges_are_tabulated_within_their_bound(prefix):
    """These densities are uniform in s1 (the azimuth) in every strip, so u1 = s1 exactly.  The
    pole and centre singularities sit in the first strip, where the conditional's boxes are
    graded geometrically toward s0 = 0 and 1 (one box across the singular end had left a bound
    of 1.5e-3, past 1 / sqrt(n)); the cone's edge is a step of the density inside a strip,
    where the boxes are cut (a box across it had left 4.7e-5)."""
    s = next(z for z in zoo.correct() if z.name.startswith(prefix))
    n = 1_000_000
    t = SamplerTest(s.pdf, s.domain, sample_count=n, breaks=s.breaks).transform
    hi = 0.05 if "cone" in prefix else 1.0                 # the cone: s0 in [0, 0.05]
    s0 = np.concatenate([np.geomspace(1e-12, hi, 3000), hi - np.geomspace(1e-12, hi, 3000)[1:]])
    s1 = np.random.default_rng(0).random(s0.size)
    u = t(np.column_stack([s0, s1]))
    assert np.max(np.abs(u[:, 1] - s1)) <= t.conditional.error
    assert t.conditional.error * math.sqrt(n) <= 0.01


def test_a_texel_tables_conditional_is_exact_between_its_steps():
    """A piecewise-constant 32 x 16 table on the square: the conditional's boxes are cut at every
    texel column inside a strip (the marginal's steps), so each box integrates a constant and
    the conditional CDF matches the exact one (computed from the texels) within its bound,
    which is rounding (a box across a column had left 2.7e-3)."""
    s = next(z for z in zoo.correct() if z.name.startswith("piecewise_constant_2d"))
    cols, rows = 32, 16
    centres = np.column_stack([np.repeat((np.arange(cols) + 0.5) / cols, rows),
                               np.tile((np.arange(rows) + 0.5) / rows, cols)])
    texel = s.pdf(centres).reshape(cols, rows)
    t = SamplerTest(s.pdf, s.domain, sample_count=1_000_000, breaks=s.breaks).transform
    rng = np.random.default_rng(1)
    worst = 0.0
    left = np.arange(cols) / cols
    for a, b in zip(t.edges[:-1], t.edges[1:]):
        overlap = np.clip(np.minimum(b, left + 1 / cols) - np.maximum(a, left), 0, None)
        row_mass = overlap @ texel / rows
        cum = np.concatenate([[0.0], np.cumsum(row_mass)])
        s0, s1 = a + (b - a) * rng.random(500), rng.random(500)
        k = np.minimum((s1 * rows).astype(int), rows - 1)
        exact = (cum[k] + row_mass[k] * (s1 * rows - k)) / cum[-1]
        worst = max(worst, np.max(np.abs(t(np.column_stack([s0, s1]))[:, 1] - exact)))
    assert worst <= t.conditional.error <= 1e-11


def test_a_tabulation_over_its_evaluation_budget_stops_within_its_bound(monkeypatch):
    """A disk of uniform density on the square: its rim, a curve across every box it meets,
    keeps the cubature refining; with the budget cut to 2 million pdf calls the tabulation
    stops there, and the marginal it gives is still within its (larger) bound of the exact
    CDF, the disk's segment area left of s0."""

    monkeypatch.setattr(cdf_tables, "_MAX_TABLE_EVALS", 2_000_000)
    r = 0.3
    calls = []

    def q(sp: np.ndarray) -> np.ndarray:
        calls.append(sp.shape[0])
        return np.where(np.hypot(sp[:, 0] - 0.5, sp[:, 1] - 0.5) <= r, 1 / (math.pi * r * r), 0.0)

    t = Transform.build(q, 2, 1_000_000)
    # the budget, then at most one round of box integrals (_MAX_EVALS) past it, per table
    # (without the cut: 60 million)
    assert sum(calls) <= 2 * (2_000_000 + cdf_tables._MAX_EVALS)
    x = np.linspace(0.2, 0.8, 2001)
    d = np.clip((x - 0.5) / r, -1, 1)
    exact = (np.arccos(-d) * r * r - (-d) * r * r * np.sqrt(1 - d * d)) / (math.pi * r * r)
    got = t(np.column_stack([x, np.full_like(x, 0.5)]))[:, 0]
    assert np.max(np.abs(got - exact)) <= t.marginal.error + 1e-9


def test_a_tabulation_stops_refining_once_its_cubature_error_leaves_the_tests_no_power():
    """A rotated checkerboard (a density stepping along lines across every box): its box
    integrals never converge, and halving its leaves adds boxes with errors of their own.  Once
    the cubature error spent in a strip passes 1 / sqrt(n) the tabulation stops: a sixth of the
    pdf calls of refining on to the limits, which leave both bounds past 1 / sqrt(n) still (the
    tests gain no power: the marginal's 0.13 against the stop's 0.016, the conditional's 0.022
    against 0.025), and the marginal still within its bound."""
    import harness.samplers.transform as tr

    c, s = math.cos(0.5), math.sin(0.5)

    def checkerboard(calls: list):
        def q(sp: np.ndarray) -> np.ndarray:
            calls.append(sp.shape[0])
            a = np.sin(2 * np.pi * 16 * (sp[:, 0] * c + sp[:, 1] * s))
            b = np.sin(2 * np.pi * 16 * (-sp[:, 0] * s + sp[:, 1] * c))
            return 1 + 0.9 * np.sign(a * b)
        return q

    n = 1_000_000
    stopped, refined = [], []
    t = Transform.build(checkerboard(stopped), 2, n)
    tabulate = tr.tabulate
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(tr, "tabulate", lambda *a, **k: tabulate(*a, **{**k, "useless": math.inf}))
        t_on = Transform.build(checkerboard(refined), 2, n)
    assert sum(stopped) < sum(refined) / 4
    assert min(t_on.marginal.error, t_on.conditional.error) > 1 / math.sqrt(n)
    assert t.marginal.error <= t_on.marginal.error
    # the marginal CDF against a 4096 x 4096 midpoint sum of the density (error ~1e-4)
    g = (np.arange(4096) + 0.5) / 4096
    col = np.array([checkerboard([])(np.column_stack([np.full_like(g, x), g])).mean() for x in g])
    exact = np.concatenate([[0.0], np.cumsum(col)]) / col.sum()
    x = np.arange(4097) / 4096
    got = t(np.column_stack([x, np.full_like(x, 0.5)]))[:, 0]
    assert np.max(np.abs(got - exact)) <= t.marginal.error + 2e-4


def test_once_a_strip_stops_with_a_useless_bound_the_others_stop_refining_to_eps():
    """A lobe on a floor, rough along its lowest band of s0 (a rotated checkerboard there, as
    an area light's curved edge in its cap map): the conditional's strip there stops with a
    bound past 1 / sqrt(n), which is then the table's error whatever the other strips reach;
    they stop refining to it, for about half the conditional's pdf calls (7.1 million against
    13.2) and the same error (the tests have no power on u1 either way)."""
    import harness.samplers.transform as tr

    c, s = math.cos(0.5), math.sin(0.5)

    axis = [0]
    tabulate = tr.tabulate

    def tabulate_axis(*args, **kw):   # args[2]: the axis tabulated (1: the conditional)
        axis[0] = args[2]
        return tabulate(*args, **kw)

    def rough(calls: list):
        def q(sp: np.ndarray) -> np.ndarray:
            calls.append(sp.shape[0] if axis[0] == 1 else 0)
            v = np.exp(-((sp[:, 0] - 0.5) ** 2 + (sp[:, 1] - 0.5) ** 2) / (2 * 0.05**2)) + 0.05
            a = np.sin(2 * np.pi * 40 * (sp[:, 0] * c + sp[:, 1] * s))
            b = np.sin(2 * np.pi * 40 * (-sp[:, 0] * s + sp[:, 1] * c))
            return np.where(sp[:, 0] < 0.05, v * (1 + 0.9 * np.sign(a * b)), v)
        return q

    n = 1_000_000
    calls, refined = [], []
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(tr, "tabulate", tabulate_axis)
        t = Transform.build(rough(calls), 2, n)
        mp.setattr(cdf_tables, "_settled_bound", lambda bound, mass: 0.0)   # every strip refines to eps
        t_on = Transform.build(rough(refined), 2, n)
    assert t.conditional.error > 1 / math.sqrt(n)
    assert t.conditional.error == pytest.approx(t_on.conditional.error, rel=1e-6)
    assert t.marginal.error == t_on.marginal.error
    assert sum(calls) < 0.6 * sum(refined)      # the conditional's pdf calls
