"""Do the efficiency intervals cover as often as they claim?  One comparison repeated.

    .venv/bin/python benchmarks/efficiency_coverage.py [--repeats 20] [--samples 1000000]
                                                        [--sets 1] [--same-process]

Runs the same two-case suite (gaussian: uniform MC and importance sampling, efficiency only)
``repeats`` times, each into a fresh database with its own seed and, unless
``--same-process``, in a fresh process (`harness run`, the cases' replicas interleaved), and
asks of three figures how often a run's 95 % interval contains the median of all runs' values:

* log10 1/(V·T) per technique, T in seconds: its interval claims only this run's machine
  state, so it is expected to fall short across processes;
* log10 1/(V·T_clock) per technique, T in ticks of the reference clock timed beside each
  replica (harness.stats.timing.CLOCK): its interval claims other runs;
* the ratio importance/uniform (interleaved replicas: the machine's state cancels).

Nominal: about 95 % (a little more, since the median of the runs is itself uncertain).  The
intervals take the time's standard error from the spread between blocks of 4 replicas, with
Student's t on the blocks' degrees of freedom.  ``--sets`` repeats the whole experiment (one
table each, then their sum).  Prints the CPU, each run's figures and time per estimate.
"""
from __future__ import annotations

import argparse
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from harness.stats import median_time
from harness.suite.parse import loads_suite
from harness.suite.readers import load, reading
from harness.suite.run import run_suite

FIGURES = (("log10_efficiency", "uniform", "log10 1/(V·T) uniform, s"),
           ("log10_efficiency", "importance:linear", "log10 1/(V·T) importance, s"),
           ("log10_efficiency_clock", "uniform", "log10 1/(V·T) uniform, clock"),
           ("log10_efficiency_clock", "importance:linear", "log10 1/(V·T) importance, clock"),
           ("efficiency_ratio", "importance:linear", "ratio importance/uniform"))

SUITE = """\
[suite]
name = "coverage"
seed = {seed}
samples = {samples}
replicas = 32
measurements = ["efficiency"]

[[case]]
integrand = "gaussian"
techniques = ["uniform", "importance:linear"]
"""


def _cpu() -> str:
    try:
        return next(line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                    if line.startswith("model name"))
    except (OSError, StopIteration):
        return platform.processor() or "unknown CPU"


def _times(db: Path) -> dict[str, np.ndarray]:
    """Per case: its top budget's replica times (s), in replica order (the order they ran)."""
    with reading(db) as con:
        rows = con.execute("SELECT c.technique, u.replica, u.seconds FROM units u JOIN cases c USING "
                           "(case_key) WHERE u.kind = 'state' AND u.stream = (SELECT MAX(stream) FROM units "
                           "WHERE kind = 'state') ORDER BY u.replica, u.chunk_begin").fetchall()
    out: dict[str, dict[int, float]] = {}
    for technique, replica, seconds in rows:
        out.setdefault(technique, {}).setdefault(replica, 0.0)
        out[technique][replica] += seconds
    return {t: np.array([v[r] for r in sorted(v)]) for t, v in out.items()}


def _run(seed: int, samples: int, folder: Path, fresh: bool) -> tuple[dict, dict[str, np.ndarray]]:
    """One run: each figure's (value, lo, hi), and each case's replica times."""
    db = folder / f"r{seed}.sqlite"
    text = SUITE.format(seed=seed, samples=samples)
    if fresh:   # a new process, as a user's next `harness run` is
        suite = folder / f"r{seed}.toml"
        suite.write_text(text)
        subprocess.run([sys.executable, "-m", "harness.cli", "run", str(suite), "--db", str(db)], check=True,
                       stdout=subprocess.DEVNULL)
    else:
        run_suite(loads_suite(text), db)
    m = load(db)
    got = {(r.measurement, r.technique): (r.value, r.lo, r.hi) for r in m.itertuples()}
    return {f: got.get(f[:2], (np.nan,) * 3) for f in FIGURES}, _times(db)


def _table(runs: list[tuple[dict, dict]]) -> dict[tuple, tuple[int, float, float]]:
    """Per figure: runs whose interval covers the runs' median, the median, the SD of the log10
    values between runs."""
    out = {}
    for f in FIGURES:
        a = np.array([figures[f] for figures, _ in runs], dtype=float)
        med = float(np.median(a[:, 0]))
        logs = np.log10(a[:, 0]) if f[0] == "efficiency_ratio" else a[:, 0]
        out[f] = (int(np.sum((a[:, 1] <= med) & (med <= a[:, 2]))), med, float(np.std(logs, ddof=1)))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--samples", type=int, default=1_000_000)
    ap.add_argument("--sets", type=int, default=1, help="independent repetitions of the whole experiment")
    ap.add_argument("--same-process", action="store_true", help="all runs in this process")
    args = ap.parse_args()
    fresh = not args.same_process
    print(f"CPU: {_cpu()}; {args.sets} x {args.repeats} repeats of {args.samples} samples per case, "
          f"32 replicas, {'a fresh process per run' if fresh else 'all runs in one process'}")
    tables = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.sets):
            runs = [_run(1000 * k + seed, args.samples, Path(tmp), fresh) for seed in range(args.repeats)]
            tables.append(_table(runs))
            print(f"\nset {k + 1}: per run: log10 1/(V·T) [95% CI] uniform, importance (s); the same in "
                  "clock ticks; ratio [95% CI]; median time per estimate ± s.e. (ms) uniform, importance")
            for i, (fig, times) in enumerate(runs):
                cells = [f"{v:.4f} [{lo:.4f}, {hi:.4f}]" for v, lo, hi in (fig[f] for f in FIGURES)]
                tu, ti = (median_time(times[t]) for t in ("uniform", "importance:linear"))
                print(f"  {i:2d}: {'; '.join(cells)}; {1e3 * tu[0]:.3f} ± {1e3 * tu[1]:.3f}, "
                      f"{1e3 * ti[0]:.3f} ± {1e3 * ti[1]:.3f}")
    sets = " | ".join(f"set {k + 1}" for k in range(args.sets))
    print(f"\n| figure | {sets} | all | SD of log10 between runs (median of sets) |")
    print(f"|---|{'---|' * args.sets}---|---|")
    for f in FIGURES:
        covered = [t[f][0] for t in tables]
        sd = np.median([t[f][2] for t in tables])
        print(f"| {f[2]} | {' | '.join(f'{c}/{args.repeats}' for c in covered)} | "
              f"{sum(covered)}/{args.repeats * args.sets} | {sd:.4f} |")


if __name__ == "__main__":
    main()
