"""Nothing stale, nothing mixed: a suite edited between runs on one database measures exactly
what a fresh run of the edited suite measures (stored units of the earlier version that share a
case's key — renders at another spp, other budgets or replica counts, the tail sample of another
sample count — are never mixed in), and load/show/report list the latest run's cases only (a
removed case, measurement or sampler is gone; the earlier run stays as history); harness gc
prunes what the latest run does not need without changing a number; a finished render suite
reruns bitwise; a deleted or damaged image or cached reference is reported with its path and
computed again."""
from __future__ import annotations

import json
import math
import textwrap

import pytest

import harness
from harness.suite.gc import collect_garbage
from harness.suite.parse import load_suite
from harness.suite.run import run_suite
from reports import load_results

TIMED = {"log10_efficiency", "log10_efficiency_clock", "efficiency_ratio", "efficiency",
         "equal_time_relmse"}
TIMING_DETAIL = {"seconds", "seconds_se", "error_vs_time", "rows", "log10_value", "clock_ticks",
                 "clock_seconds"}


def _untimed(d):
    """A stored detail without its wall-time fields, at any depth."""
    if isinstance(d, dict):
        return {k: _untimed(v) for k, v in d.items() if k not in TIMING_DETAIL}
    return [_untimed(v) for v in d] if isinstance(d, list) else d


def _measured(db, **which) -> list[tuple]:
    """(integrand, technique, measurement, value, lo, hi, n, pvalue, verdict, detail) of every
    row ``harness.load`` returns, in its order, except those that depend on wall times (and
    timing fields left out of the details)."""
    return [(r["integrand"], r["technique"], r["measurement"])
            + tuple("nan" if isinstance(v, float) and math.isnan(v) else v
                    for v in (r["value"], r["lo"], r["hi"], r["n"], r["pvalue"], r["verdict"]))
            + (repr(_untimed(json.loads(r["detail"]))),)
            for r in harness.load(db, **which).to_dict("records") if r["measurement"] not in TIMED]


def _edited_equals_fresh(tmp_path, before: str, after: str) -> None:
    """Runs ``before`` then ``after`` on one database and ``after`` on a fresh one: the
    latest run's measurements are equal (bitwise, timing aside), row for row; ``harness gc``
    then prunes the edited database, and a rerun computes nothing and changes nothing."""
    first, second = tmp_path / "before.toml", tmp_path / "after.toml"
    first.write_text(textwrap.dedent(before))
    second.write_text(textwrap.dedent(after))
    db, fresh_db = tmp_path / "edited" / "r.sqlite", tmp_path / "fresh" / "r.sqlite"
    earlier = run_suite(load_suite(first), db, threads=2)
    edited = run_suite(load_suite(second), db, threads=2)
    fresh = run_suite(load_suite(second), fresh_db, threads=2)
    assert edited.units_run < fresh.units_run  # the edit reused what still applies
    assert _measured(db) == _measured(fresh_db)
    history = harness.load(db, all_runs=True)
    assert sorted(set(history["run"])) == [earlier.run, edited.run]
    assert len(history) == len(harness.load(db, run=earlier.run)) + len(harness.load(db))
    shown = [list(load_results(d).measurements["case_key"]) for d in (db, fresh_db)]
    assert shown[0] == shown[1]

    removed = collect_garbage(db)
    assert removed.units > 0 and collect_garbage(db).units == 0
    again = run_suite(load_suite(second), db, threads=2)
    assert again.units_run == 0 and _measured(db) == _measured(fresh_db)


def test_a_removed_case_measurement_and_sampler_leave_no_stale_rows(tmp_path):
    """The issue's case: a suite loses a technique, a measurement and a sampler; load, show and
    report then list what a fresh run of the edited suite lists, not 11 cases where it has 6."""
    base = """        [suite]
        name = "removed"
        samples = 65536
        batches = 16
        replicas = 4
        budgets = [1024, 4096, 16384]
        measurements = {measurements}

        [[case]]
        integrand = "gaussian"
        techniques = {techniques}

        [[case]]
        integrand = "singularity"
        techniques = ["uniform", "importance:power"]
        {sampler}
        [[sampler]]
        name = "cosine_hemisphere"
        samples = 20000
        """
    extra = """
        [[sampler]]
        name = "linear"
        samples = 20000
        """
    _edited_equals_fresh(
        tmp_path,
        base.format(measurements='["bias", "variance", "convergence"]',
                    techniques='["uniform", "uniform/stratified"]', sampler=extra),
        base.format(measurements='["bias", "convergence"]', techniques='["uniform"]', sampler=""))


