"""The core's pieces for estimators outside the catalogue: the canonical points of a chunk
range, the accumulator state of one chunk of given values, and states merged in order."""
import numpy as np
import pytest

import reference_estimators as rest


@pytest.mark.parametrize("kind", ["random", "stratified", "sobol"])
def test_points_of_a_chunk_range_are_those_rows_of_the_whole_set(kind):
    n = 3 * rest.CHUNK_SIZE + 123
    whole = rest.points(n, 3, kind, seed=5, case_id=7, replica=2)
    part = rest.points(n, 3, kind, seed=5, case_id=7, replica=2, chunk_begin=1, chunk_end=3)
    assert np.array_equal(part, whole[rest.CHUNK_SIZE:3 * rest.CHUNK_SIZE])
    last = rest.points(n, 3, kind, seed=5, case_id=7, replica=2, chunk_begin=3)
    assert np.array_equal(last, whole[3 * rest.CHUNK_SIZE:])


def test_points_chunk_range_outside_the_estimate_is_refused():
    with pytest.raises(ValueError, match=r"chunks \[2, 2\) must be a non-empty range within the 1 chunk"):
        rest.points(10, 2, chunk_begin=2, chunk_end=2)


def test_chunk_states_merge_to_the_accumulated_values_and_name_faulty_points():
    n = 2 * rest.CHUNK_SIZE + 10
    u = rest.points(n, 2, seed=1)
    y = u[:, 0] * 2.0
    y[rest.CHUNK_SIZE + 4] = np.nan
    k = rest.CHUNK_SIZE
    states = [rest.accumulate_chunk(y[c * k:(c + 1) * k], first=c * k, points=u[c * k:(c + 1) * k])
              for c in range(3)]
    e = rest.estimate_of_states(states, reference=1.0)
    whole = rest.accumulate(y)
    assert (e.n, e.mean, e.variance) == (whole.n, whole.mean, whole.variance)
    assert e.issues == {"nan": 1} and e.reference == 1.0
    (ex,) = e.examples
    assert ex["index"] == rest.CHUNK_SIZE + 4
    assert ex["point"][:2] == tuple(u[rest.CHUNK_SIZE + 4])
    merged = rest.merge_states(states)
    assert rest.estimate_of_states([merged], reference=1.0).mean == e.mean


def test_accumulate_chunk_refuses_mismatched_points():
    with pytest.raises(ValueError, match=r"'points' must have shape \(3, dim\), one row per value, "
                                         r"got \(2, 2\)"):
        rest.accumulate_chunk(np.ones(3), points=np.ones((2, 2)))
    with pytest.raises(ValueError, match="'values' must not be empty"):
        rest.accumulate_chunk(np.ones(0))
