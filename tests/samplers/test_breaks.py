"""Declared breaks (where a claimed pdf may step or kink) and the sphere's pole: the cubature
splits at a break in one step, the integrals and bounds stay its own, and a pole other than
+z is an exact permutation of the frame."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from harness.samplers import Domain, SamplerTest, zoo
from harness.samplers.cubature import box_integrals, split_points
from harness.samplers.domains import checked_breaks


def test_a_box_is_split_at_the_break_nearest_its_middle_else_at_its_middle():
    breaks = np.array([0.1, 0.3, 0.45, 0.7])
    lo, hi = np.array([0.0, 0.0, 0.5, 0.3, 0.75]), np.array([1.0, 0.5, 0.6, 0.45, 1.0])
    assert split_points(lo, hi, breaks).tolist() == [0.45, 0.3, 0.55, 0.375, 0.875]
    # on an end, or a rounding away from it: no sliver, the middle
    end = 0.3 + 1e-17
    assert split_points(np.array([end]), np.array([0.4]), breaks)[0] == (end + 0.4) / 2
    assert split_points(lo, hi, None).tolist() == ((lo + hi) / 2).tolist()


def _step(x: np.ndarray) -> np.ndarray:
    """A density on [0, 1]^2 that steps 1:9 at s0 = 1/3 and is smooth elsewhere."""
    return np.where(x[:, 0] < 1 / 3, 0.5, 4.5) * (1 + 0.3 * np.sin(3 * x[:, 1]))


def _exact_step() -> float:
    across = 1 + 0.3 * (1 - math.cos(3)) / 3
    return (0.5 / 3 + 4.5 * 2 / 3) * across


@pytest.mark.parametrize("declared", [False, True])
def test_the_integral_of_a_step_is_within_its_bound_and_one_split_where_declared(declared):
    calls = []

    def q(x):
        calls.append(x.shape[0])
        return _step(x)

    breaks = (np.array([1 / 3]), None) if declared else None
    v, e = box_integrals(q, np.zeros((1, 2)), np.ones((1, 2)), 1e-10, breaks=breaks)
    assert abs(v[0, 0] - _exact_step()) <= e[0, 0] + 1e-15
    if declared:    # one split cuts the step out; halving approaches it to the depth limit
        assert sum(calls) <= 1_000 and e[0, 0] <= 1e-10
    else:
        assert sum(calls) > 10_000 and e[0, 0] > 1e-8


def test_the_pole_permutes_the_frame_exactly():
    rng = np.random.default_rng(5)
    s = rng.random((1000, 2))
    z, y, x = Domain("sphere"), Domain("sphere", pole="y"), Domain("sphere", pole="x")
    assert np.array_equal(y.to_points(s), z.to_points(s)[:, [1, 2, 0]])
    assert np.array_equal(x.to_points(s), z.to_points(s)[:, [2, 0, 1]])
    w = z.to_points(s)
    assert np.array_equal(y.to_params(w)[0], z.to_params(w[:, [2, 0, 1]])[0])
    assert y.to_params(np.array([[0.0, 1.0, 0.0]]))[0][0, 0] == 0.0          # theta from +y
    with pytest.raises(ValueError, match="'pole' 'y' is for the sphere only"):
        Domain("hemisphere", pole="y")
    for pole in ("w", ["y"], None):
        with pytest.raises(ValueError, match="'pole' must be one of"):
            Domain("sphere", pole=pole)


def test_a_sampler_about_another_pole_gets_the_same_tables_bit_for_bit():
    """The pole-singular zoo sampler turned so that its pole is +y, checked with pole "y":
    the density in parameter space is the same function, so are the cubature and tables."""
    pole = next(s for s in zoo.correct() if s.name.startswith("uniform_theta_sphere"))
    turned = SamplerTest(lambda w: pole.pdf(w[:, [2, 0, 1]]), Domain("sphere", pole="y"),
                         sample_count=100_000)
    plain = SamplerTest(pole.pdf, "sphere", sample_count=100_000)
    assert np.array_equal(turned.mass, plain.mass) and np.array_equal(turned.err, plain.err)
    assert turned.transform.error == plain.transform.error
    assert np.array_equal(turned.transform.conditional.start, plain.transform.conditional.start)
    sample = lambda u: pole.sample(u)[:, [1, 2, 0]]   # noqa: E731  the sampler turned the same way
    assert turned.check(sample, seed=3).pvalue == plain.check(pole.sample, seed=3).pvalue


def test_breaks_are_validated_sorted_and_stripped_of_the_ends():
    dom = Domain("sphere")
    b = checked_breaks([[0.5, 0.25, 0.5, 0.0, 1.0], None], dom)
    assert b[0].tolist() == [0.25, 0.5] and b[1] is None
    assert checked_breaks(None, dom) is None
    rows = checked_breaks(np.array([[0.5, 0.25], [0.1, 0.2]]), dom)     # an array, a row per axis
    assert rows[0].tolist() == [0.25, 0.5] and rows[1].tolist() == [0.1, 0.2]
    for bad, match in [([[0.5]], "sequence of 2"), ("ab", "sequence of 2"), ([[np.nan], None], "not finite"),
                       ([[1.5], None], r"in \[0, 1\]"), ([["x"], None], "must be numbers"),
                       ([0.3, 0.5], "must be a sequence of coordinates"), (b"\x00\xff", "sequence of 2"),
                       ([{"a": 1}, None], "must be numbers"), (7, "sequence of 2"),
                       ([[10**400], None], "must be numbers")]:
        with pytest.raises(ValueError, match=match):
            checked_breaks(bad, dom)


_ANYTHING = st.recursive(st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=3)
                         | st.binary(max_size=3), lambda inner: st.lists(inner, max_size=4)
                         | st.tuples(inner, inner) | st.dictionaries(st.text(max_size=2), inner, max_size=2),
                         max_leaves=12)


@settings(max_examples=300, deadline=None)
@given(_ANYTHING, st.sampled_from(["interval", "sphere"]))
def test_any_breaks_are_taken_or_refused_with_a_value_error(breaks, kind):
    """Whatever a sampler carries as ``breaks``: sorted coordinates strictly inside (0, 1), one
    array (or None) per axis, or a ValueError naming 'breaks', never another exception."""
    dom = Domain(kind)
    try:
        out = checked_breaks(breaks, dom)
    except ValueError as e:
        assert "'breaks'" in str(e)
        return
    assert out is None or len(out) == dom.k
    for v in out or ():
        assert v is None or (v.ndim == 1 and np.all((v > 0) & (v < 1)) and np.all(np.diff(v) > 0))


def test_natural_coordinates_map_to_the_parameter_axes():
    assert Domain("sphere").breaks([math.pi / 2], [-math.pi / 2]) == (pytest.approx([0.5]),
                                                                     pytest.approx([0.75]))
    assert Domain("hemisphere").breaks([math.pi / 3], None)[0] == pytest.approx([0.5])
    assert Domain("disk").breaks([0.5], [math.pi])[0] == pytest.approx([0.25])
    assert Domain("interval", 1.0, 3.0).breaks([2.5])[0] == pytest.approx([0.75])
    assert Domain("half_line").breaks([1.0])[0] == pytest.approx([0.5])
    with pytest.raises(ValueError, match="the sphere has 2 coordinate"):
        Domain("sphere").breaks([1.0])


def test_a_declared_envmap_costs_fewer_pdf_calls_for_tighter_tables():
    """The zoo's 16 x 32 lat-long map with and without its texel edges declared: fewer pdf
    calls, a transform bound no larger, and its exact mass 1 within the cubature's bound (which
    without the breaks it misses by 1.7e-4, 26 times its bound of 6.5e-6: a texel edge within
    3.5 % of a cell's width from its end or its middle lies between every node of the box's
    rule and of its halves', and the rules agree on the wrong value)."""
    env, declared = (next(s for s in zoo.correct() if s.name == name)
                     for name in ("envmap 16x32 on the sphere",
                                  "envmap 16x32 on the sphere, texel edges declared"))
    calls = {}

    def counted(key):
        def pdf(w):
            calls[key] = calls.get(key, 0) + w.shape[0]
            return env.pdf(w)
        return pdf

    plain = SamplerTest(counted("plain"), "sphere", sample_count=1_000_000)
    cut = SamplerTest(counted("cut"), "sphere", sample_count=1_000_000, breaks=declared.breaks)
    mass, err = cut.normalization
    assert abs(mass - 1) <= err
    assert calls["cut"] <= 0.85 * calls["plain"]
    assert cut.transform.error <= 1.01 * plain.transform.error
