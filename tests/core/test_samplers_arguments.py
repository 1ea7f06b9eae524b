"""The sampler API's argument checks and the pbrt-style sample_/_pdf/invert_ functions by name."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

import reference_estimators as rest

from tests.core.sampler_cases import PC2D_TABLE, REGISTRY, Case


# --- argument errors ----------------------------------------------------------------------
def test_unknown_sampler_lists_known_samplers():
    with pytest.raises(ValueError, match=r"unknown sampler 'nope'; known samplers: .*ggx") as e:
        rest.sampler("nope")
    for name in REGISTRY:
        assert name in str(e.value)


def test_unknown_parameter_is_named():
    with pytest.raises(ValueError, match=r"sampler 'ggx' has no parameter 'beta'; its parameters: alpha"):
        rest.sampler("ggx", beta=0.3)
    with pytest.raises(ValueError, match=r"has no parameter 'k'; its parameters: \(none\)"):
        rest.sampler("uniform_sphere", k=1)


@pytest.mark.parametrize("name,params,message", [
    ("ggx", {"alpha": 0}, "'alpha' must be > 0"),
    ("ggx", {"alpha": -0.1}, "'alpha' must be > 0"),
    ("exponential", {"rate": -1}, "'rate' must be > 0"),
    ("exponential", {"rate": 0}, "'rate' must be > 0"),
    ("power", {"k": -1}, "'k' must be > -1"),
    ("uniform_cone", {"cos_max": 1}, "'cos_max' must be in (-1, 1)"),
    ("uniform_cone", {"cos_max": -1}, "'cos_max' must be in (-1, 1)"),
    ("lomax", {"shape": 0}, "'shape' must be > 0"),
    ("linear", {"a": -1}, "'a' must be >= 0"),
    ("linear", {"a": 0, "b": 0}, "'a + b' must be > 0"),
    ("trimmed_logistic", {"s": 0}, "'s' must be > 0"),
    ("trimmed_logistic", {"a": 1, "b": 0}, "'b' must be > a"),
    ("ggx", {"alpha": math.inf}, "'alpha' must be finite"),
    ("ggx", {"alpha": math.nan}, "'alpha' must be finite"),
])
def test_invalid_parameter_names_argument_and_rule(name, params, message):
    with pytest.raises(ValueError, match=re.escape(f"sampler '{name}': parameter {message}")):
        rest.sampler(name, **params)


def test_non_numeric_parameter_is_a_type_error():
    with pytest.raises(TypeError, match=r"parameter 'alpha' must be a number"):
        rest.sampler("ggx", alpha="0.1")


@pytest.mark.parametrize("name,table,message", [
    ("piecewise_constant_1d", [1.0, 2.0, -1.0], r"table values must be finite and >= 0, got -1 at index 2"),
    ("piecewise_constant_1d", [1.0, math.nan], r"table values must be finite and >= 0, got nan at index 1"),
    ("piecewise_constant_1d", [1.0, math.inf], r"table values must be finite and >= 0, got inf at index 1"),
    ("piecewise_constant_1d", [0.0, 0.0, 0.0], r"table values must not all be 0"),
    ("piecewise_constant_2d", [[1.0, 2.0], [-0.5, 1.0]],
     r"table values must be finite and >= 0, got -0.5 at index 2"),
    ("piecewise_constant_2d", [[1.0, math.nan], [0.5, 1.0]],
     r"table values must be finite and >= 0, got nan at index 1"),
    ("piecewise_constant_2d", np.zeros((3, 4)), r"table values must not all be 0"),
    ("piecewise_constant_2d", [1.0, 2.0, 3.0], r"table must be 2-dimensional"),
])
def test_bad_tables_are_rejected(name, table, message):
    with pytest.raises(ValueError, match=rf"sampler '{name}': {message}"):
        rest.sampler(name, table=np.array(table, dtype=float))


def test_table_required_and_refused():
    with pytest.raises(ValueError, match=r"sampler 'piecewise_constant_1d' needs a table"):
        rest.sampler("piecewise_constant_1d")
    with pytest.raises(ValueError, match=r"sampler 'ggx' takes no table"):
        rest.sampler("ggx", table=[1.0, 2.0])


@pytest.mark.parametrize("case,shape,want", [
    (Case("ggx", "ggx"), (5, 3), r"'u' must have shape (N, 2), got (5, 3)"),
    (Case("ggx", "ggx"), (5,), r"'u' must have shape (N, 2), got (5,)"),
    (Case("pc2d", "piecewise_constant_2d", table=PC2D_TABLE), (5, 1),
     r"'u' must have shape (N, 2), got (5, 1)"),
    (Case("linear", "linear"), (5, 2), r"'u' must have shape (N, 1) or (N,), got (5, 2)"),
    (Case("linear", "linear"), (5, 1, 1), r"'u' must have shape (N, 1) or (N,), got (5, 1, 1)"),
])
def test_sample_rejects_u_of_the_wrong_shape(case, shape, want):
    with pytest.raises(ValueError, match=re.escape(want)):
        case.make().sample(np.full(shape, 0.5))


@pytest.mark.parametrize("case,shape,want", [
    (Case("ggx", "ggx"), (5, 2), r"'x' must have shape (N, 3), got (5, 2)"),
    (Case("uniform_sphere", "uniform_sphere"), (3,), r"'x' must have shape (N, 3), got (3,)"),
    (Case("pc2d", "piecewise_constant_2d", table=PC2D_TABLE), (5, 3),
     r"'x' must have shape (N, 2), got (5, 3)"),
    (Case("exponential", "exponential"), (5, 2), r"'x' must have shape (N, 1) or (N,), got (5, 2)"),
])
def test_pdf_and_invert_reject_x_of_the_wrong_shape(case, shape, want):
    s = case.make()
    with pytest.raises(ValueError, match=re.escape(want)):
        s.pdf(np.full(shape, 0.5))
    with pytest.raises(ValueError, match=re.escape(want)):
        s.invert(np.full(shape, 0.5))


@pytest.mark.parametrize("n,exc", [(0, ValueError), (-5, ValueError), (2.5, TypeError), (True, TypeError)])
def test_draw_rejects_bad_counts(n, exc):
    with pytest.raises(exc, match="'n'"):
        rest.sampler("linear").draw(n)


# --- pbrt-style names ----------------------------------------------------------------------
def test_every_analytic_sampler_has_a_complete_triple_by_name():
    from reference_estimators import sampling

    rng = np.random.default_rng(3)
    for info in rest.samplers():
        if info["needs_table"]:
            continue
        name = info["name"]
        fns = [getattr(sampling, f) for f in (f"sample_{name}", f"{name}_pdf", f"invert_{name}")]
        s = rest.sampler(name)
        u = rng.random((100, s.udim))
        x = fns[0](u)
        np.testing.assert_array_equal(x, s.sample(u)[0], err_msg=name)
        np.testing.assert_array_equal(fns[1](x), s.pdf(x), err_msg=name)
        np.testing.assert_array_equal(fns[2](x), s.invert(x), err_msg=name)
    assert (sampling.sample_ggx(np.full((1, 2), 0.5), alpha=0.3)[0, 2]
            == pytest.approx(1 / math.sqrt(1 + 0.09)))
