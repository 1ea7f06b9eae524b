"""Runs are recorded, and every damaged or unusable database is one line naming the file.

The runs table (which suite revision each run measured; show --runs / --all / --run), a
database written before runs were recorded, and the fault matrix of the store: a --db whose
parent is a file, a read-only results folder (show and report read it unchanged), a garbage
and a truncated database (refused with the advice to repair,
repaired by ``harness gc --repair``, then rerun to the numbers of an undamaged run), a lock
held by another process, a full disk, an unreachable Dask scheduler; ``harness gc`` removes
half-written files and keeps what other databases in the folder may use.
"""
from __future__ import annotations

import ctypes
import os
import sqlite3
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

import harness
from harness.suite import plan
from harness.suite.gc import collect_garbage, repair
from harness.suite.parse import load_suite, loads_suite
from harness.suite.readers import runs
from harness.suite.run import run_suite
from harness.suite.store import Store, StoreError
from tests.suite.test_stale_results import _measured

HARNESS = str(Path(sys.executable).with_name("harness"))

SUITE = """\
[suite]
name = "tiny"
samples = 65536
batches = 16
replicas = 4
budgets = [1024, 4096, 16384]

[[case]]
integrand = "gaussian"
techniques = ["uniform"]

[[sampler]]
name = "linear"
samples = 20000
"""


