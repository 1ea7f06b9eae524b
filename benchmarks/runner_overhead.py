"""Runner overhead: a 1e8-sample suite through `harness run` (plan, threads, SQLite, analysis)
against the same core calls made directly (each batch's state with its contributions' tails,
the tails merged: what the bias measurement needs), side by side in one run; and the time to
resume a finished suite (in process, and as a fresh `harness run` command).

    .venv/bin/python benchmarks/runner_overhead.py [--repeat 3]
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import reference_estimators as rest

from harness.suite.parse import load_suite
from harness.suite.plan import BIAS_STREAM, bias_budget, core_case_id, tail_keeps
from harness.suite.run import run_suite

SUITE = """
[suite]
name = "overhead"
samples = 25_000_000
batches = 64
measurements = ["bias"]

[[case]]
integrand = "gaussian"
techniques = ["uniform", "importance:linear", "roulette:uniform(q=0.5)", "mis_balance:uniform+linear"]
"""


def direct(suite, threads: int) -> float:
    """The work the suite's bias measurements need, as plain core calls: each batch's state with
    its contributions' tails (one pass), the tails merged, the estimate of each batch."""
    start = time.perf_counter()
    for case in suite.cases:
        b = bias_budget(suite, case)
        keep, part_keep = tail_keeps(suite, case)
        core_case = core_case_id(case, BIAS_STREAM)
        f = rest.integrand(case.integrand)
        t = rest.technique(f, case.technique)
        chunks = -(-b // rest.CHUNK_SIZE)
        states = [rest.integrate_chunks(f, t, b, 0, chunks, seed=suite.seed, case_id=core_case, replica=k,
                                        threads=threads, tail_keep=part_keep, tail_median=k == 0)
                  for k in range(suite.batches)]
        rest.merge_tails([s.pop("tails") for s in states], keep)
        assert all(rest.estimate_from_states(f, t, [s]).ok for s in states)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "overhead.toml"
        path.write_text(SUITE)
        suite = load_suite(path)
        total = sum(c.samples for c in suite.cases)
        direct(suite, args.threads)  # warm-up
        rows = []
        for r in range(args.repeat):
            t_direct = direct(suite, args.threads)
            db = Path(tmp) / f"run{r}.sqlite"
            t0 = time.perf_counter()
            summary = run_suite(suite, db, threads=args.threads)
            t_runner = time.perf_counter() - t0
            rows.append((t_direct, t_runner))
            assert summary.units_run == summary.units_planned
        t0 = time.perf_counter()
        again = run_suite(suite, db, threads=args.threads)
        t_resume = time.perf_counter() - t0
        assert again.units_run == 0
        t0 = time.perf_counter()
        subprocess.run([str(Path(sys.executable).with_name("harness")), "run", str(path), "--db", str(db)],
                       check=True, capture_output=True)
        t_command = time.perf_counter() - t0

    print(f"suite: {len(suite.cases)} cases, {total:.1e} samples, "
          f"bias measurement ({suite.batches} batches), {args.threads} threads\n")
    print(f"{'run':>4} {'direct core calls [s]':>22} {'harness runner [s]':>19} {'overhead':>9}")
    for i, (d, r) in enumerate(rows):
        print(f"{i:>4} {d:22.3f} {r:19.3f} {100 * (r / d - 1):8.1f}%")
    d, r = min(x[0] for x in rows), min(x[1] for x in rows)
    print(f"best {d:22.3f} {r:19.3f} {100 * (r / d - 1):8.1f}%\n")
    print(f"resume of the finished suite: {t_resume:.3f} s in process, {t_command:.3f} s as a fresh "
          f"`harness run` command (interpreter start-up and imports included)")


if __name__ == "__main__":
    main()
