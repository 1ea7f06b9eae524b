"""The plan (harness.suite.plan): the units a suite's measurements need and nothing else, their
count from the batch and chunk arithmetic, and keys that are stable and distinct.

Deterministic: planning draws no random numbers, so nothing here has a seed."""
from __future__ import annotations

from pathlib import Path

import pytest

import reference_estimators as rest

from harness.suite.estimators import EstimatorKind
from harness.suite.parse import Suite, load_suite
from harness.suite.plan import (
    UNIT_CHUNKS,
    Unit,
    bias_budget,
    bias_stream,
    case_key,
    convergence_budgets,
    estimator_units,
    plan,
    tail_keeps,
    units_per_estimate,
)

CHUNK = rest.CHUNK_SIZE   # 65 536 contributions per core chunk


def suite_of(tmp_path: Path, head: str, cases: str, name: str = "s.toml") -> Suite:
    path = tmp_path / name
    path.write_text(f"[suite]\n{head}\n\n{cases}", encoding="utf-8")
    return load_suite(path)


def case(integrand: str, technique: str, extra: str = "") -> str:
    return f'[[case]]\nintegrand = "{integrand}"\ntechniques = ["{technique}"]\n{extra}\n'


def only(suite: Suite, **kw) -> list[Unit]:
    (units,) = plan(suite, **kw).values()
    return units


def chunk_ranges(units: list[Unit]) -> list[tuple[int, int]]:
    return [(u.chunk_begin, u.chunk_end) for u in units]


