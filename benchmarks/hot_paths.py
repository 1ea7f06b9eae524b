"""Importance sampling, MIS and Sobol' points: Msamples/s of the core's `integrate` against numpy
and drjit implementations of the same estimators, side by side in one run.

Rows (integrand, catalogue technique):
  gaussian2d  importance:piecewise_constant_2d              f/p, p the 16x16 table sampler
  gaussian2d  mis_balance:uniform_box+piecewise_constant_2d one draw from each, balance heuristic
  gaussian2d  uniform/sobol                                 f at scrambled Sobol' points
  ggx_lobe    importance:ggx                                f/p, p = GGX D cos (zero variance)
  ggx_lobe    importance:cosine_hemisphere                  f/p, p = cos / pi
  ggx_lobe    mis_balance:cosine_hemisphere+ggx             one draw from each, balance heuristic
gaussian2d = exp(-|x - (0.3, 0.6)|^2 / (2 0.08^2)) on [0,1]^2; ggx_lobe = GGX D(w) cos(theta),
alpha = 0.01, over the hemisphere.  A sample is one contribution Y (an MIS sample draws one
point from each of its two samplers and evaluates f at both).

All three implementations run the core's estimator math in float64: the same samplers (the
piecewise-constant 2D sampler inverts the marginal CDF over rows, then the row's conditional
CDF, on the table the core builds: f at the cell centres + 1e-3), the same pdfs and the same
sums (f/p; MIS: sum_i f(X_i) / sum_j p_j(X_i)).
The numpy and drjit versions share one implementation of that math (written against a small
array interface, `NumpyOps` / `DrjitOps`, in hot_path_peers.py), checked against the core's own samplers and
integrands on the same uniforms before anything is timed.
  core   reference_estimators.integrate: PCG32 chunk streams, compensated sum, M2..M4 moments,
         point, pdf and NaN/Inf screening (what the harness runs); Sobol': Owen-scrambled
         (Burley's hash) Sobol' points
  numpy  Generator.random in batches of 2^21 samples; bins by np.searchsorted (the conditional
         CDFs as one array, row r shifted by r: one search for all rows); one thread.  Sobol':
         scipy.stats.qmc.Sobol(d=2, scramble=True), whose scrambling is a linear matrix scramble
         plus digital shift, not Owen's: a scrambled Sobol' estimator, not the core's bits
  drjit  drjit.llvm, one fused kernel per estimate: PCG32.next_float64, dr.gather for the
         tables, a branchless binary search over the CDFs, dr.sum (symbolic mode).  drjit has no
         Sobol' generator; its column runs the core's construction written in drjit's integer
         ops (the same Joe-Kuo direction numbers, Burley's Owen scrambling, the core's seeds):
         the same points as the core, bit for bit.
On ggx_lobe f and every pdf read a direction's cos theta alone: all three draw z alone (the
core's polar path, Integrand.polar and Sampler.polar; drjit's tracer would drop the rest
anyway), the same bits as the whole directions' z.  The core's polar path also generates only
the uniforms it reads (each sampler's u0, the even-numbered ones of its stream; for importance
sampling inside the sampler's loop, a generator row at a time, so that PCG32's
multiplications overlap the sampler's divisions as in drjit's fused loop) and computes
f once where it is a sampler's pdf (the GGX lobe and GGX's pdf: Sampler.polar_function), as
drjit's tracer leaves out what nothing reads and merges equal expressions.  An MIS pair whose
f is one sampler's pdf runs in one loop (polar_mis.cpp): both techniques' draws, pdfs, weights
and terms in registers, each generator row's cosines drawn a row ahead of its terms.  The
"core path" lines name the path each row took (Estimate.kernel) and the blocks that went back
to the general path (Estimate.redone_blocks: 0 for these samplers), and the table sampler's
path for whole vectors of points (Sampler.kernel: on AVX-512 the 16 x 16 table is counted in
vector lanes, small_table2d.h).
Not in the peers: the core's screening of points, pdfs and contributions and its higher
moments (these samplers never produce a point the core would exclude).

Before timing, each numpy and drjit estimator runs at n = 2^18 against the exact reference
(Sobol' rows: 8 independent scrambles, the error from their spread); one more than 6 standard
errors off prints a loud warning.

Columns of the throughput table, in Msamples/s (n / best wall time):
  core 1, core 2      reference_estimators.integrate with threads=1 and 2 (the runs alternate)
  numpy               the numpy estimator (numpy is one thread)
  drjit 1, drjit 2    the drjit LLVM float64 estimator with 1 and 2 threads (alternating)
  core2/numpy         core with 2 threads over numpy
  core2/drjit2        core with 2 threads over drjit with 2 threads
Columns of the estimates table: the core's mean and standard error (Sobol': the spread of 8
independently scrambled replicas of the core, its samples being dependent), then the numpy and
drjit means from their last timed run; they agree within a few standard errors.
Timings: best of `--repeat` runs after a warm-up (drjit's kernel compilation excluded).

Last, a stage profile of each row in ns per sample and thread, at 1 and 2 threads: the core's
stages are differences of its pipeline's prefixes (reference_estimators.profile_stages: the
uniforms; the samplers' points and pdfs; their screening; for MIS every technique's pdf at
every point; the integrand and the estimator's arithmetic; the contributions' screening and
accumulation), each prefix timed alone, so a stage near 0 can come out slightly negative on
a noisy machine (on the polar path, ggx_lobe's rows, the samplers screen z and the pdf in their
own pass: the screening stage is in the sampling one and reads 0; and importance sampling
draws its u0s in that pass too, so its sampling stage is what the pass adds to drawing them
alone, less than the two apart; the MIS pair's prefixes are its one loop stopped early, so
its stages are what each part adds to that loop); drjit's are its uniforms
(a kernel that draws and sums them) and the rest of its whole kernel.

    .venv/bin/python benchmarks/hot_paths.py [--samples 2e7] [--repeat 3] [--no-drjit]
"""
from __future__ import annotations

