"""The Mitsuba samplers the harness checks (:func:`catalogue`), the planted faults every check
must catch (:func:`wrong_catalogue`), and :func:`run_catalogue`, which runs both checks of
``harness.adapters.mitsuba.checks`` on a list of them (benchmarks/mitsuba_samplers.py,
tests/adapters/test_mitsuba_samplers.py).
"""
from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from harness.adapters.mitsuba.checks import check_mitsuba_sampler, weight_consistency
from harness.adapters.mitsuba.faults import Mutant, no_cosine
from harness.adapters.mitsuba.samplers import (
    BSDFSampler,
    MicrofacetSampler,
    SampleBatch,
    bsdf_sampler,
    envmap_sampler,
    microfacet_sampler,
    plugin_label,
    sky_bitmap,
)
from harness.stats import holm

__all__ = ["ALPHAS", "THETAS", "CatalogueEntry", "catalogue", "run_catalogue", "wrong_catalogue"]


@dataclass(frozen=True)
class CatalogueEntry:
    """One sampler to check: ``make()`` builds it (lazily: building imports Mitsuba);
    ``plugin`` names it without the incident angle ``theta`` (degrees; None where there is
    none); ``fault`` says what was planted ('' for a real plugin)."""

    plugin: str
    theta: float | None
    make: Callable[[], Any]
    fault: str = ""
    group: str = ""

    @property
    def label(self) -> str:
        return self.plugin + (f" θi={self.theta:g}°" if self.theta is not None else "")


THETAS = (0.0, 45.0, 80.0)
ALPHAS = (0.01, 0.1, 0.5)


def catalogue(*, thetas: Sequence[float] = THETAS, alphas: Sequence[float] = ALPHAS,
              variant: str = "llvm_ad_rgb") -> list[CatalogueEntry]:
    """The real plugins checked, each at every incident angle in ``thetas`` (degrees):
    diffuse; roughconductor, GGX and Beckmann, at every alpha, visible-normal sampling on
    and off; roughdielectric (GGX, alpha 0.1 and 0.5, int_ior 1.5); roughplastic (GGX, alpha
    0.1); the microfacet distributions themselves (GGX and Beckmann at every alpha; visible
    normals at every angle, all normals once: they do not depend on wi); envmaps from
    ``sky_bitmap()`` with a soft-rimmed and a hard-edged sun."""
    out: list[CatalogueEntry] = []

    def bsdf(group: str, plugin: dict[str, Any]) -> None:
        for t in thetas:
            out.append(CatalogueEntry(plugin_label(plugin), float(t),
                                      lambda t=t: bsdf_sampler(plugin, wi=t, variant=variant), "", group))

    bsdf("diffuse", {"type": "diffuse"})
    for dist in ("ggx", "beckmann"):
        for a in alphas:
            for vis in (True, False):
                bsdf("roughconductor",
                     {"type": "roughconductor", "distribution": dist, "alpha": a, "sample_visible": vis})
    for a in (0.1, 0.5):
        bsdf("roughdielectric",
             {"type": "roughdielectric", "distribution": "ggx", "alpha": a, "int_ior": 1.5})
    bsdf("roughplastic", {"type": "roughplastic", "distribution": "ggx", "alpha": 0.1})
    for dist in ("ggx", "beckmann"):
        for a in alphas:
            for t in thetas:
                out.append(CatalogueEntry(
                    f"microfacet {dist} α={a:g} visible", float(t),
                    lambda d=dist, a=a, t=t: microfacet_sampler(d, a, visible=True, wi=t, variant=variant),
                    "", "microfacet"))
            out.append(CatalogueEntry(
                f"microfacet {dist} α={a:g} all normals", None,
                lambda d=dist, a=a: microfacet_sampler(d, a, visible=False, variant=variant),
                "", "microfacet"))
    out.append(CatalogueEntry("envmap 256x128 sky, sun with a soft rim", None,
                              lambda: envmap_sampler(variant=variant), "", "envmap"))
    out.append(CatalogueEntry("envmap 256x128 sky, hard-edged sun", None,
                              lambda: envmap_sampler(sky_bitmap(sun_edge=0.0), variant=variant), "",
                              "envmap"))
    return out


