"""A user's estimator (a contributions callable) in the statistics API: the same chunked
streams as the catalogue, its errors named, and every measurement that takes a catalogue name
taking it too."""
import math
import re

import numpy as np
import pytest

import reference_estimators as rest

from harness import stats
from harness.testing import assert_converges
from harness.usercode import UserCodeError


def importance(u):
    """3 x^2 on [0, 1] (integral 1) sampled with pdf 2x."""
    x = np.sqrt(u[:, 0])
    return 1.5 * x


def test_an_estimate_does_not_depend_on_how_its_chunks_are_grouped():
    c = stats.Contributions(importance, 2, 1.0)
    n = 3 * rest.CHUNK_SIZE + 7
    whole = c.estimate(n, seed=3, case_id=4, replica=5)
    parts = [c.state(n, 0, 1, seed=3, case_id=4, replica=5), c.state(n, 1, 4, seed=3, case_id=4, replica=5)]
    split = c.from_states(parts)
    assert (split.n, split.mean, split.variance) == (whole.n, whole.mean, whole.variance)
    again = c.estimate(n, seed=3, case_id=4, replica=5)
    assert again.mean == whole.mean                       # bitwise reproducible
    y = c.values(n, seed=3, case_id=4, replica=5)
    assert y.shape == (n,) and math.isclose(float(np.mean(y)), whole.mean, rel_tol=1e-12)


def test_the_callable_sees_the_streams_points():
    seen = []

    def spy(u):
        seen.append(u.copy())
        return u[:, 0]
    stats.Contributions(spy, 3).estimate(100, seed=9, case_id=1, replica=2)
    assert np.array_equal(seen[0], rest.points(100, 3, seed=9, case_id=1, replica=2))


def test_errors_name_the_callable_the_input_and_the_expected_output():
    def scalar(u):
        return float(np.sum(u))

    def boom(u):
        raise KeyError("albedo")
    with pytest.raises(UserCodeError, match=r"test_estimator:test_errors_name.*<locals>.scalar returned "
                                            r"shape \(\) for uniforms of shape \(100, 2\), float64; "
                                            r"expected shape \(100,\)"):
        stats.Contributions(scalar, 2).estimate(100)
    with pytest.raises(UserCodeError, match=r"boom raised KeyError: 'albedo' \(called on shape \(100, 2\), "
                                            r"float64; expected to return contributions of shape \(100,\)\)"):
        stats.Contributions(boom, 2).estimate(100)
    with pytest.raises(UserCodeError,      # a string had been parsed as a number where it was one
                       match=r"returned a str of <U1 values .*expected a float array of shape \(100,\)"):
        stats.Contributions(lambda u: "x", 2).estimate(100)


def test_faulty_contributions_are_counted_with_their_uniforms():
    def holes(u):
        y = u[:, 0].copy()
        y[u[:, 0] < 0.01] = np.nan
        return y
    e = stats.Contributions(holes, 2).estimate(10_000)
    assert e.issues["nan"] == 10_000 - e.n > 50
    assert all(ex["point"][0] < 0.01 for ex in e.examples)


@pytest.mark.parametrize("bad, message", [
    ({"dim": 0}, "'dim' must be a positive integer"),
    ({"points": "halton"}, "'points' must be one of random, stratified, sobol"),
    ({"reference": math.inf}, "'reference' must be a finite number"),
])
def test_contributions_refuse_bad_arguments(bad, message):
    with pytest.raises(ValueError, match=message):
        stats.Contributions(importance, **{"dim": 2, **bad})


def test_contributions_take_numpy_scalars():
    # a dim from an array's shape, a reference from numpy: had been refused
    c = stats.Contributions(importance, np.int64(2), np.float32(1.0))
    assert c.dim == 2 and type(c.dim) is int and c.reference == 1.0 and type(c.reference) is float


@pytest.mark.parametrize("techniques, budgets, message", [
    ([importance], [], "'budgets' needs at least one size, got []"),
    ([importance], None, "'budgets' needs at least one size, got None"),
    ([importance], [1024, 0], "'budgets' must be a positive whole number, got 0"),
    ([], [1024], "'techniques' must name at least one technique, got none"),
])
def test_error_vs_time_refuses_what_gives_no_table(techniques, budgets, message):
    # each had returned an empty table
    with pytest.raises(ValueError, match=re.escape(message)):
        stats.error_vs_time(None, techniques, budgets, 8, dim=2, reference=1.0)


def test_replicate_convergence_and_error_vs_time_take_callables():
    r = stats.replicate(importance, n=4096, replicas=16, dim=2, reference=1.0)
    assert r.integrand.endswith(":importance") and r.technique == "importance" and r.iid
    assert math.isclose(r.sample_variance, 1.125 - 1.0, rel_tol=0.05)   # E[(1.5 x)^2] - 1, x = sqrt(u)
    assert stats.efficiency(r).verdict == "measured"
    c = stats.convergence_rate(importance, budgets=[1024, 4096, 16384, 65536], dim=2, reference=1.0)
    assert c.passed and c.n == 4 * 32
    table = stats.error_vs_time(None, [importance, stats.Contributions(lambda u: 3 * u[:, 0] ** 2, 1, 1.0,
                                                                       label="uniform")],
                                [1024, 4096], 8, dim=2, reference=1.0)
    assert list(table["technique"]) == ["importance"] * 2 + ["uniform"] * 2
    assert (table["rmse"] > 0).all() and (table["replicas"] == 8).all()
    assert_converges(importance, budgets=[1024, 4096, 16384], dim=2, reference=1.0)


def test_a_callable_slower_than_promised_fails_assert_converges():
    def stuck(u):            # an estimator whose error stops falling: biased by 0.01
        return 1.5 * np.sqrt(u[:, 0]) + 0.01
    with pytest.raises(AssertionError, match="slower than expected"):
        assert_converges(stuck, budgets=[4096, 65536, 2**20], dim=1, reference=1.0, replicas=16)


def test_naming_mistakes_are_explained():
    with pytest.raises(TypeError, match="needs dim="):
        stats.replicate(importance, n=100, replicas=4)
    with pytest.raises(TypeError, match="takes no technique"):
        stats.replicate(importance, "uniform", 100, 4, dim=2)
    with pytest.raises(TypeError, match="dim and reference apply to contributions callables"):
        stats.replicate("gaussian", "uniform", 100, 4, dim=2)
    with pytest.raises(ValueError, match="errors need the exact value: give reference="):
        stats.convergence_rate(importance, budgets=[16, 64, 256], dim=2)
