"""Killing `harness run` at random moments of a sampler-check suite and of a render suite, with
SIGKILL, SIGINT and SIGTERM, then rerunning it: the stored results must equal an uninterrupted
run's (units and their payloads bit for bit, images, cached references, measurements; only wall
times may differ).  The estimator kind's version of this is in test_runner.py (SIGKILL) and
test_cli.py (SIGINT, SIGTERM); this is the matrix over the other two kinds of case."""
from __future__ import annotations

import hashlib
import json
import math
import os
import random
import re
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

import harness
from harness.suite.store import image_dir, read_stored
from tests.suite.test_stale_results import TIMED, _untimed

HARNESS = str(Path(sys.executable).with_name("harness"))
OWN_RENDERER = Path(__file__).resolve().parents[2] / "examples" / "own-renderer"


SIGNALS = [pytest.param(signal.SIGKILL, id="SIGKILL"), pytest.param(signal.SIGINT, id="SIGINT"),
           pytest.param(signal.SIGTERM, id="SIGTERM")]
EXIT = {signal.SIGKILL: -9, signal.SIGINT: 130, signal.SIGTERM: 143}
SAID = re.compile(r"harness: interrupted: (\d+) of (\d+) units stored in (.+), rerun to resume")

# ~2 s of chi-square checks on 2 threads, one unit each: the cheap checks on an interval or half-line
# first (so the first commit comes early), then the hemisphere and sphere ones (~0.3 s each at
# 4e6 samples on 2026-12-04; 4e5 had left ~0.2 s after the first commit once the samplers ran
# in vector lanes and the tables' setup halved)
SAMPLERS = """
[suite]
name = "kill-samplers"
seed = 17
samples = 4_000_000

[[sampler]]
name = "power"
params = { k = -0.75 }

[[sampler]]
name = "power"
params = { k = 2.0 }

[[sampler]]
name = "exponential"
params = { rate = 3.0 }

[[sampler]]
name = "lomax"
params = { shape = 2.5 }

[[sampler]]
name = "linear"
params = { a = 0.2, b = 1.0 }

[[sampler]]
name = "trimmed_logistic"
params = { s = 0.05, mu = 0.4 }

[[sampler]]
name = "ggx"
params = { alpha = 0.05 }

[[sampler]]
name = "ggx"
params = { alpha = 0.3 }

[[sampler]]
name = "cosine_hemisphere"

[[sampler]]
name = "uniform_sphere"
"""

# examples/own-renderer's renderer twice: as a command (a process per image, ~0.3 s each) against
# its exact image, and as a Python function (~0.05 s per 1024 spp) against a rendered reference
# (8 parts, units like the others, then cached in references/ beside the database)
RENDERS = """
[suite]
name = "kill-renders"
seed = 11

[[render]]
adapter = "command"
command = "{python} myrenderer.py --spp {spp} --seed {seed} --out {out}"
exact = "ref.exr"
time = "stdout:render time: ([0-9.]+) s"
timeout = 60
spp = 8
replicas = 5
measurements = ["bias", "variance"]

[[render]]
adapter = "python"
function = "myrenderer:render"
spp = 1024
replicas = 4
budgets = [256, 512, 1024]
reference_spp = 8192
"""


# --- reading a results database --------------------------------------------------------------
def _rows(db: Path, sql: str) -> list[tuple]:
    """The rows of a query on the database, opened read-only."""
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        return con.execute(sql).fetchall()
    finally:
        con.close()


def stored_count(db: Path) -> int:
    """Unit rows committed so far; 0 while the file or its schema does not exist yet."""
    if not db.exists():
        return 0
    try:
        return _rows(db, "SELECT COUNT(*) FROM units")[0][0]
    except sqlite3.Error:
        return 0


def units_table(db: Path) -> list[tuple]:
    """Every unit row but its wall time and finishing time (seconds, finished); the payload as the
    stored text, so equal means bitwise equal."""
    return _rows(db, "SELECT case_key, stream, budget, replica, chunk_begin, chunk_end, kind, payload "
                     "FROM units ORDER BY 1, 2, 3, 4, 5, 6, 7")


def other_tables(db: Path) -> dict[str, list[tuple]]:
    """The cases, and the images without their finishing times and file digests
    (an EXR file holds the time it was written: its bytes differ from run to run, its pixels must not)."""
    return {"cases": _rows(db, "SELECT * FROM cases ORDER BY case_key"),
            "images": _rows(db, "SELECT name, file, height, width, channels FROM images ORDER BY name")}


def plan(db: Path) -> tuple[int, int]:
    """(units the latest run planned, how many of them are stored).  A run after the one that
    cached a rendered reference plans no parts of it: their units stay stored, outside the plan."""
    return _rows(db, "SELECT COUNT(*), COUNT(u.case_key) FROM planned p LEFT JOIN units u USING "
                     "(case_key, stream, budget, replica, chunk_begin, chunk_end, kind)")[0]