import argparse
import math
import os
import sys
from dataclasses import replace
from functools import partial
from typing import Any, Callable

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from hot_path_peers import (  # noqa: E402
    ROWS,
    TABLE_RES,
    DrjitPeer,
    NumpyOps,
    PiecewiseConstant2D,
    Row,
    cosine_pdf,
    gaussian2d,
    gaussian2d_table,
    ggx_lobe,
    numpy_estimate,
    sample_cosine,
    sample_ggx,
)
from uniform_mc import add_core_arguments, alternating, best_of, cpu_line, load_core, numpy_simd  # noqa: E402

N_VALIDATE = 1 << 18        # samples of each validation run
SOBOL_REPLICAS = 8          # independent scrambles behind a Sobol' error
Z_FAIL = 6.0                # |estimate - reference| / stderr above this is a failure
CHECK_POINTS = 4096         # uniforms of the cross-check against the core's samplers


# --- checks before timing --------------------------------------------------------------------
def worst_difference(ours: list[np.ndarray], theirs: list[np.ndarray]) -> float:
    """Largest |a - b| / max(|b|, 1) over pairs of arrays."""
    return max(float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1.0))) for a, b in zip(ours, theirs))


def cross_check(rest: Any, table: PiecewiseConstant2D, ops: Any) -> dict[str, float]:
    """Worst relative difference to the core's samplers (points and pdf from the same uniforms,
    pdf at the core's points) and integrands, for the table, GGX and cosine samplers."""
    u = np.random.default_rng(7).random((CHECK_POINTS, 2))
    uu = [ops.from_numpy(u[:, 0]), ops.from_numpy(u[:, 1])]
    out = {}
    core = rest.technique("gaussian2d", "importance:piecewise_constant_2d").sampler
    x, p = core.sample(u)
    cx = [ops.from_numpy(x[:, 0]), ops.from_numpy(x[:, 1])]
    ours = [*table.sample(ops, *uu), table.pdf(ops, *cx), gaussian2d(ops, *cx)]
    truth = [x[:, 0], x[:, 1], p, core.pdf(x), rest.integrand("gaussian2d").eval(x)]
    out["piecewise_constant_2d"] = worst_difference([ops.to_numpy(a) for a in ours], truth)
    directions = (("ggx", sample_ggx, ggx_lobe), ("cosine_hemisphere", sample_cosine, cosine_pdf))
    for name, sample, pdf in directions:
        core = rest.technique("ggx_lobe", f"importance:{name}").sampler
        w, p = core.sample(u)
        cw = tuple(ops.from_numpy(w[:, j]) for j in range(3))
        ws, ps = sample(ops, *uu)
        ours = [*ws, ps, pdf(ops, cw[2]), ggx_lobe(ops, cw[2])]
        truth = [w[:, 0], w[:, 1], w[:, 2], p, core.pdf(w), rest.integrand("ggx_lobe").eval(w)]
        out[name] = worst_difference([ops.to_numpy(a) for a in ours], truth)
    return out


