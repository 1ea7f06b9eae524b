"""False-alarm rate and power of the MCMC cross-check (harness.samplers.mcmc_crosscheck) on
the sampler zoo: every correct sampler of harness.samplers.zoo.correct() plus an exponential
sampler on the half line, and every mutant of zoo.wrong().

    .venv/bin/python benchmarks/mcmc_calibration.py [--seeds 200] [--wrong-seeds 20]
        [--samples 5000] [--alpha 0.01] [--workers 2] [--out results.jsonl]
    .venv/bin/python benchmarks/mcmc_calibration.py --table mcmc_calibration.jsonl

Prints one row per sampler: its domain, the failed checks of N seeds (false alarms for a
correct sampler, with the upper 99 % Clopper-Pearson bound of the rate; catches for a mutant),
the inconclusive count (chain too short under the step cap), the median tau and steps per
walker, and the median seconds per check (sampler, chain and tests).  Seeds are 0..N-1, run
seed-major over the samplers on ``--workers`` processes, each result written to ``--out`` (if
given) as it comes; ``--table`` prints the table of such a file, a partial run included.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import time
import warnings
from multiprocessing import Pool

from scipy import stats

import reference_estimators as rest

from harness.samplers import mcmc_crosscheck, zoo


def samplers() -> list[tuple[str, zoo.ZooSampler]]:
    """("correct" | "wrong", sampler) for the whole zoo and the half-line exponential."""
    expo = rest.sampler("exponential", rate=1.0)
    half = zoo.ZooSampler("exponential(rate=1)", "half_line", lambda u: expo.sample(u)[0], expo.pdf)
    return [("correct", s) for s in [*zoo.correct(), half]] + [("wrong", s) for s in zoo.wrong()]


def _one(job: tuple[int, int, int, float]) -> dict:
    index, seed, n, alpha = job
    warnings.simplefilter("ignore")
    kind, s = samplers()[index]
    start = time.perf_counter()
    r = mcmc_crosscheck(s.sample, s.pdf, s.domain, sample_count=n, seed=seed, alpha=alpha)
    domain = s.domain if isinstance(s.domain, str) else "interval"
    return {"sampler": s.name, "kind": kind, "domain": domain,
            "seed": seed, "n": n, "alpha": alpha, "verdict": r.verdict, "pvalue": r.pvalue,
            "tau": r.tests.attrs.get("tau"), "steps": r.tests.attrs.get("steps"),
            "seconds": time.perf_counter() - start}


def table(rows: list[dict]) -> str:
    """The benchmark's table of result rows (one per check)."""
    names = list(dict.fromkeys(r["sampler"] for r in rows))
    head = (f"{'sampler':52s} {'domain':10s} {'kind':7s} {'failed/N':>9s} {'rate (99% upper)':>17s} "
            f"{'inconcl.':>8s} {'tau':>6s} {'steps':>6s} {'sec':>6s}")
    lines = [head, "-" * len(head)]
    for name in names:
        rs = [r for r in rows if r["sampler"] == name]
        k = sum(r["verdict"] == "failed" for r in rs)
        inc = sum(r["verdict"] == "inconclusive" for r in rs)
        upper = stats.beta.ppf(0.99, k + 1, len(rs) - k) if k < len(rs) else 1.0
        taus = [r["tau"] for r in rs if r["tau"] is not None and r["tau"] == r["tau"]]
        lines.append(f"{name[:52]:52s} {rs[0]['domain']:10s} {rs[0]['kind']:7s} {k:4d}/{len(rs):<4d} "
                     f"{k / len(rs):7.3f} ({upper:.3f}) {inc:8d} "
                     f"{statistics.median(taus) if taus else float('nan'):6.1f} "
                     f"{statistics.median(r['steps'] for r in rs):6.0f} "
                     f"{statistics.median(r['seconds'] for r in rs):6.2f}")
    correct = [r for r in rows if r["kind"] == "correct"]
    if correct:
        k = sum(r["verdict"] == "failed" for r in correct)
        lines.append(f"all correct samplers: {k} false alarms in {len(correct)} checks "
                     f"({k / len(correct):.4f}; alpha = {correct[0]['alpha']}, "
                     f"{sum(r['verdict'] == 'inconclusive' for r in correct)} inconclusive), "
                     f"{correct[0]['n']} samples a check")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=200, help="seeds per correct sampler")
    ap.add_argument("--wrong-seeds", type=int, default=20, help="seeds per mutant")
    ap.add_argument("--samples", type=int, default=5000)
    ap.add_argument("--alpha", type=float, default=0.01)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", help="a JSON-lines file for the results, one line a check")
    ap.add_argument("--table", metavar="JSONL", help="print the table of a results file and stop")
    args = ap.parse_args()
    if args.table:
        with open(args.table) as f:
            print(table([json.loads(line) for line in f]))
        return
    zs = samplers()
    seeds = {"correct": args.seeds, "wrong": args.wrong_seeds}
    jobs = [(i, seed, args.samples, args.alpha) for seed in range(max(seeds.values()))
            for i, (kind, _) in enumerate(zs) if seed < seeds[kind]]
    rows = []
    with Pool(args.workers) as pool, open(args.out or os.devnull, "w") as out:
        for row in pool.imap_unordered(_one, jobs, chunksize=1):
            rows.append(row)
            out.write(json.dumps(row) + "\n")
            out.flush()
    print(f"MCMC cross-check, {args.samples} samples, alpha = {args.alpha}, seeds 0..N-1\n")
    print(table(rows))


if __name__ == "__main__":
    main()