def wrong_catalogue(*, variant: str = "llvm_ad_rgb") -> list[CatalogueEntry]:
    """Planted faults every check must catch: a pdf 0.5 % too large or too small (BSDFs with
    and without failed samples, envmap); the pdf of GGX alpha 0.1 claimed for samples of
    alpha 0.11 (conductor and distribution) and of 0.01 for 0.011; Beckmann's pdf for GGX
    samples; the envmap's pdf with the sun 1 degree away; a weight missing cos theta_o; a
    weight 0.1 % too large (BSDF and envmap)."""
    def ggx(a: float, t: float = 45.0) -> BSDFSampler:
        return bsdf_sampler({"type": "roughconductor", "distribution": "ggx", "alpha": a}, wi=t,
                            variant=variant)

    def entry(plugin: str, theta: float | None, make: Callable[[], Any], fault: str) -> CatalogueEntry:
        return CatalogueEntry(plugin, theta, make, fault, "wrong")

    def heavier(b: SampleBatch) -> np.ndarray:  # a weight 0.1 % too large
        return b.weight * 1.001

    def diffuse() -> BSDFSampler:
        return bsdf_sampler({"type": "diffuse"}, wi=45, variant=variant)

    def microfacet(a: float) -> MicrofacetSampler:
        return microfacet_sampler("ggx", a, wi=45, variant=variant)

    def plastic() -> BSDFSampler:
        return bsdf_sampler({"type": "roughplastic", "distribution": "ggx", "alpha": 0.1}, wi=45,
                            variant=variant)

    def beckmann() -> BSDFSampler:
        return bsdf_sampler({"type": "roughconductor", "distribution": "beckmann", "alpha": 0.1}, wi=45,
                            variant=variant)

    return [
        entry("roughconductor ggx α=0.1, pdf × 1.005", 45.0,
              lambda: Mutant(ggx(0.1), "pdf × 1.005", pdf_scale=1.005), "pdf 0.5 % too large"),
        entry("roughconductor ggx α=0.1, pdf × 1.005", 0.0,
              lambda: Mutant(ggx(0.1, 0.0), "pdf × 1.005", pdf_scale=1.005), "pdf 0.5 % too large"),
        entry("diffuse, pdf × 0.995", 45.0,
              lambda: Mutant(diffuse(), "pdf × 0.995", pdf_scale=0.995), "pdf 0.5 % too small"),
        entry("roughconductor ggx samples α=0.11, pdf α=0.1", 45.0,
              lambda: Mutant(ggx(0.11), "pdf of α=0.1", pdf_from=ggx(0.1)), "pdf of another alpha"),
        entry("roughconductor ggx samples α=0.011, pdf α=0.01", 45.0,
              lambda: Mutant(ggx(0.011), "pdf of α=0.01", pdf_from=ggx(0.01)), "pdf of another alpha"),
        entry("microfacet ggx visible samples α=0.11, pdf α=0.1", 45.0,
              lambda: Mutant(microfacet(0.11), "pdf of α=0.1", pdf_from=microfacet(0.1)),
              "pdf of another alpha"),
        entry("roughconductor ggx samples, beckmann pdf α=0.1", 45.0,
              lambda: Mutant(ggx(0.1), "beckmann pdf", pdf_from=beckmann()), "pdf of another distribution"),
        entry("envmap, pdf × 1.005", None,
              lambda: Mutant(envmap_sampler(variant=variant), "pdf × 1.005", pdf_scale=1.005),
              "pdf 0.5 % too large"),
        entry("envmap, pdf of the map with the sun 1° away", None,
              lambda: Mutant(envmap_sampler(variant=variant), "sun moved",
                             pdf_from=envmap_sampler(sky_bitmap(sun_phi=71.0), variant=variant)),
              "pdf of a slightly different map"),
        entry("roughconductor ggx α=0.1, weight without cos θo", 45.0,
              lambda: Mutant(ggx(0.1), "weight without cos", weight_fault=no_cosine), "weight omits cos θo"),
        entry("roughplastic ggx α=0.1, weight × 1.001", 45.0,
              lambda: Mutant(plastic(), "weight × 1.001", weight_fault=heavier), "weight 0.1 % too large"),
        entry("envmap, weight × 1.001", None,
              lambda: Mutant(envmap_sampler(variant=variant), "weight × 1.001", weight_fault=heavier),
              "weight 0.1 % too large"),
    ]


