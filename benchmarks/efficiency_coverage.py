"""Do the efficiency intervals cover as often as they claim?  One comparison repeated.

    .venv/bin/python benchmarks/efficiency_coverage.py [--repeats 20] [--samples 1000000]

Runs the same two-case suite (gaussian: uniform MC and importance sampling, efficiency only)
``repeats`` times, each into a fresh database with its own seed, as `harness run` does (the
cases' replicas interleaved), and asks of each case's 1/(V·T) and of their ratio: how often
does a run's 95 % interval contain the median of all runs' values?  Nominal: about 95 %
(a little more, since the median of the runs is itself uncertain).  Beside it, the same
coverage with the time's standard error taken as before (1.2533 x 1.4826 MAD / sqrt(R) over
the replicas, as if their times were independent), from the same stored times.  Prints the
CPU, the repeats and each run's figures.
"""
from __future__ import annotations

import argparse
import math
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
    for eff, ratio, times in runs:
        for t in ("uniform", "importance:linear"):
            v, lo, hi = eff[t]
            # the same interval with the old time error: log10 half-width from the two relative errors
            med, se_new = median_time(times[t])
            se_old = 1.2533 * 1.4826 * float(np.median(np.abs(times[t] - med))) / math.sqrt(times[t].size)
            half = hi - v
            var_rel = math.sqrt(max((half / 1.96 * math.log(10)) ** 2 - (se_new / med) ** 2, 0.0))
            half_old = 1.96 * math.hypot(var_rel, se_old / med) / math.log(10)
            rows[t].append((v, lo, hi, v - half_old, v + half_old))
        rows["ratio"].append(ratio + (math.nan, math.nan))
    print(f"{'figure':<22} {'covered (new)':>14} {'covered (old time s.e.)':>24} {'median':>10}")
    for name, rs in rows.items():
        a = np.array(rs, dtype=float)
        med = float(np.median(a[:, 0]))
        new = int(np.sum((a[:, 1] <= med) & (med <= a[:, 2])))
        old = int(np.sum((a[:, 3] <= med) & (med <= a[:, 4]))) if np.isfinite(a[:, 3]).all() else None
        label = f"log10 1/(V·T) {name}" if name != "ratio" else "ratio importance/uniform"
        print(f"{label:<22} {new:>8}/{len(rs):<5} {(f'{old}/{len(rs)}' if old is not None else '—'):>24} "
              f"{med:>10.4g}")
    print("\nper run: log10 efficiency [95% CI] uniform; importance; ratio [95% CI]")
    for i in range(len(runs)):
        u, s, r = rows["uniform"][i], rows["importance:linear"][i], rows["ratio"][i]
        print(f"  {i:2d}: {u[0]:.4f} [{u[1]:.4f}, {u[2]:.4f}]; {s[0]:.4f} [{s[1]:.4f}, {s[2]:.4f}]; "
              f"{r[0]:.3f} [{r[1]:.3f}, {r[2]:.3f}]")


if __name__ == "__main__":
    main()
