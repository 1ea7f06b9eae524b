"""False-alarm rate of the multi-scale render bias test on real renders: Mitsuba 3's path and
light tracers (cornell, glossy; LLVM) and pyrender's soft shadows and antialiasing, at low
sample counts (the sparse, skewed pixels a CI suite renders), side by side with the peer
(Welch per pixel-channel against the reference's parts, Bonferroni).

    .venv/bin/python benchmarks/render_calibration.py [--seeds 100] [--spp 4] [--replicas 4 8 16]
                                                      [--only cornell glossy pyrender]

Per configuration: a reference of 8 parts rendered by the configuration's reference renderer
(Mitsuba: a path tracer; pyrender: the same technique) at 2048 spp each, then for every seed 16
replica renders at ``--spp`` (seeds seed * 16 + k), of which the first 4, 8 or 16 are tested.
Every configuration is unbiased, so each "biased" is a false alarm (alpha = 0.01: 1 of 100
expected; more than 4 of 100 is beyond the binomial 0.99 quantile).  A planted bias row per
configuration (an 8 x 8 region 5 % too bright in every replica) gives the power.
"""
from __future__ import annotations

import platform
import time

import calibration_args
import numpy as np
import pandas as pd
from scipy import stats as sps

from harness.adapters import renderer
from harness.stats.images import Reference, pixel_bias_test

CONFIGS = {
    "cornell path (depth 2)": ("mitsuba", {"scene": "cornell", "integrator": "path", "max_depth": 2}),
    "cornell ptracer (depth 2)": ("mitsuba", {"scene": "cornell", "integrator": "ptracer", "max_depth": 2}),
    "cornell path (depth 4)": ("mitsuba", {"scene": "cornell", "integrator": "path", "max_depth": 4}),
    "glossy path": ("mitsuba", {"scene": "glossy", "integrator": "path", "max_depth": 3}),
    "glossy ptracer": ("mitsuba", {"scene": "glossy", "integrator": "ptracer", "max_depth": 3}),
    "pyrender soft shadow": ("pyrender", {"scene": "shadow", "technique": "soft_shadow"}),
    "pyrender antialias": ("pyrender", {"scene": "edges", "technique": "antialias"}),
}
PARTS, PART_SPP = 8, 2048


def _peer(images: np.ndarray, parts: np.ndarray, alpha: float) -> bool:
    with np.errstate(all="ignore"):
        p = sps.ttest_ind(images, parts, axis=0, equal_var=False).pvalue
    p = np.nan_to_num(p, nan=1.0)
    return bool(p.min() * p.size <= alpha)


def _plant(images: np.ndarray) -> np.ndarray:
    out = images.copy()
    out[:, 8:16, 8:16] *= 1.05
    return out


def main() -> None:
    parser = calibration_args.parser(__doc__, 100)
    parser.add_argument("--spp", type=int, default=4)
    args = parser.parse_args()
    print(f"{platform.processor() or platform.machine()}, Python {platform.python_version()}; "
          f"{args.spp} spp a replica, seeds 0..{args.seeds - 1}, alpha = 0.01")
    rows = []
    for name, (adapter, spec) in CONFIGS.items():
        if args.only and not any(s in name for s in args.only):
            continue
        if adapter == "mitsuba":
            spec = {**spec, "variant": "llvm_ad_rgb"}
        start = time.perf_counter()
        r = renderer(adapter, spec)
        exact = r.exact()
        ref_r = r.reference()
        parts = np.stack([ref_r.render(PART_SPP, 10**6 + k).image for k in range(PARTS)])
        reference = Reference.exact(exact) if exact is not None else Reference.from_parts(parts)
        renders = [np.stack([r.render(args.spp, s * 16 + k).image for k in range(16)])
                   for s in range(args.seeds)]
        for reps in args.replicas:
            for fault, change in (("-", None), ("8x8 region +5 %", _plant)):
                verdicts, peer, scales = [], 0, {}
                for x in renders:
                    x = x[:reps] if change is None else change(x[:reps])
                    b = pixel_bias_test(x, reference, args.spp)
                    verdicts.append(b.verdict)
                    if b.verdict == "biased":
                        scales[b.worst_scale.name] = scales.get(b.worst_scale.name, 0) + 1
                    peer += _peer(x, parts, 0.01)
                k, n = verdicts.count("biased"), len(verdicts)
                ci = sps.binomtest(k, n).proportion_ci(0.95, method="exact")
                rows.append({"configuration": name, "fault": fault, "replicas": reps, "runs": n, "biased": k,
                             "inconclusive": verdicts.count("inconclusive"),
                             "invalid": verdicts.count("invalid"),
                             "rate": k / n, "rate_lo": ci.low, "rate_hi": ci.high, "peer": peer,
                             "rejecting scales": ", ".join(f"{s} {c}" for s, c in sorted(scales.items()))})
        print(f"{name}: {time.perf_counter() - start:.0f} s", flush=True)
    table = pd.DataFrame(rows)
    for title, part in (("unbiased renders (rate = false-alarm rate)", table[table["fault"] == "-"]),
                        ("planted bias (rate = power)", table[table["fault"] != "-"])):
        print(f"\n{title}")
        print(part.to_string(index=False, float_format=lambda v: f"{v:.3f}"))


if __name__ == "__main__":
    main()
