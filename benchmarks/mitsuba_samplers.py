"""Which Mitsuba 3 samplers pass: every plugin of harness.adapters.mitsuba.catalogue.catalogue()
(diffuse, roughconductor GGX/Beckmann at alpha 0.01, 0.1, 0.5 with and without visible-normal
sampling, roughdielectric, roughplastic, the microfacet distributions; mask, twosided,
blendbsdf, principled, plastic; the phase functions hg, rayleigh, blendphase; envmaps; area
lights on a rectangle and a sphere with constant and bitmap radiance, nearest and bilinear)
at each of its incident angles or reference points, and the planted faults of
wrong_catalogue(), through

  chi2      check_mitsuba_sampler: check_sampler's tests on the directions Mitsuba produced
            plus an exact binomial test of the samples it did not produce (failed, or of a
            Dirac lobe); p-values Holm-corrected across the whole table (real and planted) at
            family-wise alpha = 0.01; area lights in their map (a rectangle's square, else the
            equal-area map of their cap; the domain column says which);
  reported  the pdf each sample call reports against pdf() at the returned direction
            (1e-4 relative + float32 rounding of the direction: harness.adapters.mitsuba.checks);
            deterministic, no alpha;
  weight    weight_consistency: the weight bsdf.sample / phase.sample /
            emitter.sample_direction returns against eval / pdf at the returned direction
            (1e-4 relative + float32 rounding); deterministic, no alpha; 'n/a' for microfacet
            distributions (no weight);
  mitsuba   Mitsuba's own mitsuba.chi2.ChiSquareTest on the same sample / pdf pair (its
            SphericalDomain, failed and Dirac-lobe samples given weight 0), at its own level
            0.01 per test, the same sample count; no multiple-testing correction.

    .venv/bin/python benchmarks/mitsuba_samplers.py [--samples 1e6] [--seed 0] [--csv out.csv]
                                                    [--only TEXT] [--group GROUP,...] [--start K]
                                                    [--no-mitsuba] [--warm-up 16384]

Columns: P is the pdf's integral over the domain (cubature, ± its error bound; in its map for
area lights); 'failed' the samples Mitsuba did not produce of n ('δ' of those sampled a
Dirac lobe, in the weight check's draw); p the check's smallest within-check Holm-adjusted
p-value, 'adj' after Holm over the table; 'rep' the reported-pdf verdict with its mismatch
count and the largest relative difference over the weight check's draw (every plugin: it is
0 where Mitsuba computes the reported pdf with pdf() itself); 'weight' the verdict with the
number of mismatching weights and the largest relative difference; 'exp' whether the
failing checks are the entry's documented ones (a real plugin: its Mitsuba finding, else
none; a planted fault: the check of its kind); seconds: 's ours' for check_mitsuba_sampler
(pdf cubature and reported pdf included: the test beside Mitsuba's), 's wt' for the weight
check, 's mi' for Mitsuba's test, each entry's checks first run untimed on --warm-up samples
so that drjit's JIT compilation of the plugin's kernels (cached for the process) is in none
of them (Mitsuba's test, run after ours, reuses those kernels).  llvm_ad_rgb on the CPU.
The findings are in the catalogue's entries (``finding``) and the README.
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from harness.adapters.mitsuba.catalogue import catalogue, run_catalogue, wrong_catalogue
from harness.adapters.mitsuba.runtime import use_libllvm


def mitsuba_chi2(s, n: int, seed: int) -> tuple[str, float]:
    """Mitsuba's ChiSquareTest on sampler s (world directions): ('pass' | 'FAIL', seconds)."""
    import mitsuba as mi

    from harness.adapters.mitsuba.runtime import using_variant

    def sample_func(u):
        a = np.column_stack([np.array(c, dtype=np.float64) for c in u])
        b = s.sample_batch(a)
        x = np.where(b.valid[:, None], b.x, [0.0, 0.0, 1.0])
        return mi.Vector3f(x[:, 0], x[:, 1], x[:, 2]), mi.Float(b.valid.astype(np.float32))

    def pdf_func(v):
        x = np.column_stack([np.array(c, dtype=np.float64) for c in (v.x, v.y, v.z)])
        with np.errstate(all="ignore"):
            return mi.Float(np.nan_to_num(np.asarray(s.pdf(x), dtype=np.float64), posinf=0.0))

    start = time.perf_counter()
    with using_variant(s.variant):
        test = mi.chi2.ChiSquareTest(domain=mi.chi2.SphericalDomain(), sample_func=sample_func,
                                     pdf_func=pdf_func, sample_dim=s.udim, sample_count=n, seed=seed)
        ok = bool(test.run(0.01, quiet=True))  # quiet: no log, no chi2_data.py written on failure
    return ("pass" if ok else "FAIL"), time.perf_counter() - start


def _row(r) -> str:
    theta = "" if r["theta"] is None or r["theta"] != r["theta"] else f"{r['theta']:g}°"
    weight = (r["weight"] if r["weight"] == "n/a"
              else f"{r['weight']} {r['weight_mismatches']}/{r['weight_max_rel']:.1e}")
    if r["bad_weights"]:
        weight += f" ({r['bad_weights']} NaN/Inf/neg)"
    rep = f"{r['reported']} {r['reported_mismatches']}/{r['reported_max_rel']:.1e}"
    return (f"{r['plugin'][:52]:52s} {theta:>4s} {r['domain'][:4]:4s} {r['P']:.5f}±{r['P_err']:.0e} "
            f"{r['failed']:>7d} {r['delta']:>7d} {r['pvalue']:9.2g} {r.get('adjusted', float('nan')):9.2g} "
            f"{r.get('chi2', ''):5s} {rep:18s} {weight:22s} {r.get('mitsuba', ''):5s} "
            f"{r.get('expected', ''):3s} {r['seconds_chi2']:6.2f} {r['seconds_weight']:5.2f} "
            f"{r.get('seconds_mitsuba', float('nan')):5.2f}"
            + (f"  {r['failures']}" if r["failures"] else "") + (f"  [{r['fault']}]" if r["fault"] else ""))


