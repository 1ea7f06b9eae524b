"""Sampler tests side by side: harness.check_sampler against Mitsuba 3's mitsuba.chi2.ChiSquareTest
(llvm_ad_rgb, its defaults: 1e6 samples, 101 x 202 cells on the sphere, 4 x 4 points per
cell, pooling below 5), on the same zoo of correct and subtly wrong samplers
(harness.samplers.zoo), at the same sample count and seeds.

    .venv/bin/python benchmarks/sampler_tests.py [--seeds 10] [--samples 1e6] [--match TEXT] [--ours-only]

For each sampler (the zoo's correct ones, its mutants and the smooth warps below any bin
width): how many of the seeds each test rejected (false alarms for correct samplers at
alpha = 0.01, catches for wrong ones) and the seconds per test.  Mitsuba's is timed whole
(its sampler calls included); ours is split into the setup done once per claimed pdf (the
cubature and the CDF tables), the sampler's own time and the check's time per seed; the
check's time includes one call of the user's pdf at the sampled points, timed again alone
('pdf s'), and 'own s' is the check's own work (check s - pdf s).  'one test s' is what a
single test of a new pdf costs us (setup + sampler s + check s), to set beside Mitsuba's
's/test'; in a run over many seeds of one pdf the setup is paid once.
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import reference_estimators as rest

from harness.adapters.mitsuba.runtime import use_libllvm
from harness.samplers import SAMPLE_CASE, SamplerTest, as_domain
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


def ours(test: SamplerTest, s, seed: int) -> tuple[bool, float, float, float]:
    """(passed, the sampler's own seconds, the check's seconds, the pdf's seconds) for one seed:
    the check's time includes its one call of the user's pdf at the sampled points, timed
    again alone for the last figure, so that check - pdf is the check's own work."""
    n = test.n
    u = rest.points(n, as_domain(s.domain).udim, seed=seed, case_id=SAMPLE_CASE)
    t0 = time.perf_counter()
    x = s.sample(u)
    t1 = time.perf_counter()
    ok = test.check(lambda _u, x=x: x, seed=seed).passed   # the same uniforms, the points already drawn
    t2 = time.perf_counter()
    s.pdf(x)
    return ok, t1 - t0, t2 - t1, time.perf_counter() - t2


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--samples", default="1e6")
    parser.add_argument("--match", default="", help="only the samplers whose name contains this")
    parser.add_argument("--ours-only", action="store_true",
                        help="skip Mitsuba's test (its columns show '-'): a calibration run of ours alone")
    args = parser.parse_args()
    n = int(float(args.samples))
    mi = None
    if not args.ours_only:
        use_libllvm()  # before drjit is imported
        import mitsuba as mi

        mi.set_variant("llvm_ad_rgb")
    print(f"{n:.0e} samples per test, seeds 0..{args.seeds - 1}, alpha = 0.01; "
          f"'rejected' = failed tests of {args.seeds}; ours: the pdf's cubature and CDF tables once per "
          f"sampler ('setup'), then per seed the sampler's own time and the check's\n")
    print(f"{'sampler':50s} {'truth':7s} {'Mitsuba rej':>11s} {'s/test':>7s} {'ours rej':>8s} "
          f"{'setup s':>8s} {'sampler s':>9s} {'check s':>8s} {'pdf s':>6s} {'own s':>6s} "
          f"{'one test s':>10s}")
    samplers = [s for s in sampler_zoo.correct() + sampler_zoo.wrong() + sampler_zoo.smooth_warps()
                if args.match in s.name]
    # one untimed test of each first, on the first sampler: the first test in a process pays
    # one-off costs (ours: pandas' import and the thread pool's start, 0.2 s; Mitsuba's: its
    # variant's start) that the first row would otherwise carry
    if samplers:
        if mi is not None:
            mitsuba_test(mi, samplers[0], n, 0)
        first = samplers[0]
        ours(SamplerTest(first.pdf, first.domain, sample_count=n, breaks=first.breaks), first, 0)
    for s in samplers:
        m = [] if args.ours_only else [mitsuba_test(mi, s, n, seed) for seed in range(args.seeds)]
        t0 = time.perf_counter()
        test = SamplerTest(s.pdf, s.domain, sample_count=n, breaks=s.breaks)
        setup = time.perf_counter() - t0
        o = [ours(test, s, seed) for seed in range(args.seeds)]
        sampler, check, pdf = (statistics.median(r[i] for r in o) for i in (1, 2, 3))
        print(f"{s.name[:50]:50s} {'wrong' if s.fault else 'correct':7s} "
              f"{sum(not ok for ok, _ in m) if m else '-':>11} "
              f"{f'{statistics.median(t for _, t in m):7.2f}' if m else '-':>7} "
              f"{sum(not r[0] for r in o):>8d} {setup:8.2f} "
              f"{sampler:9.3f} {check:8.3f} {pdf:6.3f} {check - pdf:6.3f} {setup + sampler + check:10.3f}",
              flush=True)


if __name__ == "__main__":
    main()
