"""Sampler tests side by side: harness.check_sampler against Mitsuba 3's mitsuba.chi2.ChiSquareTest
(llvm_ad_rgb, its defaults: 1e6 samples, 101 x 202 cells on the sphere, 4 x 4 points per
cell, pooling below 5), on the same zoo of correct and subtly wrong samplers
(harness.samplers.zoo), at the same sample count and seeds.

    .venv/bin/python benchmarks/sampler_tests.py [--seeds 10] [--samples 1e6]

For each sampler: how many of the seeds each test rejected (false alarms for correct
samplers at alpha = 0.01, catches for wrong ones) and the median seconds per test.  Ours is
timed whole: the pdf's cubature (once per test) plus the check; the sampler's own time is
included in both columns.
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from harness.adapters.mitsuba.runtime import use_libllvm
from harness.samplers import SamplerTest, as_domain
from harness.samplers import zoo as sampler_zoo


def mitsuba_test(mi, s, n: int, seed: int) -> tuple[bool, float]:
    dom = as_domain(s.domain)

    def arr(v, k):
        return np.column_stack([np.array(getattr(v, c), dtype=np.float64) for c in "xyz"[:k]])

    if dom.kind in ("hemisphere", "sphere"):
        domain, sdim = mi.chi2.SphericalDomain(), 2
        to_mi = lambda x: mi.Vector3f(x[:, 0], x[:, 1], x[:, 2])  # noqa: E731
        from_mi = lambda v: arr(v, 3)  # noqa: E731
    elif dom.kind == "interval":
        domain, sdim = mi.chi2.LineDomain(bounds=[dom.lo, dom.hi]), 1
        to_mi = lambda x: mi.Point1f(mi.Float(x.reshape(-1)))  # noqa: E731
        from_mi = lambda v: np.array(v if isinstance(v, mi.Float) else v.x, dtype=np.float64)  # noqa: E731
    else:  # square and disk on a planar domain
        lo = [0, 0] if dom.kind == "square" else [-1, -1]
        bounds = mi.ScalarBoundingBox2f(lo, [1, 1])
        domain, sdim = mi.chi2.PlanarDomain(bounds), 2
        to_mi = lambda x: mi.Point2f(x[:, 0], x[:, 1])  # noqa: E731
        from_mi = lambda v: arr(v, 2)  # noqa: E731

    def sample_func(u):
        a = arr(u, sdim)
        with np.errstate(all="ignore"):
            return to_mi(np.asarray(s.sample(a), dtype=np.float64))

    def pdf_func(v):
        with np.errstate(all="ignore"):
            p = np.nan_to_num(np.asarray(s.pdf(from_mi(v)), dtype=np.float64), posinf=0.0)
        return mi.Float(p)

    t = time.perf_counter()
    test = mi.chi2.ChiSquareTest(domain=domain, sample_func=sample_func, pdf_func=pdf_func, sample_dim=sdim,
                                 sample_count=n, seed=seed)
    ok = bool(test.run(0.01, quiet=True))  # quiet: no log printed, no chi2_data.py written on failure
    return ok, time.perf_counter() - t


def ours(s, n: int, seed: int) -> tuple[bool, float]:
    t = time.perf_counter()
    ok = SamplerTest(s.pdf, s.domain, sample_count=n).check(s.sample, seed=seed).passed
    return ok, time.perf_counter() - t


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--samples", default="1e6")
    args = parser.parse_args()
    n = int(float(args.samples))
    use_libllvm()  # before drjit is imported
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    print(f"{n:.0e} samples per test, seeds 0..{args.seeds - 1}, alpha = 0.01; "
          f"'rejected' = failed tests of {args.seeds}\n")
    print(f"{'sampler':58s} {'truth':8s} {'Mitsuba rejected':>16s} {'s/test':>7s} {'ours rejected':>14s} "
          f"{'s/test':>7s}")
    for s in sampler_zoo.correct() + sampler_zoo.wrong():
        m = [mitsuba_test(mi, s, n, seed) for seed in range(args.seeds)]
        o = [ours(s, n, seed) for seed in range(args.seeds)]
        print(f"{s.name[:58]:58s} {'wrong' if s.fault else 'correct':8s} "
              f"{sum(not ok for ok, _ in m):>16d} {statistics.median(t for _, t in m):7.2f} "
              f"{sum(not ok for ok, _ in o):>14d} {statistics.median(t for _, t in o):7.2f}", flush=True)


if __name__ == "__main__":
    main()
