"""The suite runner and its storage, run for real: subprocesses killed with SIGKILL, a real
SQLite file, a real Dask LocalCluster."""
from __future__ import annotations

import json
import math
import os
import random
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

import harness
from harness.suite.parse import load_suite
from harness.suite.run import run_suite

HARNESS = str(Path(sys.executable).with_name("harness"))

# A suite of several seconds: long enough for 20 kills to land mid-run (each run is killed up to
# 0.4 s after its first commit), short enough for CI: 2^28 samples, more on a machine where
# they take under LEAST_SECONDS (sized_suite).  2^28 took about 14 s on two threads on
# 2026-12-04, since the trimmed-logistic and MIS cases ran 8x and 1.6x faster in vector lanes
# and 2^25 had left too little work for 20 kills.
SUITE = """
[suite]
name = "killme"
seed = 3
samples = {samples}
batches = 16
replicas = 8
budgets = [262144, 1048576, 4194304]

[[case]]
integrand = "gaussian16"
techniques = ["uniform", "uniform/sobol"]

[[case]]
integrand = "peak"
techniques = ["importance:trimmed_logistic"]

[[case]]
integrand = "ggx_lobe"
techniques = ["mis_balance:cosine_hemisphere+ggx"]
"""


def units_table(db: Path) -> list[tuple]:
    con = sqlite3.connect(db)
    try:
        return sorted(con.execute("SELECT case_key, stream, budget, replica, chunk_begin, chunk_end, kind, "
                                  "payload FROM units").fetchall())
    finally:
        con.close()


def stored_count(db: Path) -> int:
    """Unit rows so far; 0 while the file or its schema does not exist yet (a run starting)."""
    if not db.exists():
        return 0
    con = sqlite3.connect(db)
    try:
        return con.execute("SELECT COUNT(*) FROM units").fetchone()[0]
    except sqlite3.OperationalError:
        return 0
    finally:
        con.close()


def without_timing(rows: list[tuple]) -> list[tuple]:
    """Unit rows with the payloads' wall times removed (each run measures its own)."""
    return [(*r[:7], {k: v for k, v in json.loads(r[7]).items() if k not in ("seconds", "threads", "clock")})
            for r in rows]


def measurements(db: Path):
    df = harness.load(db)
    return df.drop(columns=["detail"]).sort_values(["case_key", "measurement"]).reset_index(drop=True)


LEAST_SECONDS = 12.0   # the suite's uninterrupted run on two threads, at least, for the kills


@pytest.fixture(scope="module")
def sized_suite(tmp_path_factory) -> tuple[Path, Path, int]:
    """(the suite file, its uninterrupted run's database, its samples): 2^28 samples, scaled by
    powers of two until that run lasts LEAST_SECONDS on this machine (2^28 took about 14 s on
    2026-12-04's), so that a faster machine or core still leaves the kills work to interrupt."""
    samples = 2**28
    while True:
        d = tmp_path_factory.mktemp("suite")
        (d / "killme.toml").write_text(SUITE.format(samples=samples))
        start = time.monotonic()
        r = subprocess.run([HARNESS, "run", str(d / "killme.toml"), "--db", str(d / "ref.sqlite"),
                            "--threads", "2"], capture_output=True, text=True, timeout=600)
        assert r.returncode == 0, r.stdout + r.stderr
        seconds = time.monotonic() - start
        if seconds >= LEAST_SECONDS:
            return d / "killme.toml", d / "ref.sqlite", samples
        samples *= 2 ** math.ceil(math.log2(LEAST_SECONDS / seconds))


@pytest.fixture(scope="module")
def suite_file(sized_suite) -> Path:
    return sized_suite[0]


@pytest.fixture(scope="module")
def reference_db(sized_suite) -> Path:
    return sized_suite[1]


@pytest.fixture(scope="module")
def suite_samples(sized_suite) -> int:
    return sized_suite[2]


def test_a_finished_suite_reruns_without_computing(suite_file, reference_db, tmp_path):
    db = tmp_path / "copy.sqlite"
    db.write_bytes(reference_db.read_bytes())
    before = units_table(db)
    summary = run_suite(load_suite(suite_file), db, threads=2)
    assert summary.units_run == 0 and summary.units_planned == len(before)
    assert units_table(db) == before


