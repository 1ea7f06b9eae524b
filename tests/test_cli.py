"""The command line and suite files, run as a user runs them: the real console script."""
from __future__ import annotations

import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import reference_estimators as rest

from harness import SuiteError, load_suite

HARNESS = str(Path(sys.executable).with_name("harness"))


def run(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([HARNESS, *args], capture_output=True, text=True, cwd=cwd, timeout=300)


def test_main_job_prints_every_case_of_the_default_suite(root, tmp_path):
    r = run("run", "suites/default.toml", "--db", str(tmp_path / "default.sqlite"), cwd=root)
    assert r.returncode == 0, r.stdout + r.stderr
    suite = load_suite(root / "suites" / "default.toml")
    lines = r.stdout.splitlines()
    header = next(line for line in lines if line.startswith("integrand"))
    assert suite.family_alpha == 0.01 / 5   # five families share the run's alpha
    assert "alpha 0.01 (0.002 for each of 5 families (estimator bias, estimator convergence, sampler " \
           "checks, render bias, render convergence), Holm within each)" in lines[0]
    for col in ("technique", "n", "estimate ± stderr", "exact", "t", "p", "bias (Holm, α=0.002)",
                "RMSE slope [95% CI]", "1/(V·T) vs baseline [95% CI]", "notes"):
        assert col in header, col
    rows = {}
    for case in suite.cases:
        match = [line for line in lines if line.split()[:2] == [case.integrand, case.technique]]
        assert match, case
        rows[(case.integrand, case.technique)] = match[0]
    total = len(suite.cases) + len(suite.samplers) + len(suite.renders)
    assert (f"{len(suite.cases)} cases, {len(suite.samplers)} sampler checks, {len(suite.renders)} render "
            "configurations in") in r.stdout and f"summary: {total} passed, 0 failed" in r.stdout
    assert "sampler checks" in r.stdout and all(sc.label in r.stdout for sc in suite.samplers)
    assert suite.renders and all(rc.label in r.stdout for rc in suite.renders)
    every = {(f.name, t) for f in rest.catalogue() for t in rest.techniques(f)}
    assert every <= set(rows)
    # the deliberately biased techniques are found, the others are not
    for (f, t), line in rows.items():
        planted = rest.technique(f, t).biased
        assert ("biased (expected)" in line) == planted, line
        assert " biased " not in line.replace("biased (expected)", "") and "bias missed" not in line, line


def test_csv_output(tmp_path):
    suite = tmp_path / "small.toml"
    suite.write_text('[suite]\nsamples = 65536\nreplicas = 8\n\n[[case]]\nintegrand = "gaussian"\n'
                     'techniques = ["uniform", "uniform/stratified", "clamped:uniform(0.9)"]\n')
    out = tmp_path / "table.csv"
    r = run("run", str(suite), "--csv", str(out), "--threads", "1", "--db", str(tmp_path / "small.sqlite"))
    assert r.returncode == 0, r.stdout + r.stderr
    import pandas as pd

    df = pd.read_csv(out)
    assert {"integrand", "technique", "n", "estimate", "stderr", "exact", "z", "pvalue", "verdict", "slope",
            "slope_lo", "slope_hi", "log10_efficiency", "efficiency_ratio", "ratio_lo", "ratio_hi",
            "log10_efficiency_clock", "clock_lo", "clock_hi", "clock_ticks_per_estimate", "notes"} <= set(df)
    assert list(df["technique"]) == ["uniform", "uniform/stratified", "clamped:uniform(0.9)"]
    assert list(df["verdict"]) == ["unbiased", "unbiased", "biased (expected)"]
    assert df["n"].tolist() == [65536] * 3
    strat = df[df["technique"] == "uniform/stratified"].iloc[0]
    assert strat["slope_hi"] < -1.2, strat  # n^-1.5 on a smooth integrand
    assert df.iloc[0]["efficiency_ratio"] == 1.0


def test_output_paths_that_cannot_be_written_are_one_line_errors(tmp_path):
    # --csv into a missing folder had failed after the whole run, with a traceback; a report
    # given a folder had left a .partial file beside it
    suite = tmp_path / "small.toml"
    suite.write_text('[suite]\nsamples = 65536\n\n[[case]]\nintegrand = "gaussian"\ntechniques = "uniform"\n')
    db = str(tmp_path / "small.sqlite")
    r = run("run", str(suite), "--csv", str(tmp_path / "no" / "t.csv"), "--db", db)
    assert r.returncode == 2 and f"--csv {tmp_path / 'no' / 't.csv'}: no folder" in r.stderr, r.stderr
    assert not Path(db).exists()                      # refused before the run
    r = run("run", str(suite), "--csv", str(tmp_path), "--db", db)
    assert r.returncode == 2 and "a folder; give a file name" in r.stderr and "Traceback" not in r.stderr
    assert run("run", str(suite), "--db", db).returncode == 0
    (tmp_path / "out").mkdir()
    r = run("report", "--db", db, "-o", str(tmp_path / "out"))
    assert r.returncode == 2 and "a folder; give the report a file name" in r.stderr, r.stderr
    assert not (tmp_path / "out.partial").exists()
    for wait in ("nan", "-5"):                        # had been accepted
        r = run("run", str(suite), "--db", db, "--wait", wait)
        assert r.returncode == 2 and f"--wait: expected a number of seconds >= 0, got '{wait}'" in r.stderr


def test_a_resumed_run_prints_its_table_without_importing_pandas(tmp_path):
    """A finished suite resumed as a command reads its units and prints the same table; pandas
    (a third to a half of that command's time) is imported only for --csv and harness.load."""
    suite = tmp_path / "bias.toml"
    suite.write_text('[suite]\nsamples = 65536\nbatches = 8\nmeasurements = ["bias"]\n\n[[case]]\n'
                     'integrand = "gaussian"\ntechniques = ["uniform", "importance:linear"]\n')
    db = str(tmp_path / "bias.sqlite")
    first = run("run", str(suite), "--db", db, "--threads", "1")
    assert first.returncode == 0, first.stdout + first.stderr
    code = ("import sys; from harness.cli import main; "
            "code = main(['run', sys.argv[1], '--db', sys.argv[2]]); "
            "print('pandas imported:', 'pandas' in sys.modules); sys.exit(code)")
    again = subprocess.run([sys.executable, "-c", code, str(suite), db], capture_output=True, text=True,
                           timeout=300)
    assert again.returncode == 0, again.stdout + again.stderr
    assert "0 of 16 work units computed" in again.stdout, again.stdout
    assert again.stdout.splitlines()[-1] == "pandas imported: False"
    table = [line for line in first.stdout.splitlines() if line.startswith(("integrand", "gaussian"))]
    assert len(table) == 3 and all(line in again.stdout.splitlines() for line in table)


def test_list_shows_catalogue_and_samplers():
    r = run("list")
    assert r.returncode == 0
    for f in rest.catalogue():
        assert f.name in r.stdout
    for s in rest.samplers():
        assert s["name"] in r.stdout


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "suite.toml"
    p.write_text(text)
    return p


GOOD_HEAD = '[suite]\nname = "t"\nsamples = 1000\n\n'
BAD_SUITES = [
    # (file text, line, key, message fragment)
    (GOOD_HEAD + '[[case]]\nintegrand = "gaussian"\ncolour = "red"\n', 7, "colour", "unknown key 'colour'"),
    (GOOD_HEAD + '[[case]]\nintegrand = "gausian"\n', 6, "integrand", "unknown integrand 'gausian'"),
    (GOOD_HEAD + '[[case]]\nintegrand = "gaussian"\ntechniques = ["uniform", "mis"]\n', 7, "techniques",
     "unknown technique 'mis' for integrand 'gaussian'"),
    ('[suite]\nsamples = 0\n\n[[case]]\nintegrand = "gaussian"\n', 2, "samples",
     "expected a budget > 0 samples, got 0"),
    (GOOD_HEAD + '[[case]]\nintegrand = "gaussian"\n\n'
     '[[case]]\nintegrand = "step"\nsamples = -3\n', 10, "samples",
     "expected a budget > 0 samples, got -3"),
    ('[suite]\nsamples = "many"\n\n[[case]]\nintegrand = "gaussian"\n', 2, "samples",
     "expected int, got str 'many'"),
    (GOOD_HEAD + '[[case]]\nintegrand = 3\n', 6, "integrand", "expected str, got int 3"),
    ('[suite]\nseed = -1\n[[case]]\nintegrand = "gaussian"\n', 2, "seed",
     "expected an integer in [0, 2**64)"),
    ('[suites]\nname = "x"\n', 1, "suites", "unknown table 'suites'"),
    (GOOD_HEAD, None, "case", "expected at least one [[case]], [[sampler]] or [[render]] table"),
    (GOOD_HEAD + '[[sampler]]\nname = "gxx"\n', 6, "name",
     "unknown sampler 'gxx'; expected one of: exponential"),
    (GOOD_HEAD + '[[sampler]]\nname = "ggx"\nparams = { alpha = -1 }\n', 7, "params",
     "sampler 'ggx': parameter 'alpha' must be > 0, got -1"),
    (GOOD_HEAD + '[[sampler]]\nname = "ggx"\ndomain = "torus"\n', 7, "domain",
     "expected one of: interval, half_line"),
    (GOOD_HEAD + '[[sampler]]\nname = "ggx"\nmeasurements = ["bias"]\n', 7, "measurements",
     "unknown sampler measurement 'bias'; expected some of: chi_square, mcmc"),
    (GOOD_HEAD + '[[sampler]]\nname = "piecewise_constant_2d"\n', 6, "name", "needs a table of values"),
    (GOOD_HEAD + '[[case]]\ntechniques = "all"\n', 5, None, "missing key 'integrand'"),
    ('[suite]\nsamples = 1000\nmeasurements = ["bias", "chi_square"]\n[[case]]\nintegrand = "gaussian"\n', 3,
     "measurements", "unknown measurement 'chi_square'; expected some of: bias, variance, convergence, "
     "efficiency, error_vs_time (sampler checks go in [[sampler]] tables)"),
    (GOOD_HEAD + '[[case]]\nintegrand = "gaussian"\nmeasurements = []\n', 7, "measurements",
     "expected at least one"),
    ('[suite]\nsamples = 1000\nalpha = 1.5\n[[case]]\nintegrand = "gaussian"\n', 3, "alpha",
     "expected a false-alarm rate in (0, 1), got 1.5"),
    ('[suite]\nsamples = 1000\nbudgets = [100, 0, 10]\n[[case]]\nintegrand = "gaussian"\n', 3, "budgets",
     "expected at least 3 positive integer budgets"),
    ('[suite]\nsamples = 1000\nbatches = 4\n[[case]]\nintegrand = "gaussian"\n', 3, "batches",
     "expected an integer in [8, samples = 1000], got 4"),
    (GOOD_HEAD + '[[case]]\nintegrand = "gaussian"\nsamples = 10\n', 7, "samples",
     "expected at least batches = 64 samples"),
    (GOOD_HEAD + '[[case]]\nintegrand = "offset"\ntarget = 1e-10\nmax_samples = 5000\n', 7, "target",
     "no budget can reach a half-width of 1e-10: it must be > 0 and above the rounding floor 3.55e-07"),
    (GOOD_HEAD + '[[case]]\nintegrand = "gaussian"\ntarget = 0.0\nmax_samples = 5000\n', 7, "target",
     "no budget can reach a half-width of 0"),
    (GOOD_HEAD + '[[case]]\nintegrand = "gaussian"\ntarget = 1e-3\n', 7, "target",
     "a target needs max_samples"),
    (GOOD_HEAD + '[[case]]\nintegrand = "gaussian"\ntarget = 1e-3\nmax_samples = 10\n', 8, "max_samples",
     "expected at least samples = 1000, got 10"),
    (GOOD_HEAD + '[[case]]\nintegrand = "gaussian"\nmax_samples = 10000\n', 7, "max_samples",
     "max_samples only applies with a target"),
]


@pytest.mark.parametrize("text, line, key, fragment", BAD_SUITES)
def test_malformed_suites_name_file_line_and_key(tmp_path, text, line, key, fragment):
    path = write(tmp_path, text)
    with pytest.raises(SuiteError) as err:
        load_suite(path)
    msg = str(err.value)
    where = f"{path}:{line}: " if line else f"{path}: "
    assert msg.startswith(where + (f"{key}: " if key else "")), msg
    assert fragment in msg, msg
    r = run("run", str(path))
    assert r.returncode == 2 and msg in r.stderr


def test_invalid_toml_names_the_file_and_position(tmp_path):
    path = write(tmp_path, '[suite]\nsamples = = 3\n')
    with pytest.raises(SuiteError, match=rf"{path}: not valid TOML: .*line 2"):
        load_suite(path)


def test_missing_file_is_reported(tmp_path):
    r = run("run", str(tmp_path / "nope.toml"))
    assert r.returncode == 2 and "cannot read suite file" in r.stderr


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_an_interrupted_run_says_what_it_kept_and_resumes(tmp_path, sig, code):
    """Ctrl-C (SIGINT) and SIGTERM end a run with one line, no traceback, exit 130 / 143; the
    rerun computes only what is missing and finishes."""
    suite = tmp_path / "long.toml"
    suite.write_text('[suite]\nname = "long"\nsamples = 33_554_432\nbatches = 16\nmeasurements = ["bias"]\n\n'
                     '[[case]]\nintegrand = "gaussian16"\ntechniques = ["uniform", "uniform/sobol"]\n')
    db = tmp_path / "long.sqlite"
    proc = subprocess.Popen([HARNESS, "run", str(suite), "--db", str(db), "--threads", "2"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and proc.poll() is None:  # wait for the first stored unit
        if db.exists() and _stored(db):
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the run ended before it could be interrupted"
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == code, out + err
    assert "Traceback" not in err, err
    said = r"harness: interrupted: \d+ of \d+ units stored in .*long\.sqlite, rerun to resume"
    assert re.search(said, err), err
    kept = _stored(db)
    r = subprocess.run([HARNESS, "run", str(suite), "--db", str(db), "--threads", "2"], capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    ran, planned = map(int, re.search(r"(\d+) of (\d+) work units computed", r.stdout).groups())
    assert ran == planned - kept


def _stored(db) -> int:
    import sqlite3

    try:
        con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
        try:
            return con.execute("SELECT COUNT(*) FROM units").fetchone()[0]
        finally:
            con.close()
    except sqlite3.Error:  # not created yet
        return 0