def z_score(rest: Any, row: Row, estimate: Callable[[int], tuple[float, float]]) -> float:
    """(estimate - reference) / stderr at n = N_VALIDATE; Sobol': over SOBOL_REPLICAS scrambles."""
    reference = rest.integrand(row.integrand).reference
    if row.sobol:
        means = [estimate(replica)[0] for replica in range(SOBOL_REPLICAS)]
        mean, stderr = float(np.mean(means)), float(np.std(means, ddof=1)) / math.sqrt(SOBOL_REPLICAS)
    else:
        mean, stderr = estimate(0)
    return (mean - reference) / (stderr + 1e-12 * abs(reference))  # zero-variance rows: rounding


def core_sobol_spread(rest: Any, row: Row, n: int) -> float:
    """Standard deviation of the core's estimate over SOBOL_REPLICAS independent scrambles."""
    means = [rest.integrate(row.integrand, row.technique, n, replica=r, threads=2).mean
             for r in range(SOBOL_REPLICAS)]
    return float(np.std(means, ddof=1))


# --- timing and printing ---------------------------------------------------------------------
def recorded(store: dict[str, Any], key: str, fn: Callable[[], Any]) -> Callable[[], Any]:
    """fn, keeping its last result in store[key]."""
    return lambda: store.__setitem__(key, fn())


def time_row(rest: Any, row: Row, table: PiecewiseConstant2D, n: int, repeat: int,
             drjit: DrjitPeer | None) -> tuple[dict[str, float], dict[str, Any]]:
    """Best seconds and last result of each implementation on one row."""
    results: dict[str, Any] = {}
    shift = rest.integrand(row.integrand).reference

    def core(k: int) -> Callable[[], Any]:
        run = partial(rest.integrate, row.integrand, row.technique, n, threads=k)
        return recorded(results, f"core {k}", run)

    seconds = {f"core {k}": s for k, s in alternating(repeat, {1: core(1), 2: core(2)}).items()}
    numpy_run = recorded(results, "numpy", lambda: numpy_estimate(row, table, n, shift))
    seconds["numpy"] = best_of(repeat, numpy_run)
    if drjit is not None:
        def dj(k: int) -> Callable[[], Any]:
            return recorded(results, f"drjit {k}", partial(drjit.estimate, row, table, n, shift, threads=k))

        seconds.update({f"drjit {k}": s for k, s in alternating(repeat, {1: dj(1), 2: dj(2)}).items()})
    return seconds, results


def column(value: float | None, fmt: str, width: int, unit: str = "") -> str:
    """value right-aligned in `width` characters with `unit` after it, or n/a."""
    text = "n/a" if value is None else f"{value:{fmt}}{unit}"
    return f"{text:>{width}s}"


def print_throughput(n: int, seconds: dict[Row, dict[str, float]]) -> None:
    names = ("core 1", "core 2", "numpy", "drjit 1", "drjit 2")
    print(f"\nMsamples/s{'':38s}" + "".join(f"{c:>9s}" for c in names)
          + f"{'core2/numpy':>13s}{'core2/drjit2':>14s}")
    for row, s in seconds.items():
        rate = {c: n / s[c] / 1e6 if c in s else None for c in names}
        ratio = [rate["core 2"] / rate[c] if rate[c] else None for c in ("numpy", "drjit 2")]
        print(f"{row.integrand:10s} {row.technique:46s}" + "".join(column(rate[c], ".1f", 9) for c in names)
              + column(ratio[0], ".2f", 13, "x") + column(ratio[1], ".2f", 14, "x"))


