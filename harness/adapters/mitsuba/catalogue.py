"""The Mitsuba samplers the harness checks (:func:`catalogue`), the planted faults every check
must catch (:func:`wrong_catalogue`), and :func:`run_catalogue`, which runs the checks of
``harness.adapters.mitsuba.checks`` on a list of them (benchmarks/mitsuba_samplers.py,
tests/adapters/test_mitsuba_catalogue.py): the chi-square (failed samples allowed for), the
reported-pdf check (the pdf each sample call reports against pdf()) and the weight check.
"""
from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from harness.adapters.mitsuba.checks import check_mitsuba_sampler, weight_consistency
from harness.adapters.mitsuba.emitters import light_bitmap, rectangle_light, sphere_light
from harness.adapters.mitsuba.faults import (
    Mutant,
    area_density_reported,
    lobe_pdf_reported,
    no_cosine,
    opacity_missing,
    reported_from,
    scaled_weight,
)
from harness.adapters.mitsuba.findings import CHANCE, FINDINGS
from harness.adapters.mitsuba.samplers import (
    area_emitter_sampler,
    bsdf_sampler,
    envmap_sampler,
    microfacet_sampler,
    phase_sampler,
    plugin_label,
    sky_bitmap,
)
from harness.stats import holm

__all__ = ["ALPHAS", "BLEND", "CHANCE", "CHECKS", "FINDINGS", "MASK", "PHASE_THETAS", "REFS", "THETAS",
           "TWOSIDED_THETAS", "CatalogueEntry", "catalogue", "emitter_entries", "failing_checks",
           "layered_bsdfs",
           "phase_functions", "run_catalogue", "wrong_catalogue"]


CHECKS = ("chi2", "reported", "weight")


@dataclass(frozen=True)
class CatalogueEntry:
    """One sampler to check: ``make()`` builds it (lazily: building imports Mitsuba);
    ``plugin`` names it without the incident angle ``theta`` (degrees; None where there is
    none); ``fault`` says what was planted ('' for a real plugin).  ``fails``: the checks of
    :data:`CHECKS` that must fail: for a planted fault the check that catches its kind; for
    a real plugin the checks a Mitsuba finding fails (``finding`` says what and the measured
    numbers), else none; ``fails_from``: the sample count from which the finding shows
    (a rare float32 event, about one sample in 1e6, does not show at 1e5); ``may_fail``:
    checks such a rare event may fail as well, from ``fails_from`` on: whether one of its
    samples lands in that check's draw depends on the float32 rounding of the machine's
    vector ISA, not only on the seed (:data:`CHANCE`)."""

    plugin: str
    theta: float | None
    make: Callable[[], Any]
    fault: str = ""
    group: str = ""
    fails: tuple[str, ...] = ()
    finding: str = ""
    fails_from: int = 0
    may_fail: tuple[str, ...] = ()

    def documented(self, failing: set[str], sample_count: int) -> bool:
        """Whether the checks ``failing`` at ``sample_count`` samples are what is documented
        (:func:`_documented_failures`)."""
        return _documented_failures(failing, set(self.fails), set(self.may_fail), sample_count,
                                    self.fails_from, planted=bool(self.fault))

    @property
    def label(self) -> str:
        return self.plugin + (f" θi={self.theta:g}°" if self.theta is not None else "")


THETAS = (0.0, 45.0, 80.0)
#: twosided BSDFs are lit from above and from below (theta_i > 90)
TWOSIDED_THETAS = (0.0, 45.0, 80.0, 135.0)
#: phase functions: incident directions across the whole sphere
PHASE_THETAS = (0.0, 60.0, 135.0)
ALPHAS = (0.01, 0.1, 0.5)
#: the narrow GGX lobe checked at normal incidence alone (visible normals)
POLE_ALPHA = 0.003
#: reference points the area lights are sampled from: on the axis, and off it and closer
#: (the light seen obliquely, a sphere's silhouette near the edge of the cone)
REFS = ((0.0, 0.0, 0.0), (0.6, -0.4, 0.3))
MASK = {"type": "mask", "opacity": 0.3, "bsdf": {"type": "diffuse"}}
BLEND = {"type": "blendbsdf", "weight": 0.3, "bsdf_0": {"type": "diffuse"},
         "bsdf_1": {"type": "roughconductor", "distribution": "ggx", "alpha": 0.1}}


