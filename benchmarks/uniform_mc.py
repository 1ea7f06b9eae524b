"""Uniform Monte Carlo of exp(-x^2) on [0, 1]: Msamples/s of the core against numpy and drjit.

All three draw float64 uniforms, evaluate exp(-x^2) in float64 and reduce:
  core   reference_estimators.integrate: PCG32 chunk streams, 52-bit uniforms, compensated
         sum, M2..M4 moments and NaN/Inf/negative screening (what the harness really runs)
  numpy  Generator.random + np.exp + np.sum over 4M-sample batches (numpy is one thread)
  drjit  drjit.llvm PCG32.next_float64 + dr.exp + dr.sum, one fused LLVM kernel, float64
Timings: best of `--repeat` runs after a warm-up (drjit's kernel compilation excluded).

    .venv/bin/python benchmarks/uniform_mc.py [--samples 1e8] [--repeat 5]
"""
from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

import reference_estimators as rest


def best_of(repeat: int, fn) -> float:
    fn()
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def core(n: int, threads: int) -> float:
    return best_of(ARGS.repeat, lambda: rest.integrate("gaussian", "uniform", n, threads=threads))


def numpy_mc(n: int) -> float:
    rng = np.random.default_rng(0)
    batch = 1 << 22

    def run() -> float:
        total = 0.0
        for start in range(0, n, batch):
            x = rng.random(min(batch, n - start))
            total += float(np.sum(np.exp(-x * x)))
        return total / n

    return best_of(ARGS.repeat, run)


def drjit_mc(n: int, threads: int) -> float | None:
    from harness.adapters.mitsuba.runtime import use_libllvm

    use_libllvm()  # before drjit is imported
    try:
        import drjit as dr
        from drjit.llvm import PCG32
    except Exception as e:  # noqa: BLE001 - report why the column is missing, keep the rest
        print(f"drjit unavailable: {e}")
        return None
    dr.set_thread_count(threads)

    def run() -> float:
        x = PCG32(size=n).next_float64()
        return float(dr.sum(dr.exp(-x * x))[0]) / n

    return best_of(ARGS.repeat, run)


def main() -> None:
    n = int(float(ARGS.samples))
    print(f"uniform MC of exp(-x^2) on [0,1], n = {n:.0e} float64 samples, best of {ARGS.repeat}")
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} logical CPUs\n")
    rows = []
    for threads in (1, 2):
        rows.append((f"core, {threads} thread{'s' * (threads > 1)}", core(n, threads)))
    rows.append(("numpy, 1 thread", numpy_mc(n)))
    for threads in (1, 2):
        t = drjit_mc(n, threads)
        if t is not None:
            rows.append((f"drjit LLVM float64, {threads} thread{'s' * (threads > 1)}", t))
    rate = {name: n / t / 1e6 for name, t in rows}
    core2 = rate["core, 2 threads"]
    print(f"{'':36s} {'Msamples/s':>11s} {'core(2 threads) /':>18s}")
    for name, r in rate.items():
        print(f"{name:36s} {r:11.0f} {core2 / r:17.2f}x")
    print(f"\ncore scaling 1 -> 2 threads: {rate['core, 2 threads'] / rate['core, 1 thread']:.2f}x")
    if "drjit LLVM float64, 2 threads" in rate:
        d = rate["drjit LLVM float64, 2 threads"] / rate["drjit LLVM float64, 1 thread"]
        print(f"drjit scaling 1 -> 2 threads: {d:.2f}x")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", default="1e8")
    parser.add_argument("--repeat", type=int, default=5)
    ARGS = parser.parse_args()
    main()
