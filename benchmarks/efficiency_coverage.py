"""Do the efficiency intervals cover as often as they claim?  One comparison repeated.

    .venv/bin/python benchmarks/efficiency_coverage.py [--repeats 20] [--samples 1000000]

Runs the same two-case suite (gaussian: uniform MC and importance sampling, efficiency only)
``repeats`` times, each into a fresh database with its own seed, as `harness run` does (the
cases' replicas interleaved), and asks of each case's 1/(V·T) and of their ratio: how often
does a run's 95 % interval contain the median of all runs' values?  Nominal: about 95 %
(a little more, since the median of the runs is itself uncertain).  The intervals take the
time's standard error from the spread between blocks of 4 replicas, with Student's t on the
blocks' degrees of freedom.  Prints the CPU, the repeats and each run's figures, and each
run's block medians of the time (the drift within and between runs).
"""
from __future__ import annotations

import argparse
import platform
import tempfile
from pathlib import Path

import numpy as np

from harness.stats import median_time
from harness.suite.parse import loads_suite
from harness.suite.readers import load, reading
from harness.suite.run import run_suite

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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--samples", type=int, default=1_000_000)
    args = ap.parse_args()
    print(f"CPU: {_cpu()}; {args.repeats} repeats of {args.samples} samples per case, 32 replicas")
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.repeats):
            db = Path(tmp) / f"r{seed}.sqlite"
            run_suite(loads_suite(SUITE.format(seed=seed, samples=args.samples)), db)
            m = load(db)
            eff = {r.technique: (r.value, r.lo, r.hi) for r in m.itertuples()
                   if r.measurement == "log10_efficiency"}
            ratio = next((r.value, r.lo, r.hi) for r in m.itertuples()
                         if r.measurement == "efficiency_ratio" and r.technique == "importance:linear")
            runs.append((eff, ratio, _times(db)))
    rows = {"uniform": [], "importance:linear": [], "ratio": []}
    for eff, ratio, _ in runs:
        for t in ("uniform", "importance:linear"):
            rows[t].append(eff[t])
        rows["ratio"].append(ratio)
    print(f"{'figure':<34} {'covered':>10} {'median':>10}")
    for name, rs in rows.items():
        a = np.array(rs, dtype=float)
        med = float(np.median(a[:, 0]))
        covered = int(np.sum((a[:, 1] <= med) & (med <= a[:, 2])))
        label = f"log10 1/(V·T) {name}" if name != "ratio" else "ratio importance/uniform"
        print(f"{label:<34} {covered:>6}/{len(rs):<3} {med:>10.4g}")
    print("\nper run: log10 efficiency [95% CI] uniform; importance; ratio [95% CI]; median time per "
          "estimate ± s.e. (ms) uniform, importance")
    for i, (_, _, times) in enumerate(runs):
        u, s, r = rows["uniform"][i], rows["importance:linear"][i], rows["ratio"][i]
        tu, ti = (median_time(times[t]) for t in ("uniform", "importance:linear"))
        print(f"  {i:2d}: {u[0]:.4f} [{u[1]:.4f}, {u[2]:.4f}]; {s[0]:.4f} [{s[1]:.4f}, {s[2]:.4f}]; "
              f"{r[0]:.3f} [{r[1]:.3f}, {r[2]:.3f}]; {1e3 * tu[0]:.3f} ± {1e3 * tu[1]:.3f}, "
              f"{1e3 * ti[0]:.3f} ± {1e3 * ti[1]:.3f}")


if __name__ == "__main__":
    main()