def print_kernels(rest: Any, results: dict[Row, dict[str, Any]]) -> None:
    """The path each row's estimate took through the core (Estimate.kernel) and how many of
    its blocks went back to the general path, and the path the table sampler takes for whole
    vectors of points (Sampler.kernel) (a core without these fields: '?')."""
    print("\ncore path (two threads; blocks redone on the general path):")
    for row, r in results.items():
        e = r["core 2"]
        print(f"  {row.integrand:10s} {row.technique:46s} {getattr(e, 'kernel', '?') or '?':34s} "
              f"{getattr(e, 'redone_blocks', '?')}")
    table = rest.technique("gaussian2d", "importance:piecewise_constant_2d").sampler
    print(f"  the {TABLE_RES}x{TABLE_RES} table sampler: {getattr(table, 'kernel', '?')}")


def print_estimates(rest: Any, n: int, results: dict[Row, dict[str, Any]]) -> None:
    print(f"\nestimates (n = {n:.3g}){'':25s}{'core':>19s}{'stderr':>11s}{'numpy':>19s}{'drjit':>19s}")
    for integrand in dict.fromkeys(row.integrand for row in results):
        print(f"{integrand}: reference {rest.integrand(integrand).reference!r}")
        for row in (r for r in results if r.integrand == integrand):
            r = results[row]
            stderr = core_sobol_spread(rest, row, n) if row.sobol else r["core 2"].stderr
            peers = [r[k][0] if k in r else None for k in ("numpy", "drjit 2")]
            print(f"  {row.technique:46s}{r['core 2'].mean:19.15f}{stderr:10.2e}{'*' if row.sobol else ' '}"
                  + "".join(column(v, ".15f", 19) for v in peers))
    print(f"  * the spread of {SOBOL_REPLICAS} independently scrambled replicas "
          "(Sobol' samples are dependent)")


def print_checks(rest: Any, table: PiecewiseConstant2D, peers: dict[str, tuple[Any, Callable]]) -> None:
    """The cross-check against the core's samplers and the validation against the references."""
    print(f"\ncross-check on {CHECK_POINTS} uniforms, worst relative difference to the core's samplers "
          "(points, pdfs) and integrands:")
    for name, (ops, _) in peers.items():
        worst = cross_check(rest, table, ops)
        print(f"  {name:6s} " + "  ".join(f"{k} {v:.1e}" for k, v in worst.items()))
        for k, v in worst.items():
            if v > 1e-9:
                print(f"!!! WARNING: {name}'s {k} differs from the core's by {v:.2e}: "
                      "not the same sampler !!!")
    print(f"\nvalidation at n = {N_VALIDATE} (z = (estimate - reference) / stderr; Sobol': "
          f"{SOBOL_REPLICAS} scrambles):")
    for row in ROWS:
        reference = rest.integrand(row.integrand).reference
        zs = {name: z_score(rest, row, lambda rep, est=est: est(row, table, N_VALIDATE, reference, rep))
              for name, (_, est) in peers.items()}
        print(f"  {row.integrand:10s} {row.technique:46s}"
              + "".join(f"  {k} z = {z:+6.2f}" for k, z in zs.items()))
        for name, z in zs.items():
            if not abs(z) <= Z_FAIL:
                print(f"!!! WARNING: {name} {row.integrand} {row.technique} is {z:+.1f} standard errors "
                      "off the reference: its timing below is of a wrong estimator !!!")


# The core's pipeline prefixes (reference_estimators.profile_stages) and the stage each adds.
STAGES = (("points", "points"), ("sampled", "sampling"), ("screened", "screening"),
          ("weighted", "MIS weights"), ("contributions", "integrand"), ("full", "accumulation"))


def core_stages(rest: Any, row: Row, n: int, threads: int, repeat: int) -> dict[str, float | None]:
    """Best seconds of each prefix of the core's pipeline on one row (None: no such stage)."""
    best: dict[str, float | None] = {}
    for _ in range(repeat + 1):   # the first run is the warm-up, as in best_of
        d = rest.profile_stages(row.integrand, row.technique, n, threads=threads)
        best = {k: None if d[k] is None else min(d[k], best.get(k) or math.inf) for k, _ in STAGES}
    return best


