"""False alarms of the sampler check on Mitsuba 3's environment maps, with and without their
texel lines declared as the pdf's breaks (``envmap_sampler(..., texel_breaks=True)``: the
sphere's pole at +y, the bilinear texel lines cut out of every cubature box).

    .venv/bin/python benchmarks/envmap_calibration.py [--seeds 200] [--samples 1e6] [--alpha 0.01]

For the 256 x 128 procedural sky with a soft-rimmed and with a hard-edged sun, and each
setting: the setup's seconds and pdf calls (the cubature and the CDF tables, once), the
transform tables' bounds (u0's and u1's: a bound near 1/sqrt(n) leaves that Cramer-von Mises
test without power), and how many of the seeds 0..N-1 the statistical tests reject at alpha
(false alarms: Mitsuba's envmap draws what its pdf says, up to float32; the deterministic
reported-pdf finding on the sun's rim is not counted here, see benchmarks/mitsuba_samplers.py).
Each seed draws its own uniforms (the check's stream, case 0x5A3F); the samples are tested
as check_mitsuba_sampler tests them (SamplerTest.for_total(P).check_points; a seed where
Mitsuba returned a sample with weight and pdf 0, which the adapter makes a NaN row, through
check_with_missing).  Columns: 'rejected', seeds whose statistical tests on the samples
produced reject at alpha (the false alarms); 'rare', seeds failed by Mitsuba's rare events
instead (a sample not produced, which the failure count's exact test rejects when the pdf
integrates to 1; a sample where the pdf is 0: deterministic failures, findings, not alarms).
"""
from __future__ import annotations

import argparse
import time

import numpy as np
from scipy import stats

import reference_estimators as rest

from harness.adapters.mitsuba.emitters import envmap_sampler, sky_bitmap
from harness.samplers import SAMPLE_CASE, Domain, SamplerTest, check_with_missing


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=200)
    ap.add_argument("--samples", type=float, default=1e6)
    ap.add_argument("--alpha", type=float, default=0.01)
    args = ap.parse_args()
    n = int(args.samples)
    print(f"{n:.0e} samples per check, seeds 0..{args.seeds - 1}, alpha = {args.alpha}; llvm_ad_rgb")
    print(f"{'map':28s} {'texel breaks':12s} {'setup s':>8s} {'pdf calls':>10s} {'u0 bound':>9s} "
          f"{'u1 bound':>9s} {'rejected':>9s} {'99 % upper':>10s} {'rare':>5s}")
    maps = [("sky, sun with a soft rim", sky_bitmap()), ("sky, hard-edged sun", sky_bitmap(sun_edge=0.0))]
    for label, bitmap in maps:
        for texel_breaks in (False, True):
            s = envmap_sampler(bitmap, texel_breaks=texel_breaks)
            domain = Domain("sphere", pole=s.pole)
            calls = [0]

            def pdf(x, s=s):
                calls[0] += x.shape[0]
                return s.pdf(x)

            start = time.perf_counter()
            raw = SamplerTest(pdf, domain, sample_count=n, alpha=args.alpha, breaks=s.breaks)
            test = raw.for_total(raw.normalization[0])
            setup, setup_calls = time.perf_counter() - start, calls[0]
            t = raw.transform
            rejected = rare = 0
            for seed in range(args.seeds):
                x = s.sample(rest.points(n, 2, seed=seed, case_id=SAMPLE_CASE))
                if np.isfinite(x).all():
                    r = test.check_points(x, seed=seed)
                else:
                    r = check_with_missing(lambda u, x=x: x, s.pdf, domain, sample_count=n, seed=seed,
                                           alpha=args.alpha, breaks=s.breaks)
                tests = r.tests[r.tests["test"] != "failed samples"]
                statistical = bool((tests["adjusted"] <= args.alpha).any())
                rejected += statistical
                rare += not r.passed and not statistical
            upper = stats.beta.ppf(0.99, rejected + 1, args.seeds - rejected)
            print(f"{label:28s} {str(texel_breaks):12s} {setup:8.2f} {setup_calls / 1e6:9.1f}M "
                  f"{t.marginal.error:9.1e} {t.conditional.error:9.1e} {rejected:5d}/{args.seeds:<3d} "
                  f"{upper:10.3f} {rare:5d}", flush=True)


if __name__ == "__main__":
    main()