def runs_table(db: Path) -> list[tuple]:
    """Per run: (finished?, units planned, units computed, measurements stored)."""
    return _rows(db, "SELECT finished IS NOT NULL, units_planned, units_run, (SELECT COUNT(*) FROM "
                     "measurements m WHERE m.run = r.run) FROM runs r ORDER BY run")


def last_run_keys(db: Path) -> list[str]:
    """The case keys (references included) the latest run registered."""
    return [k for (k,) in _rows(db, "SELECT case_key FROM run_keys WHERE run = (SELECT MAX(run) FROM runs) "
                                    "ORDER BY case_key")]


def pixels(db: Path) -> dict[str, bytes]:
    """Every stored image's values (EXR as float32, .npy in its own precision), by name."""
    return {name: read_stored(image_dir(db) / file).tobytes()
            for name, file, *_ in other_tables(db)["images"]}


def _image_digests(db: Path) -> dict[str, tuple[str, str]]:
    return {name: (file, sha) for name, file, sha in _rows(db, "SELECT name, file, sha256 FROM images")}


def measured(db: Path) -> tuple[set, dict]:
    """(every (case_key, measurement) stored, and for those that do not depend on wall times
    everything stored about them, timing fields left out of the detail)."""
    df = harness.load(db)
    keys, out = set(), {}
    for r in df.to_dict("records"):
        key = (r["case_key"], r["measurement"])
        assert key not in keys, f"measurement stored twice: {key}"
        keys.add(key)
        if r["measurement"] not in TIMED:
            out[key] = tuple("nan" if isinstance(v, float) and math.isnan(v) else v
                             for v in (r["suite"], r["integrand"], r["technique"], r["value"], r["lo"],
                                       r["hi"], r["n"], r["pvalue"], r["alpha"], r["verdict"]))
            out[key] += (repr(_untimed(json.loads(r["detail"]))),)
    return keys, out


def references(db: Path) -> dict[str, bytes]:
    """The cached rendered references beside the database: the float64 arrays measured against."""
    return {p.name: p.read_bytes() for p in sorted((db.parent / "references").glob("*.npy"))
            if ".partial" not in p.name}


def check_consistent(db: Path, full: int) -> None:
    """What a killed run may leave: whole, unique rows, no more than the suite plans, and every
    stored render pointing at a complete image file (its bytes those recorded)."""
    rows = units_table(db) if db.exists() else []
    keys = [r[:7] for r in rows]
    assert len(keys) == len(set(keys)), "duplicate unit rows"
    assert len(rows) <= full, f"{len(rows)} unit rows, the suite plans {full}"
    payloads = [json.loads(r[7]) for r in rows]
    assert all(payloads), "an empty payload"
    images = _image_digests(db) if rows else {}
    for r, p in zip(rows, payloads):
        if r[6] == "render":
            assert p["image"] in images, f"render unit {r[:7]} without its image row"
            file, sha = images[p["image"]]
            path = image_dir(db) / file
            assert path.is_file() and hashlib.sha256(path.read_bytes()).hexdigest() == sha, path


# --- running ---------------------------------------------------------------------------------
def command(suite: Path, db: Path) -> list[str]:
    return [HARNESS, "run", str(suite), "--db", str(db), "--threads", "2"]


def environment(db: Path) -> dict[str, str]:
    """The run's environment, its temporary files beside the database: a run killed with SIGKILL
    during a command render leaves the render's temporary folder behind."""
    tmp = db.parent / "tmp"
    tmp.mkdir(parents=True, exist_ok=True)
    return {**os.environ, "TMPDIR": str(tmp)}


def run_to_completion(suite: Path, db: Path) -> float:
    """A run to the end, checked; returns the seconds from its first commit to its exit (the
    span the kill tests draw their moments from: this machine's, not a constant's)."""
    kept = stored_count(db)
    proc = subprocess.Popen(command(suite, db), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=environment(db))
    first = None
    while proc.poll() is None:
        if first is None and stored_count(db) > kept:
            first = time.monotonic()
        time.sleep(0.01)
    end = time.monotonic()
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, out + err
    assert re.search(r"summary: \d+ passed, 0 failed", out), out
    ran, planned = map(int, re.search(r"(\d+) of (\d+) work units computed", out).groups())
    assert ran == stored_count(db) - kept, (ran, kept, stored_count(db))  # only what was not stored
    assert plan(db) == (planned, planned)
    assert runs_table(db)[-1][:3] == (1, planned, ran), runs_table(db)
    return end - (first if first is not None else end)