def cli(*args: str, cwd: Path, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([HARNESS, *args], capture_output=True, text=True, cwd=cwd, timeout=timeout)


@pytest.fixture()
def suite_file(tmp_path) -> Path:
    path = tmp_path / "s.toml"
    path.write_text(SUITE)
    return path


def one_line_error(r: subprocess.CompletedProcess, *parts: str) -> None:
    """Exit 2, one line on stderr holding every part, no traceback."""
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    for p in parts:
        assert p in r.stderr, (p, r.stderr)


def test_each_run_is_recorded_with_the_suite_revision_it_measured(tmp_path, suite_file):
    db = tmp_path / "r.sqlite"
    first = run_suite(load_suite(suite_file), db, threads=2)
    suite_file.write_text(SUITE.replace("[[sampler]]", "[[sampler]]\nmeasurements = [\"chi_square\"]"))
    second = run_suite(load_suite(suite_file), db, threads=2)
    assert (first.run, second.run) == (1, 2)
    table = runs(db)
    assert list(table["run"]) == [1, 2] and list(table["suite"]) == ["tiny", "tiny"]
    assert table["revision"][0] != table["revision"][1] and all(table["finished"])
    assert list(table["units_run"]) == [first.units_run, second.units_run]

    shown = cli("show", "--db", str(db), "--runs", cwd=tmp_path)
    assert shown.returncode == 0 and str(suite_file) in shown.stdout
    latest, every = ([line for line in cli("show", "--db", str(db), *a, cwd=tmp_path).stdout.splitlines()
                      if not line.startswith("log10_efficiency:")]   # the note under the table
                     for a in ([], ["--all"]))
    assert "run" not in latest[0].split() and every[0].split()[0] == "run"
    assert len(every) == len(latest) * 2 - 1
    assert harness.load(db, run=1).equals(harness.load(db, all_runs=True).query("run == 1")
                                           .reset_index(drop=True))
    one_line_error(cli("show", "--db", str(db), "--run", "7", cwd=tmp_path), "has no run 7; its runs: 1, 2")
    one_line_error(cli("report", "--db", str(db), "--run", "7", cwd=tmp_path), "has no run 7")
    suite_name = harness.load(db)["suite"][0]    # an unknown suite had given an empty report, status 0
    for command in ("show", "report"):
        one_line_error(cli(command, "--db", str(db), "--suite", "nosuch", cwd=tmp_path),
                       f"has no suite 'nosuch'; its suites: {suite_name}")
    store = Store(db)      # a suite whose first run has not finished is known, with no rows yet
    try:
        store.start_run("fresh", "fresh.toml", "")
    finally:
        store.close()
    assert harness.load(db, suite="fresh").empty


def test_an_interrupted_run_leaves_the_last_finished_one_shown(tmp_path, suite_file):
    db = tmp_path / "r.sqlite"
    run_suite(load_suite(suite_file), db, threads=2)
    shown = _measured(db)
    store = Store(db)
    store.start_run("tiny", str(suite_file), "an edit that was interrupted")   # never finished
    store.close()
    assert _measured(db) == shown
    assert runs(db)["finished"].tolist()[-1] == ""


def test_a_database_from_before_runs_were_recorded_is_migrated(tmp_path, suite_file):
    db = tmp_path / "old.sqlite"
    con = sqlite3.connect(db)
    con.executescript("""
        CREATE TABLE measurements (case_key TEXT NOT NULL, suite TEXT NOT NULL, integrand TEXT NOT NULL,
            technique TEXT NOT NULL, measurement TEXT NOT NULL, value REAL, lo REAL, hi REAL, n INTEGER,
            pvalue REAL, alpha REAL, verdict TEXT, detail TEXT, UNIQUE (case_key, measurement));
        INSERT INTO measurements VALUES ('k', 'tiny', 'gaussian', 'uniform', 'bias', 0.5, 0, 1, 10, 0.5,
                                         0.01, 'unbiased', '{}');""")
    con.close()
    Store(db).close()
    old = harness.load(db)
    assert old[["run", "suite", "value"]].values.tolist() == [[1, "tiny", 0.5]]
    assert runs(db)["file"].tolist() == ["(before runs were recorded)"]
    again = run_suite(load_suite(suite_file), db, threads=2)
    assert again.run == 2 and set(harness.load(db)["run"]) == {2}
    assert len(harness.load(db, all_runs=True)) == len(harness.load(db)) + 1


def _as_if_unprivileged() -> None:
    """preexec_fn: a root process loses the capabilities that bypass file permissions
    (CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH), so a read-only folder is read-only to it too."""
    if os.geteuid() == 0:
        libc = ctypes.CDLL(None, use_errno=True)
        for cap in (1, 2):
            if libc.prctl(24, cap, 0, 0, 0) != 0:   # PR_CAPBSET_DROP
                raise OSError(ctypes.get_errno(), "prctl(PR_CAPBSET_DROP)")


def test_a_read_only_results_folder_is_read_and_a_run_there_is_one_line(tmp_path, suite_file):
    folder = tmp_path / "results"
    run_suite(load_suite(suite_file), folder / "r.sqlite", threads=2)
    before = {f.name: f.read_bytes() for f in folder.iterdir()}
    for f in folder.iterdir():
        f.chmod(0o444)
    folder.chmod(0o555)
    try:
        def cli_ro(*args: str) -> subprocess.CompletedProcess:
            return subprocess.run([HARNESS, *args], capture_output=True, text=True, cwd=tmp_path, timeout=120,
                                  preexec_fn=_as_if_unprivileged)

        shown = cli_ro("show", "--db", "results/r.sqlite")
        assert shown.returncode == 0 and "gaussian" in shown.stdout, shown.stderr
        report = cli_ro("report", "--db", "results/r.sqlite", "-o", "r.html")
        assert report.returncode == 0 and (tmp_path / "r.html").stat().st_size > 10_000, report.stderr
        one_line_error(cli_ro("run", str(suite_file), "--db", "results/r.sqlite"), "results/r.sqlite")
        assert {f.name: f.read_bytes() for f in folder.iterdir()} == before   # nothing changed
    finally:
        folder.chmod(0o755)


def test_a_db_whose_parent_is_a_file(tmp_path, suite_file):
    (tmp_path / "afile").write_text("")
    one_line_error(cli("run", str(suite_file), "--db", "afile/r.sqlite", cwd=tmp_path),
                   "afile/r.sqlite: cannot make its folder afile: a file, not a folder")


@pytest.mark.parametrize("damage", ["garbage", "truncated"])
def test_a_damaged_database_is_refused_repaired_and_rerun_to_the_same_numbers(tmp_path, suite_file, damage):
    good, db = tmp_path / "good.sqlite", tmp_path / "r.sqlite"
    run_suite(load_suite(suite_file), good, threads=2)
    run_suite(load_suite(suite_file), db, threads=2)
    store = Store(db)
    store.db.execute("PRAGMA wal_checkpoint(TRUNCATE)")   # everything in the main file
    store.close()
    data = db.read_bytes()
    db.write_bytes(bytes(b ^ 0x5A for b in data[:4096]) + data[4096:] if damage == "garbage"
                   else data[: len(data) // 3])
    advice = f"run `harness gc --repair --db {db.name}`"
    for args in (["run", str(suite_file)], ["show"], ["report"]):
        one_line_error(cli(*args, "--db", db.name, cwd=tmp_path), db.name, advice)
    r = cli("gc", "--repair", "--db", db.name, cwd=tmp_path)
    assert r.returncode == 0 and "damaged file moved to" in r.stdout, r.stdout + r.stderr
    assert len([p for p in tmp_path.glob("r.sqlite.damaged-*") if not p.name.endswith(("-wal", "-shm"))]) == 1
    assert repair(db).damaged is None   # the new one is intact
    rerun = run_suite(load_suite(suite_file), db, threads=2)
    assert rerun.units_run > 0 and _measured(db) == _measured(good)


def test_a_lock_held_by_another_process_is_one_line_after_the_wait(tmp_path, suite_file):
    db = tmp_path / "r.sqlite"
    run_suite(load_suite(suite_file), db, threads=2)
    holder = sqlite3.connect(db, isolation_level=None)
    holder.execute("BEGIN IMMEDIATE")   # another writer, mid-transaction
    try:
        start = time.perf_counter()
        r = cli("run", str(suite_file), "--db", db.name, "--wait", "1", cwd=tmp_path)
        one_line_error(r, "r.sqlite: locked by another process for 1 s", "use another --db")
        assert time.perf_counter() - start < 60
    finally:
        holder.execute("ROLLBACK")
        holder.close()
    assert cli("run", str(suite_file), "--db", db.name, cwd=tmp_path).returncode == 0


def test_a_full_disk_is_named_not_hidden_behind_a_commit_error(tmp_path, suite_file, monkeypatch):
    """SQLite's own limit on the file's pages stands in for a full disk: the same SQLITE_FULL."""
    real = sqlite3.connect

    def small(*args, **kwargs):
        con = real(*args, **kwargs)
        con.execute("PRAGMA max_page_count = 16")
        return con

    monkeypatch.setattr(sqlite3, "connect", small)
    with pytest.raises(StoreError, match=r"r\.sqlite: disk full \(database or disk is full\); free some "
                                         r"space and rerun to resume"):
        run_suite(load_suite(suite_file), tmp_path / "r.sqlite", threads=2)
    monkeypatch.undo()
    finished = run_suite(load_suite(suite_file), tmp_path / "r.sqlite", threads=2)   # resumes
    assert finished.units_run > 0 and _measured(tmp_path / "r.sqlite")


def test_an_unreachable_dask_scheduler_is_one_line(tmp_path, suite_file):
    r = cli("run", str(suite_file), "--db", "r.sqlite", "--dask", "tcp://127.0.0.1:9", cwd=tmp_path)
    one_line_error(r, "cannot reach the Dask scheduler at tcp://127.0.0.1:9")


def test_gc_removes_half_written_files_and_keeps_other_databases_references(tmp_path, suite_file):
    db = tmp_path / "r.sqlite"
    run_suite(load_suite(suite_file), db, threads=2)
    images, refs = tmp_path / "r.sqlite.images", tmp_path / "references"
    images.mkdir()
    refs.mkdir()
    (images / "x.exr.partial.exr").write_bytes(b"half")
    (refs / "0123456789abcdef01234567-parts.npy").write_bytes(b"another database's")
    dry = collect_garbage(db, dry_run=True)
    assert (dry.units, dry.files) == (0, 1) and (images / "x.exr.partial.exr").exists()
    done = collect_garbage(db)
    assert (done.units, done.files, done.references) == (0, 1, 0)
    assert not (images / "x.exr.partial.exr").exists()
    assert (refs / "0123456789abcdef01234567-parts.npy").exists()
    assert run_suite(load_suite(suite_file), db, threads=2).units_run == 0


def test_keys_follow_the_harness_code_but_seeds_do_not(monkeypatch):
    suite = loads_suite(textwrap.dedent("""\
        [[render]]
        adapter = "mitsuba"
        scene = "furnace"
        variant = "scalar_rgb"
        """))
    fingerprint = {"scene": "furnace"}
    unit = plan.Unit("k", 0, 4, 1, 0, 0, plan.RENDER)
    before = (plan.render_key(suite, fingerprint), plan.case_key(suite, loads_suite(SUITE).cases[0]),
              plan.render_stream(suite, fingerprint))
    seed = plan.render_seed(before[2], unit)
    monkeypatch.setattr(plan, "code_fingerprint", lambda *parts: "edited")
    after = (plan.render_key(suite, fingerprint), plan.case_key(suite, loads_suite(SUITE).cases[0]),
             plan.render_stream(suite, fingerprint))
    assert after[0] != before[0] and after[1] != before[1]   # edited code: nothing stored is reused
    assert after[2] == before[2] and plan.render_seed(after[2], unit) == seed   # the same random streams


def test_keys_follow_a_renderers_environment_but_seeds_do_not():
    """A core built on another machine (or another library version, a GL driver, an edited user
    renderer) re-renders, with the same seeds; a changed setting draws new ones."""
    suite = loads_suite('[[render]]\nadapter = "mitsuba"\nscene = "furnace"\nvariant = "scalar_rgb"\n')
    rc = suite.renders[0]
    here = {"scene": "furnace", "spp": 4, "environment": {"core": "a1", "mitsuba": "3.9.1"}}
    there = {**here, "environment": {"core": "b2", "mitsuba": "3.9.1"}}
    other = {**here, "spp": 8}
    assert plan.render_key(suite, here) != plan.render_key(suite, there)
    assert plan.reference_key(suite, rc, here) != plan.reference_key(suite, rc, there)
    assert plan.render_stream(suite, here) == plan.render_stream(suite, there)
    assert plan.reference_stream(suite, rc, here) == plan.reference_stream(suite, rc, there)
    assert plan.render_stream(suite, here) != plan.render_stream(suite, other)
    assert plan.reference_stream(suite, rc, here) != plan.reference_stream(suite, rc, other)


def test_a_suite_too_big_to_plan_is_refused_before_anything_is_made():
    start = time.perf_counter()
    with pytest.raises(harness.SuiteError, match=r"suite\.toml:3: samples: .*1e\+15 samples need "
                                                 r"[\d,]+ work units .* at most 1,048,576"):
        loads_suite("[suite]\nname = 'big'\nsamples = 1_000_000_000_000_000\nmeasurements = ['convergence']\n"
                    "[[case]]\nintegrand = 'gaussian'\ntechniques = ['uniform']\n")
    assert time.perf_counter() - start < 5