@pytest.mark.slow
def test_kill_minus_nine_at_random_points_then_resume(suite_file, reference_db, tmp_path):
    """20 runs killed with SIGKILL at random moments (seeded), each resuming the last; the
    final state must equal an uninterrupted run's bit for bit: no duplicate, lost or torn
    unit rows, the same measurements."""
    db = tmp_path / "killed.sqlite"
    rng = random.Random(20261123)
    full = len(units_table(reference_db))
    kills = 0
    while kills < 20:
        before = stored_count(db)
        proc = subprocess.Popen([HARNESS, "run", str(suite_file), "--db", str(db), "--threads", "2"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        # kill at a random moment after this run's first commit (whatever start-up costs on this
        # machine): each run then does at most ~0.5 s of the suite's 12 s or more of work
        deadline = time.monotonic() + 30
        while proc.poll() is None and time.monotonic() < deadline:
            if stored_count(db) > before:
                break
            time.sleep(0.02)
        time.sleep(rng.uniform(0.0, 0.4))
        if proc.poll() is not None:
            break  # finished before the kill: nothing left to interrupt
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        kills += 1
        rows = units_table(db) if db.exists() else []
        keys = [r[:7] for r in rows]
        assert len(keys) == len(set(keys)), "duplicate unit rows"
        assert all(json.loads(r[7]) for r in rows), "a torn payload"
        assert len(rows) <= full
    assert kills == 20, f"only {kills} runs were interrupted: the suite finished too fast to test resumption"
    r = subprocess.run([HARNESS, "run", str(suite_file), "--db", str(db), "--threads", "2"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert without_timing(units_table(db)) == without_timing(units_table(reference_db))
    a, b = measurements(db), measurements(reference_db)
    cols = ["case_key", "measurement", "value", "lo", "hi", "n", "pvalue", "verdict"]
    # timing-based: equal only by chance
    stat = ~a["measurement"].isin(["log10_efficiency", "log10_efficiency_clock", "efficiency_ratio"])
    assert a.loc[stat, cols].equals(b.loc[stat, cols])


@pytest.mark.slow
def test_dask_local_cluster_gives_bitwise_the_same_units(suite_file, reference_db, tmp_path):
    db = tmp_path / "dask.sqlite"
    r = subprocess.run([HARNESS, "run", str(suite_file), "--db", str(db), "--dask", "local",
                        "--threads", "2"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert without_timing(units_table(db)) == without_timing(units_table(reference_db))


def test_load_gives_each_measurement_with_uncertainty_and_n(reference_db, suite_samples):
    df = harness.load(reference_db)
    assert {"integrand", "technique", "measurement", "value", "lo", "hi", "n", "pvalue", "alpha",
            "verdict"} <= set(df)
    assert set(df["measurement"]) == {"bias", "variance", "convergence_slope", "log10_efficiency",
                                      "log10_efficiency_clock", "efficiency_ratio", "rmse"}
    bias = df[df["measurement"] == "bias"]
    assert len(bias) == 4 and (bias["n"] == suite_samples).all() and (bias["lo"] < bias["hi"]).all()
    assert set(bias["verdict"]) == {"unbiased"}
    slope = df[(df["measurement"] == "convergence_slope") & (df["technique"] == "uniform")].iloc[0]
    assert slope["lo"] < -0.5 < slope["hi"]


def test_show_prints_the_stored_measurements(reference_db):
    r = subprocess.run([HARNESS, "show", "--db", str(reference_db)], capture_output=True, text=True,
                       timeout=60)
    assert (r.returncode == 0 and "convergence_slope" in r.stdout
            and "mis_balance:cosine_hemisphere+ggx" in r.stdout)
    r = subprocess.run([HARNESS, "show", "--db", "/nonexistent/x.sqlite"], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 2 and "no results database" in r.stderr


def test_a_precision_target_doubles_samples_until_reached_and_spends_alpha(tmp_path):
    """gaussian/uniform has sigma ~0.2: a half-width of 1e-3 at alpha/looks needs ~1e6
    samples, reached at an intermediate look; the p-value is multiplied by the looks."""
    p = tmp_path / "t.toml"
    p.write_text('[suite]\nname = "t"\nsamples = 16384\nbatches = 32\nmeasurements = ["bias"]\n\n'
                 '[[case]]\nintegrand = "gaussian"\ntechniques = ["uniform"]\ntarget = 1e-3\n'
                 'max_samples = 67108864\n')
    suite = load_suite(p)
    case = suite.cases[0]
    assert case.looks == 13  # 16384 * 2^k <= 2^26 for k = 0..12
    summary = run_suite(suite, tmp_path / "t.sqlite", threads=2)
    r = summary["estimator"].results[0]
    assert 0 < r.look < case.looks - 1 and r.target_half_width <= 1e-3
    assert r.bias.n == 16384 << r.look
    raw = 2 * stats.t.sf(abs(r.bias.statistic), r.bias.df)
    assert r.bias.pvalue == pytest.approx(min(1.0, case.looks * raw))  # alpha spent over the looks
    again = run_suite(suite, tmp_path / "t.sqlite", threads=2)
    assert again.units_run == 0 and again["estimator"].results[0].look == r.look
    row = harness.load(tmp_path / "t.sqlite").set_index("measurement").loc["target_half_width"]
    assert row["verdict"] == "reached" and row["n"] == r.bias.n


def test_an_infinite_variance_case_has_efficiency_zero_and_no_interval(tmp_path):
    """singularity/uniform (infinite variance, analytic) as the baseline of nothing and as
    compared with a finite one: its stored 1/(V·T) says "infinite variance", has no interval,
    and the CLI table says so instead of printing an interval from a finite sample's spread."""
    p = tmp_path / "inf.toml"
    p.write_text('[suite]\nname = "inf"\nsamples = 65536\nbatches = 16\nreplicas = 8\n'
                 'measurements = ["bias", "efficiency"]\n\n'
                 '[[case]]\nintegrand = "singularity"\ntechniques = ["uniform"]\n')
    summary = run_suite(load_suite(p), tmp_path / "inf.sqlite", threads=2)
    e = summary["estimator"].results[0].efficiency
    assert e.verdict == "infinite variance" and e.value == 0
    row = harness.load(tmp_path / "inf.sqlite").set_index("measurement").loc["log10_efficiency"]
    assert row["verdict"] == "infinite variance" and row["value"] == -math.inf
    assert math.isnan(row["lo"]) and math.isnan(row["hi"])
    assert "efficiency 0, no interval: infinite variance (analytic)" in summary["estimator"].text


EFFICIENCY_SUITE = """\
[suite]
name = "eff"
samples = 65536
batches = 16
replicas = 8
measurements = {measurements}

[[case]]
integrand = "gaussian"
techniques = ["uniform", "importance:linear"]
"""


def _unit_payloads(db: Path) -> list[tuple[int, int, str, dict, str]]:
    """(stream, budget, kind, payload, case key) of every stored unit."""
    con = sqlite3.connect(db)
    try:
        return [(s, b, k, json.loads(p), c) for s, b, k, p, c in
                con.execute("SELECT stream, budget, kind, payload, case_key FROM units").fetchall()]
    finally:
        con.close()


def test_efficiency_has_a_figure_in_reference_clock_ticks_stored_and_resumed(tmp_path):
    """A suite that measures efficiency reads the reference clock beside each replica of its
    largest budget (and nowhere else); each case gets log10 1/(V·T_clock) with an interval,
    equal to log10 1/(V·T) times the run's seconds per clock tick; a rerun computes nothing and
    stores the same figures."""
    p = tmp_path / "eff.toml"
    p.write_text(EFFICIENCY_SUITE.format(measurements='["bias", "efficiency"]'))
    db = tmp_path / "eff.sqlite"
    summary = run_suite(load_suite(p), db, threads=2)
    units = _unit_payloads(db)
    timed = [u for u in units if "clock" in u[3]]
    assert len(timed) == 2 * 8 and {u[:3] for u in timed} == {(5, 4096, "state")}
    assert all(math.isfinite(u[3]["clock"]) and u[3]["clock"] > 0 for u in timed)
    assert not any("clock" in u[3] for u in units if (u[0], u[1]) != (5, 4096))
    df = harness.load(db).set_index(["technique", "measurement"])
    for technique, result in zip(["uniform", "importance:linear"], summary["estimator"].results):
        k, e = df.loc[(technique, "log10_efficiency_clock")], df.loc[(technique, "log10_efficiency")]
        assert all(math.isfinite(k[c]) for c in ("value", "lo", "hi")) and k["lo"] < k["value"] < k["hi"]
        dk, de = json.loads(k["detail"]), json.loads(e["detail"])
        assert dk["interval"].startswith("across runs") and de["interval"] == "this run's machine state"
        assert dk["clock"] == harness.stats.CLOCK and k["n"] == e["n"] == 8 * 4096
        key = df.loc[(technique, "log10_efficiency"), "case_key"]
        run_clock = float(np.median([u[3]["clock"] for u in timed if u[4] == key]))   # its median reading
        assert k["value"] == pytest.approx(e["value"] + math.log10(run_clock), abs=1e-12)
        assert dk["clock_seconds"] == pytest.approx(run_clock, rel=1e-12)
        assert dk["clock_ticks"] == pytest.approx(de["seconds"] / run_clock, rel=1e-12)
        assert result.clock_efficiency.log10_value == k["value"]
    assert "log10 1/(V·T_clock) [95% CI]" in summary["estimator"].text
    assert "this run's machine state only" in summary["estimator"].text
    again = run_suite(load_suite(p), db, threads=2)
    assert again.units_run == 0
    df2 = harness.load(db).set_index(["technique", "measurement"])
    assert df2.loc[:, ["value", "lo", "hi"]].equals(df.loc[:, ["value", "lo", "hi"]])


def test_only_suites_that_measure_efficiency_read_the_clock(tmp_path):
    p = tmp_path / "bias.toml"
    p.write_text(EFFICIENCY_SUITE.format(measurements='["bias", "convergence"]'))
    run_suite(load_suite(p), tmp_path / "b.sqlite", threads=2)
    assert not any("clock" in u[3] for u in _unit_payloads(tmp_path / "b.sqlite"))
    assert "log10_efficiency_clock" not in set(harness.load(tmp_path / "b.sqlite")["measurement"])


def test_units_without_clock_readings_give_the_figure_in_seconds_only(tmp_path):
    """Units stored without the clock's readings (written by a harness before the clock: such a
    database's keys no longer match, so this is a hand-made one) are read, not crashed on: the
    efficiency in 1/s, no figure in clock ticks, and a note that says so."""
    p = tmp_path / "eff.toml"
    p.write_text(EFFICIENCY_SUITE.format(measurements='["efficiency"]'))
    db = tmp_path / "eff.sqlite"
    run_suite(load_suite(p), db, threads=2)
    con = sqlite3.connect(db)
    con.execute("UPDATE units SET payload = json_remove(payload, '$.clock')")
    con.commit()
    con.close()
    again = run_suite(load_suite(p), db, threads=2)
    assert again.units_run == 0
    r = again["estimator"].results[0]
    assert r.efficiency is not None and r.clock_efficiency is None
    assert "no reference-clock readings stored" in again["estimator"].text
    assert set(harness.load(db)["measurement"]) == {"log10_efficiency", "efficiency_ratio"}


def test_the_case_key_changes_with_the_reference_clock(tmp_path, monkeypatch):
    """Stored times in clock ticks belong to one clock: another clock makes them stale."""
    from harness.suite import plan

    p = tmp_path / "eff.toml"
    p.write_text(EFFICIENCY_SUITE.format(measurements='["efficiency"]'))
    suite = load_suite(p)
    before = plan.case_key(suite, suite.cases[0])
    monkeypatch.setattr(plan, "CLOCK", {**plan.CLOCK, "samples": 2 * plan.CLOCK["samples"]})
    assert plan.case_key(suite, suite.cases[0]) != before


def test_sampler_checks_run_from_suites_and_resume(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text('[suite]\nname = "s"\nsamples = 100000\n\n'
                 '[[sampler]]\nname = "ggx"\nparams = { alpha = 0.05 }\n\n'
                 '[[sampler]]\nname = "power"\nparams = { k = -0.75 }\n')
    suite = load_suite(p)
    first = run_suite(suite, tmp_path / "s.sqlite", threads=2)
    assert (first.units_run == 2
            and [r.case.label for r in first["sampler"].results] == ["ggx(alpha=0.05)", "power(k=-0.75)"])
    assert all(c["passed"] for r in first["sampler"].results for c in r.checks.values())
    again = run_suite(suite, tmp_path / "s.sqlite", threads=2)
    assert again.units_run == 0 and again["sampler"].results[0].checks == first["sampler"].results[0].checks
    df = harness.load(tmp_path / "s.sqlite")
    assert (set(df["measurement"]) == {"chi_square"} and set(df["verdict"]) == {"passed"}
            and (df["n"] == 100000).all())