def uniforms_only(ops: Any, table: PiecewiseConstant2D, u: Any) -> Any:
    """The sum of a sample's uniforms: a kernel that draws them and nothing else."""
    total = u[0]
    for v in u[1:]:
        total = total + v
    return total


def print_stages(rest: Any, n: int, repeat: int, drjit: DrjitPeer | None, table: PiecewiseConstant2D) -> None:
    """Where each row's time goes, in ns per sample and thread: the core's stages (differences of
    its pipeline's prefixes, each timed alone) and drjit's uniforms (a kernel summing them)
    against its whole kernel."""
    print(f"\nstage profile, ns per sample and thread (best of {repeat}; a stage = the difference of two "
          "prefixes of the pipeline, each timed alone):")
    print("  core: points = the uniforms (PCG32 or Sobol'; the polar path's u0s alone); sampling = the "
          "samplers' points and pdfs;\n  screening = the points' "
          "domain and pdf checks; MIS weights = every technique's pdf at every "
          "point; integrand = f and the\n  estimator's arithmetic; accumulation = the contributions' "
          "screening, compensated sum and M2..M4")
    print("  drjit: uniforms = PCG32.next_float64 (or the Sobol' points) summed; rest = its whole kernel "
          "less that")
    print(f"{'':58s}" + "".join(f"{label:>13s}" for _, label in STAGES) + f"{'core all':>10s}"
          + f"{'drjit unif.':>12s}{'drjit rest':>11s}{'drjit all':>10s}")
    for row in ROWS:
        uniforms = replace(row, contribution=uniforms_only)   # its sum's mean: udim / 2
        reference = rest.integrand(row.integrand).reference
        for k in (1, 2):
            ns = {key: None if v is None else v * 1e9 * k / n
                  for key, v in core_stages(rest, row, n, k, repeat).items()}
            cells, last = [ns["points"]], ns["points"]
            for key, _ in STAGES[1:]:
                cells.append(None if ns[key] is None else ns[key] - last)
                last = last if ns[key] is None else ns[key]
            dj: list[float | None] = [None, None, None]
            if drjit is not None:
                drjit.threads(k)
                unif = best_of(repeat, lambda: drjit.estimate(uniforms, table, n, row.udim / 2))
                full = best_of(repeat, lambda: drjit.estimate(row, table, n, reference))
                dj = [unif * 1e9 * k / n, (full - unif) * 1e9 * k / n, full * 1e9 * k / n]
            print(f"{row.integrand:10s} {row.technique:44s} {k}t"
                  + "".join(column(c, ".2f", 13) for c in cells) + column(ns["full"], ".2f", 10)
                  + column(dj[0], ".2f", 12) + column(dj[1], ".2f", 11) + column(dj[2], ".2f", 10))


def main() -> None:
    rest = load_core(ARGS.core)

    n, repeat = int(float(ARGS.samples)), ARGS.repeat
    print(f"core integrate against numpy and drjit: importance sampling, MIS, Sobol'; n = {n:.3g} "
          f"samples a row, best of {repeat}")
    print(f"CPU: {cpu_line()}")
    print(f"core build_info: {rest.build_info()}")
    print(f"numpy {np.__version__}: kernels run {numpy_simd()}")
    table = PiecewiseConstant2D(gaussian2d_table(rest))
    peers: dict[str, tuple[Any, Callable]] = {"numpy": (NumpyOps, numpy_estimate)}
    drjit = None
    if not ARGS.no_drjit:
        try:
            drjit = DrjitPeer(ARGS.drjit_target, rest.sobol.direction_numbers(2))
            print(drjit.describe())
            peers["drjit"] = (drjit.ops, drjit.estimate)
        except Exception as e:  # noqa: BLE001 - report why the columns are missing, keep the rest
            print(f"drjit unavailable: {e}")
    print_checks(rest, table, peers)
    seconds, results = {}, {}
    for row in ROWS:
        seconds[row], results[row] = time_row(rest, row, table, n, repeat, drjit)
    print_throughput(n, seconds)
    print_kernels(rest, results)
    print_estimates(rest, n, results)
    print_stages(rest, n, repeat, drjit, table)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", default="2e7", help="samples (contributions) a row")
    parser.add_argument("--repeat", type=int, default=3)
    add_core_arguments(parser)
    ARGS = parser.parse_args()
    main()