def run_catalogue(entries: Sequence[CatalogueEntry], *, sample_count: int = 1_000_000, seed: int = 0,
                  alpha: float = 0.01, weight_samples: int | None = None,
                  progress: Callable[[dict[str, Any]], None] | None = None) -> pd.DataFrame:
    """Runs ``check_mitsuba_sampler`` and ``weight_consistency`` on every entry.  The
    chi-square verdicts are Holm-corrected across all entries at family-wise ``alpha`` (each
    check's p-value is its smallest within-check Holm-adjusted p-value, a valid p-value for
    the whole check; deterministic failures always fail).  The weight check is
    deterministic (no alpha).

    One row per entry: label, plugin, theta, group, fault, domain, n, failed (samples Mitsuba
    did not produce), P and P_err (the pdf's integral over the domain and its cubature error
    bound), pvalue, adjusted, chi2 ('pass' / 'FAIL'), failures (deterministic), weight
    ('pass' / 'FAIL' / 'n/a' for microfacet distributions), weight_mismatches, bad_weights,
    weight_max_rel, pdf_consistent, pdf_mismatches, pdf_max_rel, seconds_chi2 (pdf cubature
    included), seconds_weight.  ``attrs['checks']`` holds the (SamplerCheck, WeightCheck)
    pairs."""
    rows = []
    checks = []
    for e in entries:
        start = time.perf_counter()
        s = e.make()
        r = check_mitsuba_sampler(s, sample_count=sample_count, seed=seed, alpha=alpha)
        mid = time.perf_counter()
        w = weight_consistency(s, sample_count=weight_samples or sample_count, seed=seed)
        end = time.perf_counter()
        failed_row = r.tests[r.tests["test"] == "failed samples"]
        has_weight = s.eval(np.array([[0.0, 0.0, 1.0]])) is not None
        row = {"label": e.label, "plugin": e.plugin, "theta": e.theta, "group": e.group, "fault": e.fault,
               "domain": s.domain, "n": r.n,
               "failed": int(failed_row["statistic"].iloc[0]) if len(failed_row) else 0,
               "P": r.normalization[0], "P_err": r.normalization[1], "pvalue": r.pvalue,
               "failures": "; ".join(f"{f.check}: {f.count}" for f in r.failures),
               "weight": ("pass" if w.passed else "FAIL") if has_weight else "n/a",
               "weight_mismatches": w.mismatches, "bad_weights": w.bad_weights,
               "weight_max_rel": w.max_rel_error, "pdf_consistent": w.pdf_consistent,
               "pdf_mismatches": w.pdf_mismatches, "pdf_max_rel": w.max_pdf_rel_error,
               "seconds_chi2": mid - start, "seconds_weight": end - mid}
        rows.append(row)
        checks.append((r, w))
        if progress is not None:
            progress(row)
    table = pd.DataFrame(rows)
    if len(table):
        rejected, adjusted = holm(table["pvalue"].to_numpy(dtype=float), alpha)
        table["adjusted"] = adjusted
        table["chi2"] = np.where(rejected | (table["failures"] != ""), "FAIL", "pass")
    table.attrs["checks"] = checks
    table.attrs["alpha"] = alpha
    return table
