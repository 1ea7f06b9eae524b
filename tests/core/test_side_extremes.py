"""reference_estimators.side_extremes (one C++ pass: a subsample's floor, then a selection over
what clears it) against the definition in numpy: the largest positive deviation from the
centre on one side, how many equal it, and the `keep` largest strictly below it.  Exact
equality, including the fallback where too few deviations clear the subsample's floor (an
atom holding most of the tail) and NaN / inf values."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import reference_estimators as rest


def by_definition(y: np.ndarray, center: float, upper: bool, keep: int):
    d = (y - center) if upper else (center - y)
    d = d[d > 0]
    if d.size == 0:
        return None
    top = d.max()
    below = d[d < top]
    m = min(keep, below.size)
    largest = np.sort(np.partition(below, below.size - m)[below.size - m:])[::-1]
    return top, int(np.count_nonzero(d == top)), largest


def assert_same(y: np.ndarray, center: float, upper: bool, keep: int) -> None:
    peak, ties, below = rest.side_extremes(y, center, upper=upper, keep=keep)
    want = by_definition(y, center, upper, keep)
    if want is None:
        assert np.isnan(peak) and ties == 0 and below.size == 0
    else:
        assert (peak, ties) == want[:2]
        assert np.array_equal(below, want[2])


RNG = np.random.default_rng(0)
BLOCKS = {
    "uniform": RNG.random(390_625),
    "clamped pareto": np.minimum(RNG.pareto(1.5, 390_625), 50.0),
    "integers": np.round(RNG.random(100_000) * 5),
    "atom of 1 %": np.where(RNG.random(390_625) < 0.01, 7.0, RNG.random(390_625)),
    "atom of 60 %": np.where(RNG.random(200_000) < 0.6, 2.0, RNG.random(200_000)),
    "constant": np.full(50_000, 3.0),
    "tiny": RNG.random(10),
    "non-finite": np.array([np.nan, 1.0, np.inf, 2.0, -np.inf]),
}


@pytest.mark.parametrize("name", sorted(BLOCKS))
@pytest.mark.parametrize("upper", [True, False])
@pytest.mark.parametrize("keep", [1, 5, 5000, 20_000])
def test_matches_the_definition(name, upper, keep):
    y = BLOCKS[name]
    assert_same(y, float(np.median(y[np.isfinite(y)])), upper, keep)


@settings(max_examples=200, deadline=None)
@given(hnp.arrays(np.float64, st.integers(0, 3000), elements=st.floats(allow_nan=True, allow_infinity=True)),
       st.floats(-1e6, 1e6), st.booleans(), st.integers(1, 400))
def test_matches_the_definition_on_any_values(y, center, upper, keep):
    assert_same(y, center, upper, keep)