HEADER = (f"{'plugin':52s} {'θi':>4s} {'dom':4s} {'P (pdf integral)':16s} {'failed':>7s} {'δ':>7s} {'p':>9s} "
          f"{'adj':>9s} {'chi2':5s} {'rep mism/max rel':18s} {'weight mism/max rel':22s} {'mitsu':5s} "
          f"{'exp':3s} {'s ours':>6s} {'s wt':>5s} {'s mi':>5s}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", default="1e6")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--alpha", type=float, default=0.01)
    parser.add_argument("--csv", default=None)
    parser.add_argument("--only", default=None, help="run only entries whose label contains this text")
    parser.add_argument("--group", default=None,
                        help="run only real entries of these catalogue groups (comma-separated, e.g. "
                             "phase,emitter,mask) and the planted faults")
    parser.add_argument("--start", type=int, default=0, help="skip the first START entries (resume a run)")
    parser.add_argument("--warm-up", type=int, default=16384,
                        help="samples of an untimed first run of each entry's checks, which compiles the "
                             "plugin's kernels (0: none; the first timed test then pays drjit's JIT)")
    parser.add_argument("--no-mitsuba", action="store_true", help="skip Mitsuba's own ChiSquareTest")
    args = parser.parse_args()
    n = int(float(args.samples))
    use_libllvm()  # before drjit is imported (the catalogue imports Mitsuba lazily)
    entries = catalogue() + wrong_catalogue()
    if args.only:
        entries = [e for e in entries if args.only in e.label]
    if args.group:
        groups = set(args.group.split(",")) | {"wrong"}
        entries = [e for e in entries if e.group in groups]
    entries = entries[args.start:]
    print(f"{n:.0e} samples per check, seed {args.seed}, family-wise alpha = {args.alpha} "
          f"(Holm over {len(entries)} checks), llvm_ad_rgb\n", flush=True)
    start = time.perf_counter()
    theirs: dict[str, tuple[str, float]] = {}

    def progress(row: dict) -> None:
        if not args.no_mitsuba:
            e = next(e for e in entries if e.label == row["label"])
            theirs[e.label] = mitsuba_chi2(e.make(), n, args.seed)
            row["mitsuba"], row["seconds_mitsuba"] = theirs[e.label]
        print(_row(row), file=sys.stderr, flush=True)

    print("running (unadjusted):\n" + HEADER, file=sys.stderr, flush=True)
    table = run_catalogue(entries, sample_count=n, seed=args.seed, alpha=args.alpha, warm_up=args.warm_up,
                          progress=progress)
    table["mitsuba"] = [theirs.get(label, ("", np.nan))[0] for label in table["label"]]
    table["seconds_mitsuba"] = [theirs.get(label, ("", np.nan))[1] for label in table["label"]]
    print(HEADER)
    for real in (True, False):
        print("\nreal plugins:" if real else "\nplanted faults (must FAIL in the check of their kind):")
        for _, r in table[(table["fault"] == "") == real].iterrows():
            print(_row(r))
    real = table[table["fault"] == ""]
    wrong = table[table["fault"] != ""]
    print(f"\nreal plugins: chi2 pass {int((real['chi2'] == 'pass').sum())} of {len(real)}, reported pdf "
          f"pass {int((real['reported'] == 'pass').sum())} of {len(real)}, weight pass "
          f"{int((real['weight'] == 'pass').sum())} of {int((real['weight'] != 'n/a').sum())}, Mitsuba's "
          f"ChiSquareTest pass {int((real['mitsuba'] == 'pass').sum())} of {len(real)}; as documented "
          f"{int((real['expected'] == 'yes').sum())} of {len(real)}")
    print(f"planted faults caught by their check {int((wrong['expected'] == 'yes').sum())} of {len(wrong)} "
          f"(Mitsuba's ChiSquareTest rejects {int((wrong['mitsuba'] == 'FAIL').sum())}); "
          f"seconds per entry (medians): ours {np.median(table['seconds_chi2']):.2f} (the check beside "
          f"Mitsuba's test; the weight check {np.median(table['seconds_weight']):.2f} more), Mitsuba's "
          f"{np.nanmedian(table['seconds_mitsuba'].to_numpy(dtype=float)):.2f}"
          + (f", both after an untimed warm-up of {args.warm_up} samples that compiles the plugin's kernels "
             f"({np.median(table['seconds_warm_up']):.2f})" if args.warm_up > 0 else
             ", ours with drjit's JIT compilation of the plugin's kernels, Mitsuba's reusing them")
          + f"; {time.perf_counter() - start:.0f} s in all")
    for _, r in real[real["finding"] != ""].iterrows():
        print(f"finding, {r['label']}: {r['finding']}")
    if args.csv:
        table.to_csv(args.csv, index=False)


if __name__ == "__main__":
    main()