def layered_bsdfs() -> list[tuple[str, dict[str, Any], Sequence[float]]]:
    """(group, plugin, incident angles) of the composite and layered BSDFs: mask (opacity
    0.3 over diffuse: the pass-through is a Dirac lobe, 70 % of the samples), twosided
    (GGX conductor, lit from below too), blendbsdf (0.7 diffuse + 0.3 GGX conductor),
    principled (default; and with spec_trans 0.5, roughness 0.3: transmission), plastic
    (smooth coating: a Dirac lobe) and roughplastic (Beckmann alpha 0.3)."""
    return [("mask", MASK, THETAS),
            ("twosided", {"type": "twosided", "bsdf": {"type": "roughconductor", "distribution": "ggx",
                                                       "alpha": 0.1}}, TWOSIDED_THETAS),
            ("blendbsdf", BLEND, THETAS),
            ("principled", {"type": "principled"}, THETAS),
            ("principled", {"type": "principled", "spec_trans": 0.5, "roughness": 0.3}, TWOSIDED_THETAS),
            ("plastic", {"type": "plastic"}, THETAS),
            ("roughplastic", {"type": "roughplastic", "distribution": "beckmann", "alpha": 0.3}, THETAS)]


def phase_functions() -> list[dict[str, Any]]:
    """The phase functions checked: Henyey-Greenstein at g = -0.7, 0.3, 0.9; Rayleigh; a
    blend of 0.7 HG(0.9) and 0.3 HG(-0.7) (``blendphase``: a two-lobed mixture)."""
    return [{"type": "hg", "g": -0.7}, {"type": "hg", "g": 0.3}, {"type": "hg", "g": 0.9},
            {"type": "rayleigh"},
            {"type": "blendphase", "weight": 0.3, "phase1": {"type": "hg", "g": 0.9},
             "phase2": {"type": "hg", "g": -0.7}}]


def _lights() -> list[tuple[str, Callable[[], dict[str, Any]]]]:
    bitmap = light_bitmap()
    out: list[tuple[str, Callable[[], dict[str, Any]]]] = []
    for shape, make in (("rectangle", rectangle_light), ("sphere", sphere_light)):
        out.append((f"area {shape} constant", lambda m=make: m([1.0, 2.0, 3.0])))
        for filt in ("nearest", "bilinear"):
            out.append((f"area {shape} bitmap 32x16 {filt}",
                        lambda m=make, f=filt: m({"type": "bitmap", "bitmap": bitmap, "filter_type": f})))
    return out


def emitter_entries(*, refs: Sequence[Sequence[float]] = REFS,
                    variant: str = "llvm_ad_rgb") -> list[CatalogueEntry]:
    """Area lights on shapes sampled by direction from each point of ``refs``: a 2 x 2 square
    at z = 1 facing down and a sphere of radius 0.5 at (1, 0.6, 1.6); constant RGB radiance, and
    ``light_bitmap()`` (32 x 16 texels, a 100 : 1 checkerboard) filtered nearest and
    bilinear."""
    out = []
    for label, shape in _lights():
        for ref in refs:
            where = "(" + ", ".join(f"{c:g}" for c in ref) + ")"
            make = lambda s=shape, r=ref: area_emitter_sampler(s(), ref=r, variant=variant)  # noqa: E731
            out.append(CatalogueEntry(f"{label} from {where}", None, make, "", "emitter"))
    return out


