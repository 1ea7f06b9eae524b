"""False alarms of the convergence slope test (harness.stats.fit_convergence) at the tolerance's
bound and at the promised rate, by replica count and number of budgets.

    .venv/bin/python benchmarks/convergence_calibration.py [--seeds 20000] [--replicas 4 16 32]
                                                           [--budgets 3 5] [--harness-seeds 2000]

Two tables:
  at the bound   synthetic replicas whose errors fall exactly as n^(-0.45), the bound of the
                 default H0 (expected -0.5, tolerance 0.05), fitted by fit_convergence itself,
                 for each error law of KINDS (pooled ones by fit_convergence(pooled=True)),
                 and the power: normal errors falling as n^-0.30 ("slow").
                 The share rejected at p < 5 %, 1 %, 0.1 % is the test's level there;
                 "inconclusive" counts fits it refuses.
  the harness    convergence_rate("gaussian", "uniform", ...) over seeds: a correct estimator
                 at the promised rate (inside the bound); rejections at 2.5 % (its verdict),
                 1 % and 0.2 %.
A rejection share well above its level (beyond the binomial 0.99 quantile) is a test that does
not hold it.  About 3 ms a synthetic fit, 4-10 ms a harness fit.
"""
from __future__ import annotations

import argparse

import numpy as np

from harness import stats

LEVELS = (0.05, 0.01, 0.001)


def synthetic(kind: str, replicas: int, budgets: int, seed: int) -> stats.ConvergenceResult:
    """One fit of replicas whose RMSE falls as n^-0.45 exactly (``kind``: see KINDS), or as
    n^-0.30 for the kind "slow" (normal errors: the test's power)."""
    rng = np.random.default_rng(seed)
    n = 256 * 4.0 ** np.arange(budgets)
    reps = []
    for size in n:
        if kind == "pooled":
            pixels = rng.standard_t(3, (replicas, 3072)) / np.sqrt(3.0)
            draw = np.sqrt((pixels * pixels).mean(axis=1))
        elif kind == "rare":       # a count of rare events, mean size/256: skewed at small budgets
            k = rng.binomial(int(size), 1 / 256, replicas)
            draw = (k - size / 256) / np.sqrt(size / 256 * (1 - 1 / 256))
        else:
            draw = {"normal": lambda: rng.standard_normal(replicas),
                    "slow": lambda: rng.standard_normal(replicas) * size ** 0.15,
                    "t5": lambda: rng.standard_t(5, replicas) / np.sqrt(5 / 3),
                    "lognormal": lambda: rng.lognormal(0.0, 1.0, replicas) - np.exp(0.5)}[kind]()
        reps.append(stats.Replicates("synthetic", kind, int(size), 0.0, draw * size ** -0.45,
                                     np.full(replicas, 1e-3), np.nan, np.nan, False, 1))
    return stats.fit_convergence(reps, pooled=kind == "pooled", seed=seed)


#: Error laws at the bound: normal (a mean of many contributions), t(5) (kurtosis 9), centred
#: log-normal (skewed), rare (a count of events with mean 1, 4, 16, ... at the budgets: its
#: shape changes with the budget, the one case the test is not exact for) and pooled (each
#: replica the root mean square of 3072 t(3) "pixels", as a render's relMSE)
KINDS = ("normal", "t5", "lognormal", "rare", "pooled")
#: The test's power: normal errors whose RMSE falls as n^-0.30, 0.15 slower than the bound
POWER = "slow"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=20_000)
    ap.add_argument("--replicas", type=int, nargs="+", default=[4, 16, 32])
    ap.add_argument("--budgets", type=int, nargs="+", default=[3, 5])
    ap.add_argument("--harness-seeds", type=int, default=2000)
    args = ap.parse_args()
    print(f"seeds: {args.seeds} at the bound, {args.harness_seeds} with the harness")
    print("at the bound (slope -0.45; 'slow', the power: -0.30): rejected at p < 5 % / 1 % / 0.1 %, "
          "inconclusive")
    for kind in (*KINDS, POWER):
        for budgets in args.budgets:
            for replicas in args.replicas:
                fits = [synthetic(kind, replicas, budgets, s) for s in range(args.seeds)]
                p = np.array([f.pvalue for f in fits])
                shares = " / ".join(f"{100 * np.mean(p < level):.2f}" for level in LEVELS)
                undecided = sum(f.verdict == "inconclusive" for f in fits)
                print(f"  {kind:7s} {budgets} budgets x {replicas:3d} replicas: {shares} %, "
                      f"{undecided} inconclusive", flush=True)
    print("the harness, gaussian/uniform at the promised rate: rejected at p < 2.5 % / 1 % / 0.2 %, "
          "inconclusive")
    for budgets in args.budgets:
        b = [1024 * 4 ** k for k in range(budgets)]
        for replicas in args.replicas:
            fits = [stats.convergence_rate("gaussian", "uniform", b, replicas, seed=s)
                    for s in range(args.harness_seeds)]
            p = np.array([f.pvalue for f in fits])
            counts = " / ".join(str(int(np.sum(p < level))) for level in (0.025, 0.01, 0.002))
            undecided = sum(f.verdict == "inconclusive" for f in fits)
            print(f"  {budgets} budgets x {replicas:3d} replicas: {counts} of {args.harness_seeds}, "
                  f"{undecided} inconclusive", flush=True)


if __name__ == "__main__":
    main()