def test_samples_edited_use_the_tail_sample_of_the_new_count(tmp_path):
    base = """\
        [suite]
        name = "edit"
        samples = {samples}
        batches = 16
        replicas = 4
        budgets = [1024, 4096, 16384]
        measurements = ["bias", "variance", "convergence"]

        [[case]]
        integrand = "singularity"
        techniques = ["uniform", "importance:power"]
        """
    _edited_equals_fresh(tmp_path, base.format(samples=2**16), base.format(samples=2**17))


def test_render_spp_budgets_and_replicas_edited_measure_only_the_new_renders(tmp_path):
    base = """\
        [suite]
        name = "edit-renders"

        [[render]]
        adapter = "mitsuba"
        scene = "furnace"
        integrator = "path"
        variant = "scalar_rgb"
        spp = {spp}
        replicas = {replicas}
        budgets = {budgets}
        """
    _edited_equals_fresh(tmp_path, base.format(spp=4, replicas=5, budgets=[1, 2, 4]),
                         base.format(spp=8, replicas=4, budgets=[1, 4, 8]))


CORNELL = """\
[suite]
name = "{name}"

[[render]]
adapter = "mitsuba"
scene = "cornell"
integrator = "path"
max_depth = 2
variant = "scalar_rgb"
spp = 2
replicas = 4
budgets = [1, 2, 4]
reference_spp = 64
"""  # a rendered reference (8 parts of 8 spp) and deterministic scalar renders


def test_a_finished_render_suite_reruns_bitwise(tmp_path):
    """The first run measures against the reference it just rendered; a rerun reads it back from
    the cache (lossless float64): both store bitwise the same numbers."""
    path = tmp_path / "r.toml"
    path.write_text(CORNELL.format(name="rerun"))
    db = tmp_path / "rerun.sqlite"
    first = run_suite(load_suite(path), db)
    once = _measured(db)
    again = run_suite(load_suite(path), db)
    assert first.units_run > 0 and again.units_run == 0
    assert _measured(db) == once


def test_a_deleted_or_damaged_image_is_reported_and_rendered_again(tmp_path):
    """A replica EXR deleted, another truncated, a third with one bit flipped, the cached
    reference's mean deleted: the rerun names each file, renders exactly those three again and
    rebuilds the reference from its stored parts, and stores the numbers of the first run
    (scalar renders are deterministic)."""
    path = tmp_path / "r.toml"
    path.write_text(CORNELL.format(name="damaged"))
    db = tmp_path / "d.sqlite"
    run_suite(load_suite(path), db)
    once = _measured(db)
    replicas = sorted((tmp_path / "d.sqlite.images").glob("*render-s0-b2-r*.exr"))
    replaced = replicas[2].read_bytes()
    replicas[2].write_bytes(replaced[:-1] + bytes([replaced[-1] ^ 1]))   # same size, other bytes
    replicas[0].unlink()
    replicas[1].write_bytes(replicas[1].read_bytes()[:100])
    next((tmp_path / "references").glob("*-parts.npy")).unlink()
    with pytest.warns(UserWarning) as caught:
        again = run_suite(load_suite(path), db)
    said = "\n".join(str(w.message) for w in caught)
    assert f"{replicas[0]}: image missing: rendering it again" in said
    assert f"{replicas[1]}: image damaged (100 bytes, " in said and "stored): rendering it again" in said
    assert f"{replicas[2]}: image damaged (not the bytes stored): rendering it again" in said
    assert "cached reference unreadable" in said
    assert again.units_run == 3
    assert _measured(db) == once