def catalogue(*, thetas: Sequence[float] = THETAS, alphas: Sequence[float] = ALPHAS,
              variant: str = "llvm_ad_rgb") -> list[CatalogueEntry]:
    """The real plugins checked, each at every incident angle in ``thetas`` (degrees):
    diffuse; roughconductor, GGX and Beckmann, at every alpha, visible-normal sampling on
    and off, and GGX at :data:`POLE_ALPHA` at normal incidence; roughdielectric (GGX, alpha
    0.1 and 0.5, int_ior 1.5); roughplastic (GGX, alpha 0.1); the microfacet distributions
    themselves (GGX and Beckmann at every alpha; visible normals at every angle, all normals
    once: they do not depend on wi); the composite and layered BSDFs of :func:`layered_bsdfs`
    at their own angles; the phase functions of :func:`phase_functions` at
    :data:`PHASE_THETAS`; envmaps from ``sky_bitmap()`` with a soft-rimmed and a hard-edged
    sun; the area lights of :func:`emitter_entries`."""
    out: list[CatalogueEntry] = []

    def bsdf(group: str, plugin: dict[str, Any], angles: Sequence[float] = thetas) -> None:
        for t in angles:
            out.append(CatalogueEntry(plugin_label(plugin), float(t),
                                      lambda t=t: bsdf_sampler(plugin, wi=t, variant=variant), "", group))

    bsdf("diffuse", {"type": "diffuse"})
    for dist in ("ggx", "beckmann"):
        for a in alphas:
            for vis in (True, False):
                bsdf("roughconductor",
                     {"type": "roughconductor", "distribution": dist, "alpha": a, "sample_visible": vis})
    # a lobe about the pole narrower than a float32 direction's z resolves (1 - cos theta ~ 2e-5
    # across it, in steps of 6e-8): the domain's map takes cos theta across the pole
    bsdf("roughconductor", {"type": "roughconductor", "distribution": "ggx", "alpha": POLE_ALPHA,
                            "sample_visible": True}, (0.0,))
    for a in (0.1, 0.5):
        bsdf("roughdielectric",
             {"type": "roughdielectric", "distribution": "ggx", "alpha": a, "int_ior": 1.5})
    bsdf("roughplastic", {"type": "roughplastic", "distribution": "ggx", "alpha": 0.1})
    for group, plugin, angles in layered_bsdfs():
        bsdf(group, plugin, angles)
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
    for plugin in phase_functions():
        for t in PHASE_THETAS:
            make = lambda p=plugin, t=t: phase_sampler(p, wi=t, variant=variant)  # noqa: E731
            out.append(CatalogueEntry(plugin_label(plugin), float(t), make, "", "phase"))
    out.append(CatalogueEntry("envmap 256x128 sky, sun with a soft rim", None,
                              lambda: envmap_sampler(variant=variant), "", "envmap"))
    out.append(CatalogueEntry("envmap 256x128 sky, hard-edged sun", None,
                              lambda: envmap_sampler(sky_bitmap(sun_edge=0.0), variant=variant), "",
                              "envmap"))
    return [_documented(e) for e in out + emitter_entries(variant=variant)]


def _documented(e: CatalogueEntry) -> CatalogueEntry:
    """``e`` with its Mitsuba finding (:data:`FINDINGS`, :data:`CHANCE`), if it has one."""
    fails, finding, fails_from = FINDINGS.get(e.label, ((), "", 0))
    return dataclasses.replace(e, fails=fails, finding=finding, fails_from=fails_from,
                               may_fail=CHANCE.get(e.label, ()))


def _documented_failures(failing: set[str], must: set[str], may: set[str], sample_count: int,
                         fails_from: int, *, planted: bool) -> bool:
    """Every check that must fail failed (none below ``fails_from`` samples), and, for a real
    plugin, besides them only checks that may: a planted fault's other checks may catch it
    too."""
    if sample_count < fails_from:
        must, may = set(), set()
    return must <= failing and (planted or failing <= must | may)