# --- what each measurement needs ---------------------------------------------------------------
def test_bias_plans_every_batch_in_unit_sized_chunk_ranges_whose_units_carry_the_tails(tmp_path):
    per_batch = 70 * CHUNK   # 70 chunks: units of 32, 32 and 6 chunks
    suite = suite_of(tmp_path, f'samples = {8 * per_batch}\nbatches = 8\nmeasurements = ["bias"]',
                     case("gaussian", "uniform"))
    units = only(suite)
    key = case_key(suite, suite.cases[0])
    assert {u.kind for u in units} == {"state"}   # no second pass over the contributions
    assert bias_budget(suite, suite.cases[0]) == per_batch
    assert {(u.case_key, u.stream, u.budget) for u in units} == {(key, 0, per_batch)}
    for k in range(8):
        assert chunk_ranges([u for u in units if u.replica == k]) == [(0, 32), (32, 64), (64, 70)], k
    assert len(units) == 8 * 3 == 8 * units_per_estimate(per_batch)
    # each unit keeps twice its share of the tail sample's order statistics, plus 32
    keep, part_keep = tail_keeps(suite, suite.cases[0])
    assert keep == int((8 * per_batch) ** 0.5) and part_keep == -(-2 * keep // 24) + 32
    jobs = EstimatorKind(suite).plan(None)
    assert [j.unit for j in jobs] == sorted(units, key=lambda u: (u.stream, u.replica, u.chunk_begin))
    assert {j.tail_keep for j in jobs} == {part_keep}
    # where the units' tails cannot give the sample exactly, one unit reads the batches again
    again = estimator_units(suite, suite.cases[0], full_tail=True)
    assert again[-1] == Unit(key, 0, per_batch, 0, 0, 0, "tail") and again[:-1] == units


def test_variance_without_bias_plans_the_batches_but_no_tail(tmp_path):
    suite = suite_of(tmp_path, 'samples = 4096\nbatches = 16\nmeasurements = ["variance"]',
                     case("gaussian", "uniform"))
    units = only(suite)
    assert {u.kind for u in units} == {"state"} and sorted(u.replica for u in units) == list(range(16))
    assert {(u.stream, u.budget, u.chunk_begin, u.chunk_end) for u in units} == {(0, 256, 0, 1)}


@pytest.mark.parametrize("per_batch, units_per_batch", [
    (1, 1), (CHUNK, 1), (CHUNK + 1, 1), (UNIT_CHUNKS * CHUNK, 1), (UNIT_CHUNKS * CHUNK + 1, 2),
    (3 * UNIT_CHUNKS * CHUNK, 3)])
def test_unit_count_is_batches_times_chunks_per_unit(tmp_path, per_batch, units_per_batch):
    suite = suite_of(tmp_path, f'samples = {8 * per_batch}\nbatches = 8\nmeasurements = ["variance"]',
                     case("gaussian", "uniform"))
    units = only(suite)
    chunks = -(-per_batch // CHUNK)
    assert units_per_batch == -(-chunks // UNIT_CHUNKS) and len(units) == 8 * units_per_batch
    assert max(u.chunk_end for u in units) == chunks


def test_convergence_plans_every_replica_at_every_budget(tmp_path):
    budgets = [1024, 4096, 2 * UNIT_CHUNKS * CHUNK]   # the largest budget takes two units per replica
    suite = suite_of(tmp_path, f'samples = 1024\nbatches = 8\nreplicas = 5\nbudgets = {budgets}\n'
                     'measurements = ["convergence"]', case("gaussian", "uniform"))
    units = only(suite)
    assert convergence_budgets(suite, suite.cases[0]) == budgets
    assert {u.kind for u in units} == {"state"}
    for i, b in enumerate(budgets):
        at = [u for u in units if u.stream == 1 + i]
        assert {u.budget for u in at} == {b} and sorted({u.replica for u in at}) == list(range(5))
    assert len(units) == 5 * (1 + 1 + 2)


def test_error_vs_time_needs_every_budget_and_efficiency_alone_only_the_top_one(tmp_path):
    head = 'samples = 1024\nbatches = 8\nreplicas = 4\nbudgets = [256, 1024, 4096]'
    cases = (case("step", "uniform", 'measurements = ["efficiency"]') +
             case("step", "rejection", 'measurements = ["error_vs_time"]') +
             case("peak", "uniform", 'measurements = ["convergence", "efficiency", "error_vs_time"]'))
    efficiency, error_vs_time, shared = plan(suite_of(tmp_path, head, cases)).values()
    assert {(u.stream, u.budget) for u in efficiency} == {(3, 4096)} and len(efficiency) == 4
    every = {(1, 256), (2, 1024), (3, 4096)}
    assert {(u.stream, u.budget) for u in error_vs_time} == every and len(error_vs_time) == 3 * 4
    assert {(u.stream, u.budget) for u in shared} == every and len(shared) == 3 * 4   # shared, not doubled


def test_default_budgets_are_five_factors_of_four_below_samples_over_16(tmp_path):
    suite = suite_of(tmp_path, 'samples = 1048576\nmeasurements = ["convergence"]',
                     case("gaussian", "uniform"))
    assert convergence_budgets(suite, suite.cases[0]) == [256, 1024, 4096, 16384, 65536]
    small = suite_of(tmp_path, 'samples = 8192\nmeasurements = ["convergence"]', case("gaussian", "uniform"))
    assert convergence_budgets(small, small.cases[0]) == [16, 16, 32, 128, 512]   # none below 16


def test_a_sampler_check_is_one_unit_per_measurement(tmp_path):
    suite = suite_of(tmp_path, "samples = 5000",
                     '[[sampler]]\nname = "ggx"\nmeasurements = ["chi_square", "mcmc"]\n\n'
                     '[[sampler]]\nname = "exponential"\n')
    ggx, exponential = plan(suite).values()
    assert [(u.stream, u.budget, u.replica, u.chunk_begin, u.chunk_end, u.kind) for u in ggx] == [
        (0, 5000, 0, 0, 0, "chi_square"), (0, 5000, 0, 0, 0, "mcmc")]
    assert [u.kind for u in exponential] == ["chi_square"] and ggx[0].case_key != exponential[0].case_key


# --- keys --------------------------------------------------------------------------------------
CASES = case("gaussian", "uniform") + case("gaussian", "uniform/sobol") + case("gaussian", "uniform")
HEAD = 'samples = 4096\nbatches = 8\nreplicas = 4\nbudgets = [64, 256, 1024]'


def test_keys_are_stable_across_calls_and_parses(tmp_path):
    suite = suite_of(tmp_path, HEAD, CASES)
    first = plan(suite)
    assert plan(suite) == first and plan(suite_of(tmp_path, HEAD, CASES, "copy.toml")) == first
    assert list(first)[:3] == [case_key(suite, c) for c in suite.cases]   # in the suite's order
    assert all(u.case_key == k for k, units in first.items() for u in units)


def test_keys_differ_across_cases_positions_and_seeds(tmp_path):
    suite = suite_of(tmp_path, HEAD, CASES)
    keys = list(plan(suite))
    assert len(set(keys)) == 3   # the same integrand and technique at another position: other streams
    reseeded = suite_of(tmp_path, HEAD + "\nseed = 1", CASES)
    assert not set(keys) & set(plan(reseeded))
    units = [u for us in plan(suite).values() for u in us]
    assert len(units) == len(set(units))


def test_a_look_moves_only_the_bias_batches_to_their_own_stream_and_budget(tmp_path):
    extra = 'target = 1e-3\nmax_samples = 16384\nmeasurements = ["bias", "convergence"]'
    suite = suite_of(tmp_path, HEAD, case("gaussian", "uniform", extra) + case("step", "uniform"))
    target, other = suite.cases
    key = case_key(suite, target)
    before = plan(suite)
    assert plan(suite, looks={key: 0}) == before
    after = plan(suite, looks={key: 2})
    assert after[case_key(suite, other)] == before[case_key(suite, other)]
    moved = [u for u in after[key] if u.stream not in (1, 2, 3)]
    kept = [u for u in after[key] if u.stream in (1, 2, 3)]
    assert kept == [u for u in before[key] if u.stream in (1, 2, 3)]   # convergence is not a look's
    budget = bias_budget(suite, target, 2)
    assert budget == (4096 << 2) // 8 and bias_stream(2) not in (0, 1, 2, 3)
    assert {(u.stream, u.budget) for u in moved} == {(bias_stream(2), budget)}
    assert {u.kind for u in moved} == {"state"} and len(moved) == 8
