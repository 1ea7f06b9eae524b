"""The contributions' tails (rest.value_tails, integrate_chunks(tail_keep=...), merge_tails):
exactly the largest values, their ties and the `keep` below, as a sort over all of them gives,
on any thread count, with atoms, NaN and infinities; merged parts give the union's tails."""
import numpy as np
import pytest

import reference_estimators as rest


def sorted_side(values: np.ndarray, keep: int) -> dict:
    v = np.sort(values[np.isfinite(values)])[::-1]
    if v.size == 0:
        return {"peak": None, "ties": 0, "below": []}
    return {"peak": v[0], "ties": int(np.sum(v == v[0])), "below": list(v[v < v[0]][:keep])}


def assert_tails(got: dict, values: np.ndarray, keep: int) -> None:
    for name, v in (("upper", values), ("lower", -values)):
        want = sorted_side(v, keep)
        assert got[name]["peak"] == want["peak"] and got[name]["ties"] == want["ties"], name
        np.testing.assert_array_equal(np.array(got[name]["below"]), np.array(want["below"]), err_msg=name)


rng = np.random.default_rng(20261203)
ARRAYS = {
    "normal": rng.standard_normal(100_000),
    "pareto 1.5": rng.pareto(1.5, 200_000),
    "clamped at 200": np.minimum(rng.pareto(1.5, 200_000), 200.0),
    "rare event": np.where(rng.random(100_000) < 3e-5, 1 / 3e-5, 0.0),
    "five values": rng.integers(0, 5, 100_000).astype(float),
    "all equal": np.full(5000, 2.5),
    "non-finite": np.array([np.nan, np.inf, 1.0, -np.inf, np.nan, -3.0, 1.0]),
    "none finite": np.array([np.nan, np.inf]),
    "short": np.array([4.0, -1.0, 3.0]),
}


@pytest.mark.parametrize("name", ARRAYS)
@pytest.mark.parametrize("keep", [0, 1, 50, 3000])
def test_value_tails_equal_a_sort(name, keep):
    y = ARRAYS[name]
    got = rest.value_tails(y, keep, median=True)
    assert_tails(got, y, keep)
    finite = np.sort(y[np.isfinite(y)])
    assert got["median"] == (finite[finite.size // 2] if finite.size else None)


@pytest.mark.parametrize("name", ["normal", "pareto 1.5", "clamped at 200", "rare event", "five values"])
def test_merged_parts_give_the_union_in_any_order(name):
    y = ARRAYS[name]
    parts = [rest.value_tails(p, 400, median=True) for p in np.array_split(y, 7)]
    merged = rest.merge_tails(parts, 400)
    assert_tails(merged, y, 400)
    assert merged["median"] == parts[0]["median"]
    backwards = rest.merge_tails(parts[::-1], 400)
    assert backwards["upper"] == merged["upper"] and backwards["lower"] == merged["lower"]


@pytest.mark.parametrize("technique", ["uniform", "importance:linear", "roulette:uniform(q=0.5)",
                                       "mis_balance:uniform+linear"])
@pytest.mark.parametrize("keep", [1, 64, 2000])
def test_integrate_chunks_keeps_the_tails_of_what_it_accumulates(technique, keep):
    n, chunks = 5 * rest.CHUNK_SIZE + 123, 6
    y = rest.contributions("gaussian", technique, n, seed=3, case_id=7, replica=2, threads=1)
    plain = rest.integrate_chunks("gaussian", technique, n, 0, chunks, seed=3, case_id=7, replica=2,
                                  threads=1)
    states = [rest.integrate_chunks("gaussian", technique, n, 0, chunks, seed=3, case_id=7, replica=2,
                                    threads=threads, tail_keep=keep, tail_median=True) for threads in (1, 2)]
    for s in states:
        tails = s.pop("tails")
        assert {k: v for k, v in s.items() if k not in ("seconds", "threads")} == \
            {k: v for k, v in plain.items() if k not in ("seconds", "threads")}   # the same estimate
        assert_tails(tails, y, keep)
        first = np.sort(y[: rest.CHUNK_SIZE])
        assert tails["median"] == first[first.size // 2]
    # a range's tails: its own contributions only, the median of its first chunk
    part = rest.integrate_chunks("gaussian", technique, n, 2, 4, seed=3, case_id=7, replica=2, threads=2,
                                 tail_keep=keep, tail_median=True)["tails"]
    assert_tails(part, y[2 * rest.CHUNK_SIZE: 4 * rest.CHUNK_SIZE], keep)


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match="one-dimensional"):
        rest.value_tails(np.zeros((2, 2)), 3)
    with pytest.raises(ValueError, match="non-negative"):
        rest.value_tails(np.zeros(3), -1)
    with pytest.raises(ValueError, match="at least one"):
        rest.merge_tails([], 3)
    with pytest.raises(ValueError, match="non-negative"):
        rest.integrate_chunks("gaussian", "uniform", 10, 0, 1, tail_keep=-2)