def wrong_catalogue(*, variant: str = "llvm_ad_rgb") -> list[CatalogueEntry]:
    """Planted faults every check must catch, each kind by its check (faults.py; an entry's
    ``fails`` names it: "chi2" for a pdf fault, "weight", "reported").
    pdf (chi-square): a pdf 0.5 % too large or too small (BSDFs with and without failed samples,
    envmap, twosided from below); the pdf of GGX alpha 0.1 claimed for samples of alpha 0.11
    (conductor and distribution) and of 0.01 for 0.011; Beckmann's pdf for GGX samples; the
    envmap's pdf with the sun 1 degree away; a mask's pdf() without its opacity; HG's pdf with g
    1 % off (0.909 for 0.9, 0.303 for 0.3); a bitmap light's nearest-filtered pdf for its
    bilinear samples, and for its nearest-filtered samples the pdf of the bitmap with one texel
    twice as bright (a texel index off by one: tested in the rectangle's own square); a sphere
    light's pdf for a radius 1 % larger.  weight: missing cos theta_o; 0.1 % too large (BSDF,
    envmap, phase function, area light).  reported pdf: a blendbsdf's sampled lobe's pdf instead
    of the mixture's; a mask's opacity left out; HG's pdf with wi's sign flipped; an area
    light's density per unit area instead of per solid angle (rectangle and sphere)."""
    def entry(plugin: str, theta: float | None, make: Callable[[], Any], fault: str) -> CatalogueEntry:
        check = next((c for c in ("weight", "reported") if fault.startswith(c)), "chi2")
        return CatalogueEntry(plugin, theta, make, fault, "wrong", (check,))

    def bsdf(plugin: dict[str, Any], t: float = 45.0) -> Any:
        return bsdf_sampler(plugin, wi=t, variant=variant)

    def ggx(a: float, t: float = 45.0) -> Any:
        return bsdf({"type": "roughconductor", "distribution": "ggx", "alpha": a}, t)

    def microfacet(a: float) -> Any:
        return microfacet_sampler("ggx", a, wi=45, variant=variant)

    def hg(g: float, t: float = 60.0) -> Any:
        return phase_sampler({"type": "hg", "g": g}, wi=t, variant=variant)

    def light(shape: dict[str, Any], ref: Sequence[float] = REFS[1]) -> Any:
        return area_emitter_sampler(shape, ref=ref, variant=variant)

    def light_fault(base: Any, shape: dict[str, Any], name: str) -> Mutant:
        return Mutant(base, name, pdf_from=area_emitter_sampler(shape, ref=base.ref, variant=variant))

    def textured(filt: str, bitmap: np.ndarray | None = None) -> dict[str, Any]:
        return rectangle_light({"type": "bitmap", "bitmap": light_bitmap() if bitmap is None else bitmap,
                                "filter_type": filt})

    def one_texel_brighter() -> np.ndarray:
        img = light_bitmap()
        img[5, 13] *= 2.0      # a bright block's texel: about 0.3 % of the light's power
        return img

    plastic = {"type": "roughplastic", "distribution": "ggx", "alpha": 0.1}
    beckmann = {"type": "roughconductor", "distribution": "beckmann", "alpha": 0.1}
    twosided = {"type": "twosided", "bsdf": {"type": "roughconductor", "distribution": "ggx", "alpha": 0.1}}
    heavier = scaled_weight(1.001)
    return [
        entry("roughconductor ggx α=0.1, pdf × 1.005", 45.0,
              lambda: Mutant(ggx(0.1), "pdf × 1.005", pdf_scale=1.005), "pdf 0.5 % too large"),
        entry("roughconductor ggx α=0.1, pdf × 1.005", 0.0,
              lambda: Mutant(ggx(0.1, 0.0), "pdf × 1.005", pdf_scale=1.005), "pdf 0.5 % too large"),
        entry("diffuse, pdf × 0.995", 45.0,
              lambda: Mutant(bsdf({"type": "diffuse"}), "pdf × 0.995", pdf_scale=0.995),
              "pdf 0.5 % too small"),
        entry("roughconductor ggx samples α=0.11, pdf α=0.1", 45.0,
              lambda: Mutant(ggx(0.11), "pdf of α=0.1", pdf_from=ggx(0.1)), "pdf of another alpha"),
        entry("roughconductor ggx samples α=0.011, pdf α=0.01", 45.0,
              lambda: Mutant(ggx(0.011), "pdf of α=0.01", pdf_from=ggx(0.01)), "pdf of another alpha"),
        entry("microfacet ggx visible samples α=0.11, pdf α=0.1", 45.0,
              lambda: Mutant(microfacet(0.11), "pdf of α=0.1", pdf_from=microfacet(0.1)),
              "pdf of another alpha"),
        entry("roughconductor ggx samples, beckmann pdf α=0.1", 45.0,
              lambda: Mutant(ggx(0.1), "beckmann pdf", pdf_from=bsdf(beckmann)),
              "pdf of another distribution"),
        entry("envmap, pdf × 1.005", None,
              lambda: Mutant(envmap_sampler(variant=variant), "pdf × 1.005", pdf_scale=1.005),
              "pdf 0.5 % too large"),
        entry("envmap, pdf of the map with the sun 1° away", None,
              lambda: Mutant(envmap_sampler(variant=variant), "sun moved",
                             pdf_from=envmap_sampler(sky_bitmap(sun_phi=71.0), variant=variant)),
              "pdf of a slightly different map"),
        entry("twosided roughconductor ggx α=0.1, pdf × 1.005", 135.0,
              lambda: Mutant(bsdf(twosided, 135.0), "pdf × 1.005", pdf_scale=1.005), "pdf 0.5 % too large"),
        entry("mask opacity=0.3 (diffuse), pdf() without the opacity", 45.0,
              lambda: Mutant(bsdf(MASK), "pdf without opacity", pdf_from=bsdf({"type": "diffuse"})),
              "pdf without the mask's opacity"),
        entry("hg samples g=0.9, pdf g=0.909", 60.0,
              lambda: Mutant(hg(0.9), "pdf of g=0.909", pdf_from=hg(0.909)), "pdf with g 1 % off"),
        entry("hg samples g=0.3, pdf g=0.303", 60.0,
              lambda: Mutant(hg(0.3), "pdf of g=0.303", pdf_from=hg(0.303)), "pdf with g 1 % off"),
        entry("area rectangle bitmap bilinear samples, nearest pdf", None,
              lambda: light_fault(light(textured("bilinear")), textured("nearest"), "nearest pdf"),
              "pdf of another texture filter"),
        entry("area rectangle bitmap nearest samples, pdf with one texel twice as bright", None,
              lambda: light_fault(light(textured("nearest")), textured("nearest", one_texel_brighter()),
                                  "one texel brighter"),
              "pdf of a bitmap with one texel twice as bright"),
        entry("area sphere constant samples r=0.5, pdf r=0.505", None,
              lambda: light_fault(light(sphere_light(1.0)), sphere_light(1.0, radius=0.505),
                                  "pdf of r=0.505"),
              "pdf of a 1 % larger sphere"),
        entry("roughconductor ggx α=0.1, weight without cos θo", 45.0,
              lambda: Mutant(ggx(0.1), "weight without cos", weight_fault=no_cosine), "weight omits cos θo"),
        entry("roughplastic ggx α=0.1, weight × 1.001", 45.0,
              lambda: Mutant(bsdf(plastic), "weight × 1.001", weight_fault=heavier),
              "weight 0.1 % too large"),
        entry("envmap, weight × 1.001", None,
              lambda: Mutant(envmap_sampler(variant=variant), "weight × 1.001", weight_fault=heavier),
              "weight 0.1 % too large"),
        entry("rayleigh, weight × 1.001", 60.0,
              lambda: Mutant(phase_sampler({"type": "rayleigh"}, wi=60, variant=variant), "weight × 1.001",
                             weight_fault=heavier), "weight 0.1 % too large"),
        entry("area rectangle bitmap bilinear, weight × 1.001", None,
              lambda: Mutant(light(textured("bilinear")), "weight × 1.001", weight_fault=heavier),
              "weight 0.1 % too large"),
        entry("blendbsdf, sampled lobe's pdf reported", 45.0,
              lambda: Mutant(bsdf(BLEND), "lobe pdf reported", reported_fault=lobe_pdf_reported(
                  {2: bsdf(BLEND["bsdf_0"]), 8: bsdf(BLEND["bsdf_1"])})),
              "reported pdf: the sampled lobe's, not the mixture's"),
        entry("mask opacity=0.3 (diffuse), opacity missing from the reported pdf", 45.0,
              lambda: Mutant(bsdf(MASK), "opacity missing", reported_fault=opacity_missing(0.3)),
              "reported pdf without the mask's opacity"),
        entry("hg g=0.3, reported pdf with wi flipped", 60.0,
              lambda: Mutant(hg(0.3), "wi flipped", reported_fault=reported_from(hg(0.3, 120.0))),
              "reported pdf with forward and backward swapped"),
        entry("area rectangle constant, area density reported", None,
              lambda: Mutant(light(rectangle_light(1.0)), "area density",
                             reported_fault=area_density_reported),
              "reported pdf per area, not per solid angle"),
        entry("area sphere bitmap bilinear, area density reported", None,
              lambda: Mutant(light(sphere_light({"type": "bitmap", "bitmap": light_bitmap()})),
                             "area density", reported_fault=area_density_reported),
              "reported pdf per area, not per solid angle"),
    ]


