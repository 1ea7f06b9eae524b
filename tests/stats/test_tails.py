"""harness.stats.tails: the kept extremes (ties at the maximum counted exactly across blocks),
the tail index, and the signatures of a clamped or a
truncated tail, told apart from estimators that are discrete by design."""
from __future__ import annotations

import math

import numpy as np
import pytest

import reference_estimators as rest

from harness.stats import TailSample
from harness.stats.tails import Side

RNG = np.random.default_rng(20261201)


def pareto(n: int, index: float, rng=RNG) -> np.ndarray:
    return rng.random(n) ** (-1 / index)


def sample_of(y: np.ndarray, blocks: int = 1, keep: int | None = None) -> TailSample:
    t = TailSample(keep or TailSample.for_count(y.size).keep)
    for part in np.array_split(y, blocks):
        t.add(part)
    return t


def test_ties_at_the_maximum_are_counted_across_blocks_beyond_what_is_kept():
    y = np.minimum(pareto(200_000, 1.5), 50.0)          # P(Y > 50) = 0.28 %: about 560 ties, keep 447
    whole, blocks = sample_of(y), sample_of(y, blocks=7)
    ties = int(np.count_nonzero(y == 50.0))
    center = whole.center
    assert ties > whole.keep
    assert whole.up.ties == blocks.up.ties == ties and whole.up.peak == pytest.approx(50.0 - center)
    below = np.sort(y[y < 50.0])[::-1][: whole.keep] - center
    np.testing.assert_array_equal(whole.up.below, below)
    np.testing.assert_array_equal(whole.upper[:3], [50.0 - center] * 3)


def test_state_round_trips_through_json_like_values():
    t = sample_of(np.minimum(pareto(10_000, 1.5), 20.0), blocks=3)
    back = TailSample.from_state(t.state())
    assert back.center == t.center and back.up.ties == t.up.ties
    np.testing.assert_array_equal(back.upper, t.upper)
    assert back.tail_index() == t.tail_index()


def test_a_clamp_is_an_atom_above_continuous_values():
    end = sample_of(np.minimum(pareto(100_000, 1.5), 1e3)).up.end(1e-3)
    assert end is not None and end.kind == "clamp" and end.count >= 2


@pytest.mark.parametrize("y", [
    (RNG.random(100_000) < 3e-4) / 3e-4,                       # a rare event: its atom is all it has
    np.where(RNG.random(100_000) < 0.5, 0.0, 2.0),             # hit or miss
    np.round(pareto(100_000, 1.5)),                            # discrete by design, no atom at the top
], ids=["rare event", "hit or miss", "integer-valued"])
def test_estimators_discrete_by_design_are_not_clamps(y):
    t = sample_of(y)
    for side in (t.up, t.down):
        end = side.end(1e-3)
        assert end is None or end.kind != "clamp"


def test_a_truncated_pareto_tail_is_seen_to_end():
    y = pareto(1_000_000, 1.5)
    y = np.where(y <= 1e3, y, 0.0)                                   # 32 of 1e6 values lost, on average
    end = sample_of(y, blocks=4).up.end(1e-3)
    assert end is not None and end.kind == "truncation" and end.value < 1e3 and end.pvalue < 1e-3


def test_a_continuing_pareto_tail_rarely_reads_as_truncated():
    """Under an exact Pareto tail the spacings' F test is exact: at level 0.05 it fires in
    about 5 % of samples (here at most 12 of 100, the binomial 0.999 quantile)."""
    rng = np.random.default_rng(7)
    fired = sum(sample_of(pareto(100_000, index, rng)).up.end(0.05) is not None
                for index in (1.1, 1.5, 2.0, 2.5) for _ in range(25))
    assert fired <= 12


def test_tail_index_reads_heavy_light_and_bounded_tails():
    assert 1.2 < sample_of(pareto(1_000_000, 1.5)).tail_index() < 1.9
    assert sample_of(RNG.normal(size=100_000)).tail_index() > 3
    assert sample_of(RNG.random(100_000)).tail_index() == math.inf


def test_a_side_without_values_has_no_end_and_an_infinite_index():
    s = Side(50)
    s.add(np.array([-1.0, 0.0]), center=0.0, upper=True)  # no deviation above the centre
    assert s.peak is None and s.end(0.01) is None and s.tail_index() == math.inf
    assert s.descending().size == 0


@pytest.mark.parametrize("kind", ["pareto", "clamped", "rare event", "lognormal"])
def test_the_units_tails_merge_to_what_one_pass_over_all_values_keeps(kind):
    """TailSample.from_parts (the bias test's state units' tails) equals TailSample.add over
    every value about the same centre, the first part's median."""
    rng = np.random.default_rng(11)
    y = {"pareto": rng.pareto(1.5, 400_000), "clamped": np.minimum(rng.pareto(1.5, 400_000), 50.0),
         "rare event": np.where(rng.random(400_000) < 1e-4, 1e4, 0.0),
         "lognormal": rng.lognormal(0.0, 3.0, 400_000)}[kind]
    blocks = np.array_split(y, 64)
    whole = TailSample.for_count(y.size)
    whole.center = rest.value_tails(blocks[0], 0, median=True)["median"]
    for b in blocks:
        whole.add(b)
    part_keep = -(-2 * whole.keep // 64) + 32
    parts = [rest.value_tails(b, part_keep, median=i == 0) for i, b in enumerate(blocks)]
    merged = TailSample.from_parts(parts, whole.keep, part_keep)
    assert merged is not None and merged.center == whole.center
    for ours, theirs in ((merged.up, whole.up), (merged.down, whole.down)):
        assert ours.peak == theirs.peak and ours.ties == theirs.ties
        np.testing.assert_array_equal(ours.below, theirs.below)


def test_parts_that_kept_too_few_are_not_merged_as_if_exact():
    """A part holding more than it kept above the union's keep-th value: None, not a wrong sample."""
    rng = np.random.default_rng(12)
    y = np.concatenate([rng.standard_normal(10_000) + 100.0, rng.standard_normal(10_000)])
    parts = [rest.value_tails(b, 40, median=i == 0) for i, b in enumerate(np.array_split(y, 2))]
    assert TailSample.from_parts(parts, 100, 40) is None   # the top 100 all lie in the first part
    parts = [rest.value_tails(b, 100, median=i == 0) for i, b in enumerate(np.array_split(y, 2))]
    assert TailSample.from_parts(parts, 100, 100) is not None