def kill_once(suite: Path, db: Path, sig: signal.Signals, delay: float, full: int) -> str | None:
    """One run, sent ``sig`` ``delay`` s after its first commit; checks how it ended.  Returns a
    note when the run finished before the signal could interrupt it (None when it was interrupted)."""
    before = stored_count(db)
    proc = subprocess.Popen(command(suite, db), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=environment(db))
    try:
        deadline = time.monotonic() + 120
        while proc.poll() is None and time.monotonic() < deadline and stored_count(db) <= before:
            time.sleep(0.01)
        time.sleep(delay)
        if proc.poll() is None:
            proc.send_signal(sig)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    check_consistent(db, full)
    runs = runs_table(db) if db.exists() else []
    assert runs, f"the run stored nothing: exit {proc.returncode}\n{out}\n{err}"
    if runs[-1][0]:  # the signal came after the run had stored its measurements and finished
        return (f"{sig.name} {delay:.2f} s after the first commit came after the run finished "
                f"(exit {proc.returncode}; stderr {err.strip()[-200:]!r})")
    assert proc.returncode == EXIT[sig], f"exit {proc.returncode}\n{out}\n{err}"
    if sig != signal.SIGKILL:
        assert "Traceback" not in err, err
        lines = err.strip().splitlines()
        assert len(lines) == 1 and SAID.fullmatch(lines[0]), err
        kept, planned, where = SAID.fullmatch(lines[0]).groups()
        in_plan, stored = plan(db)
        assert (int(planned), where) == (in_plan, str(db)), err
        assert int(kept) == stored, err   # counted in the database, whenever the signal came
    return None


def kill_and_resume(suite: Path, ref_db: Path, db: Path, sig: signal.Signals, seed: int,
                    delays: list[tuple[float, float]], span: float) -> list[str]:
    """Runs on a fresh ``db``, each sent ``sig`` at a random moment (seeded: the moments, not the
    outcome) after the run's first commit, from its range of fractions of ``span`` (the
    uninterrupted run's seconds from its first commit to its exit: a fixed range in seconds had
    outlasted the run on a faster machine, and no run was interrupted), then a run to
    completion; asserts the stored results equal the uninterrupted run's in ``ref_db``.
    Returns notes on signals that came after a run had finished."""
    full = stored_count(ref_db)
    rng = random.Random(seed)
    notes, interrupted = [], 0
    for lo, hi in delays:
        note = kill_once(suite, db, sig, span * rng.uniform(lo, hi), full)
        if note:
            notes.append(note)
            break  # finished: nothing left to interrupt
        interrupted += 1
    assert interrupted, f"no run was interrupted: {notes}"
    run_to_completion(suite, db)
    runs, (ref_run,) = runs_table(db), runs_table(ref_db)
    assert len(runs) == interrupted + len(notes) + 1, runs
    assert runs[-1][3] == ref_run[3] > 0, (runs, ref_run)  # measurements stored under the final run
    assert last_run_keys(db) == last_run_keys(ref_db)
    assert units_table(db) == units_table(ref_db)
    assert other_tables(db) == other_tables(ref_db)
    assert pixels(db) == pixels(ref_db)
    assert references(db) == references(ref_db)
    (keys, values), (ref_keys, ref_values) = measured(db), measured(ref_db)
    assert keys == ref_keys
    assert values == ref_values
    check_consistent(db, full)
    return notes


# --- the suites ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def sampler_suite(tmp_path_factory) -> tuple[Path, Path, float]:
    """The sampler-check suite, its uninterrupted run's database and that run's seconds from its
    first commit to its exit."""
    folder = tmp_path_factory.mktemp("samplers")
    suite = folder / "samplers.toml"
    suite.write_text(SAMPLERS)
    db = folder / "reference" / "r.sqlite"
    return suite, db, run_to_completion(suite, db)


@pytest.fixture(scope="module")
def render_suite(tmp_path_factory) -> tuple[Path, Path, float]:
    """The render suite beside a copy of examples/own-renderer's renderer, its uninterrupted
    run's database (in its own folder: references/ is shared by the databases of a folder) and
    that run's seconds from its first commit to its exit."""
    folder = tmp_path_factory.mktemp("renders")
    for name in ("myrenderer.py", "mysampler.py", "ref.exr"):
        shutil.copy(OWN_RENDERER / name, folder / name)
    suite = folder / "renders.toml"
    suite.write_text(RENDERS)
    db = folder / "reference" / "r.sqlite"
    span = run_to_completion(suite, db)
    assert len(references(db)) == 1  # the python case's rendered reference: its parts
    return suite, db, span


@pytest.mark.slow
@pytest.mark.parametrize("sig", SIGNALS)
def test_a_sampler_suite_killed_at_random_moments_resumes_to_the_same_results(sampler_suite, tmp_path, sig):
    suite, ref_db, span = sampler_suite
    notes = kill_and_resume(suite, ref_db, tmp_path / "killed" / "r.sqlite", sig, seed=20260101 + sig,
                            delays=[(0.0, 0.6), (0.0, 0.8)], span=span)
    for note in notes:
        print("note:", note)


@pytest.mark.slow
@pytest.mark.parametrize("sig", SIGNALS)
def test_a_render_suite_killed_at_random_moments_resumes_to_the_same_results(render_suite, tmp_path, sig):
    suite, ref_db, span = render_suite
    notes = kill_and_resume(suite, ref_db, tmp_path / "killed" / "r.sqlite", sig, seed=20260202 + sig,
                            delays=[(0.1, 0.8), (0.1, 0.8)], span=span)
    for note in notes:
        print("note:", note)