def run_catalogue(entries: Sequence[CatalogueEntry], *, sample_count: int = 1_000_000, seed: int = 0,
                  alpha: float = 0.01, weight_samples: int | None = None, warm_up: int = 0,
                  progress: Callable[[dict[str, Any]], None] | None = None) -> pd.DataFrame:
    """Runs ``check_mitsuba_sampler`` (chi-square and reported pdf) and ``weight_consistency``
    on every entry.  The chi-square verdicts are Holm-corrected across all entries at
    family-wise ``alpha`` (each check's p-value is its smallest within-check Holm-adjusted
    p-value, a valid p-value for the whole check; deterministic failures always fail).  The
    reported-pdf and weight checks are deterministic (no alpha).  With ``warm_up`` > 0 each
    entry's two checks first run untimed on that many samples, so that drjit has compiled the
    plugin's kernels (cached for the process) before the timed runs: their seconds are then the
    checks' own, as a second test of the same plugin costs, and comparable with another test
    run after them on the same kernels (the benchmark's Mitsuba ChiSquareTest).

    One row per entry: label, plugin, theta, group, fault, domain, n, failed (samples not
    produced: failed or of a Dirac lobe), delta (of those, Dirac-lobe samples, counted by the
    weight check's draw), P and P_err (the pdf's integral over the domain, in its map for area
    lights (the domain then says which: "square (rectangle)", "hemisphere (cap)"), and its
    cubature error bound), pvalue, adjusted, chi2 ('pass' / 'FAIL'),
    failures (deterministic, but the reported pdf's), reported ('pass' / 'FAIL'),
    reported_mismatches, reported_max_rel (largest |reported / pdf() - 1| over the weight
    check's draw, every entry), weight ('pass' / 'FAIL' / 'n/a' for microfacet
    distributions), weight_mismatches, bad_weights, weight_max_rel, seconds_chi2 (pdf
    cubature and reported pdf included), seconds_weight, seconds_warm_up (0 without one),
    expected ('yes' where the failing
    checks are the entry's ``fails``; for a planted fault, where its check fails), finding.
    ``attrs['checks']`` holds the (SamplerCheck, WeightCheck) pairs."""
    rows = []
    checks = []
    for e in entries:
        start = time.perf_counter()
        s = e.make()
        if warm_up > 0:
            check_mitsuba_sampler(s, sample_count=warm_up, seed=seed, alpha=alpha)
            weight_consistency(s, sample_count=warm_up, seed=seed)
        warm = time.perf_counter()
        r = check_mitsuba_sampler(s, sample_count=sample_count, seed=seed, alpha=alpha)
        mid = time.perf_counter()
        w = weight_consistency(s, sample_count=weight_samples or sample_count, seed=seed)
        end = time.perf_counter()
        failed_row = r.tests[r.tests["test"] == "failed samples"]
        has_weight = s.eval(np.array([[0.0, 0.0, 1.0]])) is not None
        reported = [f for f in r.failures if f.check == "reported_pdf"]
        mapping = getattr(s, "mapping", None)   # an area light's map, where its statistical tests run
        domain = s.domain if mapping is None else f"{mapping.domain} ({type(mapping).__name__.lower()})"
        row = {"label": e.label, "plugin": e.plugin, "theta": e.theta, "group": e.group, "fault": e.fault,
               "domain": domain, "n": r.n,
               "failed": int(failed_row["statistic"].iloc[0]) if len(failed_row) else 0, "delta": w.delta,
               "P": r.normalization[0], "P_err": r.normalization[1], "pvalue": r.pvalue,
               "failures": "; ".join(f"{f.check}: {f.count}" for f in r.failures
                                     if f.check != "reported_pdf"),
               "reported": "FAIL" if reported else "pass",
               "reported_mismatches": reported[0].count if reported else 0,
               "reported_max_rel": w.max_pdf_rel_error,
               "weight": ("pass" if w.passed else "FAIL") if has_weight else "n/a",
               "weight_mismatches": w.mismatches, "bad_weights": w.bad_weights,
               "weight_max_rel": w.max_rel_error, "seconds_chi2": mid - warm, "seconds_weight": end - mid,
               "seconds_warm_up": warm - start if warm_up > 0 else 0.0,
               "fails": ",".join(e.fails), "may_fail": ",".join(e.may_fail), "fails_from": e.fails_from,
               "finding": e.finding}
        rows.append(row)
        checks.append((r, w))
        if progress is not None:
            progress(row)
    table = pd.DataFrame(rows)
    if len(table):
        rejected, adjusted = holm(table["pvalue"].to_numpy(dtype=float), alpha)
        table["adjusted"] = adjusted
        table["chi2"] = np.where(rejected | (table["failures"] != ""), "FAIL", "pass")
        table["expected"] = [_as_expected(row) for _, row in table.iterrows()]
    table.attrs["checks"] = checks
    table.attrs["alpha"] = alpha
    return table


def failing_checks(row: Any) -> set[str]:
    """The checks of :data:`CHECKS` a run_catalogue row failed."""
    return {c for c in CHECKS if row.get(c) == "FAIL"}


def _as_expected(row: Any) -> str:
    """'yes' where a planted fault's check failed, or a real plugin failed the checks its
    finding fails at the row's sample count and besides them only those it may; else 'NO'."""
    def checks(column: str) -> set[str]:
        return set(filter(None, str(row[column]).split(",")))

    ok = _documented_failures(failing_checks(row), checks("fails"), checks("may_fail"), row["n"],
                              row["fails_from"], planted=bool(row["fault"]))
    return "yes" if ok else "NO"
