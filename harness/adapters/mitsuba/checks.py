"""Checks of Mitsuba samplers that Mitsuba's own chi-square cannot make: a chi-square check
that allows for samples Mitsuba fails to produce, with the check that the pdf each sample
call reports equals ``pdf()`` at the returned direction, and the check that the weight a
sampler returns equals eval / pdf.

    check_mitsuba_sampler(s)      # a SamplerCheck, like check_sampler's, failures allowed for,
                                  # with a deterministic 'reported_pdf' failure on a mismatch
    weight_consistency(s)         # a WeightCheck: weight == eval / pdf

Reported pdf.  MIS weights use the pdf ``bsdf.sample`` / ``phase.sample`` /
``emitter.sample_direction`` reports, the chi-square only where samples go; a renderer that
reports the sampled lobe's pdf instead of the mixture's, or leaves a mask's opacity out of
it, passes every test of the histogram and biases every MIS-weighted render.  Each produced
sample's reported pdf is compared with ``pdf()`` at exactly the float32 direction returned
(harness.samplers.reported).  The tolerance is float32 rounding and nothing else: 1e-4
relative, about 840 float32 ulps (2^-23 = 1.2e-7), for a reported value computed along
another chain of float32 operations than ``pdf()`` (a microfacet BSDF's from the sampled
normal, ``pdf()`` from the half vector of the returned direction), plus the largest change
of ``pdf()`` when one coordinate of the direction moves by 4 float32 ulps (where the pdf is
steep at that scale: a lobe's edge, a texel boundary).  It detects a reported pdf off by a
factor outside 1 +- 1e-4 wherever the pdf is not steep at float32 scale: the planted faults
(a lobe's pdf for a blend's, opacity 0.3 missing, HG's pdf with wi flipped, a density per
area for one per steradian) are off by factors from 0.2 to 3.3 and fail at every produced
sample.  Correct plugins stay far below it: most Mitsuba plugins compute the reported pdf
with ``pdf()`` itself (equal to the last bit), the others within a few ulps
(benchmarks/mitsuba_samplers.py prints the largest relative difference of every plugin).

Area lights are tested statistically in a map of the directions towards them: a rectangle's
own square (:mod:`harness.adapters.mitsuba.rectangle`), else the equal-area map of the cap of
directions holding them (:mod:`harness.adapters.mitsuba.cap`); their reported pdf on the world
directions, where float32 ulps have their meaning.

Failed samples.  A sample Mitsuba could not produce (zero weight) is a NaN row of
``sampler.sample``; ``check_mitsuba_sampler`` is harness.samplers' check_with_missing (the
failure count by an exact binomial test against N (1 - P), the directions produced against
pdf / P).  A pdf 0.5 % too large is caught by the failure count where P < 1 and by the
normalisation (P > 1 + 1e-3) otherwise.

``check_mitsuba_sampler`` refuses scalar variants: its cubature evaluates the pdf at ~10^7
points, one Python call each there.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

import reference_estimators as rest

from harness.adapters.mitsuba.batch import float32_pdf_of
from harness.adapters.mitsuba.runtime import is_jit, jit_threads
from harness.samplers.check import SAMPLE_CASE, check_with_missing
from harness.samplers.domains import Domain, Float32DirectionPdf
from harness.samplers.reported import reported_pdf_failure, rounding_spread
from harness.samplers.result import SamplerCheck
from harness.stats.results import ConfidenceInterval, Failure, check_confidence_level

__all__ = ["WeightCheck", "check_mitsuba_sampler", "weight_consistency"]

_WEIGHT_CASE = 0x3E17   # weight_consistency's stream


def check_mitsuba_sampler(sampler: Any, *, sample_count: int = 1_000_000, seed: int = 0,
                          alpha: float = 0.01) -> SamplerCheck:
    """check_sampler for a sampler that may fail to produce a sample (NaN rows of
    ``sampler.sample``), as Mitsuba's BSDFs do: harness.samplers.check_with_missing, always
    (a "failed samples" row even where none failed); ``sampler`` needs ``sample``, ``pdf``,
    ``domain`` and ``udim`` (any MitsubaSampler or Mutant, or an object of your own).
    Uniforms come from the stream check_sampler uses (seed, case 0x5A3F).

    Where the sampler has ``sample_with_pdf`` (every MitsubaSampler), the pdf each sample
    call reported is checked against ``pdf()`` at the returned direction: a deterministic
    "reported_pdf" failure with its count and examples (tolerance in the module docstring),
    beside the statistical tests at ``alpha``; Dirac-lobe and failed samples are skipped.
    A sampler's optional ``pole`` (the sphere's, :class:`~harness.samplers.domains.Domain`) and
    ``breaks`` (where its pdf may step or kink, :func:`~harness.samplers.check_sampler`), as
    an envmap's, let the cubature cut at its texel lines.
    A sampler with a ``mapping`` (an area light's map: a Cap or a Rectangle) is tested
    statistically in the map (``mapping.view(sampler)``, with the map's ``breaks``) and its
    reported pdf on the same draw's world directions.
    The check runs with drjit's worker threads set to the sampler's ``check_threads``
    (:class:`~harness.adapters.mitsuba.batch.MitsubaSampler`; one for most plugins), holding
    Mitsuba's variant lock (:func:`~harness.adapters.mitsuba.runtime.jit_threads`).  Its
    cubature passes the pdf the sampler's ``pdf_batch`` directions a call, and, where the
    sampler has ``float32_pdf``, as float32 columns
    (:class:`~harness.samplers.domains.Float32DirectionPdf`; an area light's through its cap's
    map, ``CapView.float32_directions``: the same integrals, bit for bit; a rectangle's
    square through ``pdf``).
    """
    if _scalar_variant(sampler):
        raise ValueError("check_mitsuba_sampler needs a JIT variant ('llvm_ad_rgb'): the cubature evaluates "
                         "the pdf at ~10^7 points, per-sample Python calls of the "
                         f"{sampler.variant!r} variant would take hours")
    with jit_threads(getattr(sampler, "check_threads", None)):
        return _checked(sampler, sample_count, seed, alpha)


def _checked(sampler: Any, sample_count: int, seed: int, alpha: float) -> SamplerCheck:
    """check_mitsuba_sampler's checks, drjit's threads set."""
    mapping = getattr(sampler, "mapping", None)
    with_pdf = getattr(sampler, "sample_with_pdf", None)
    batch = getattr(sampler, "pdf_batch", None)   # the cubature's directions a pdf call
    float32_pdf = float32_pdf_of(sampler)   # where it takes them, the cubature's nodes as float32 columns
    if mapping is None:
        domain = Domain(sampler.domain, pole=getattr(sampler, "pole", "z"))
        pdf = sampler.pdf if float32_pdf is None else Float32DirectionPdf(sampler.pdf, float32_pdf)
        return check_with_missing(with_pdf or sampler.sample, pdf, domain, sample_count=sample_count,
                                  seed=seed, alpha=alpha, udim=sampler.udim,
                                  breaks=getattr(sampler, "breaks", None), pdf_batch=batch)
    view = mapping.view(sampler)
    directions = getattr(view, "float32_directions", None)
    pdf = (view.pdf if float32_pdf is None or directions is None
           else Float32DirectionPdf(view.pdf, view.float32_density, directions))
    r = check_with_missing(view.sample, pdf, view.domain, sample_count=sample_count, seed=seed,
                           alpha=alpha, udim=sampler.udim, breaks=view.breaks,
                           pdf_batch=batch)
    drawn = view.reported_draw()
    if drawn is None:
        return r
    x, reported, values = drawn
    f = reported_pdf_failure(x, reported, sampler.pdf, values=values)
    if f is None:
        return r
    u = rest.points(r.n, sampler.udim, seed=seed, case_id=SAMPLE_CASE)
    f = dataclasses.replace(f, examples=tuple({**ex, "u": u[ex["index"]].tolist()} for ex in f.examples))
    return dataclasses.replace(r, passed=False, failures=[*r.failures, f])


def _scalar_variant(sampler: Any) -> bool:
    variant = getattr(sampler, "variant", None)
    return isinstance(variant, str) and not is_jit(variant)


@dataclass(frozen=True)
class WeightCheck:
    """Outcome of :func:`weight_consistency`.  ``passed``: no weight differs from eval / pdf
    beyond the tolerance and none is NaN, infinite or negative (vacuously True for samplers
    without a weight: microfacet distributions).  Counts are over the produced samples; ``n``
    samples were drawn, of which ``delta`` sampled a Dirac lobe (not produced: no density, no
    weight compared).  ``max_pdf_rel_error``: the largest |reported pdf / pdf() - 1| over the
    produced samples, a figure only (the reported pdf's verdict is ``check_mitsuba_sampler``'s).

    A deterministic check: it never rejects by chance, so ``pvalue`` is 1 (the value a
    suite's Holm correction sees) and ``alpha`` 0; its verdict is its ``failures``."""

    passed: bool
    n: int
    produced: int
    mismatches: int                # weight vs eval/pdf beyond tolerance, any channel
    bad_weights: int               # NaN, infinite or negative weight
    max_rel_error: float           # largest |weight / (eval/pdf) - 1| over the produced samples
    max_pdf_rel_error: float       # largest |reported pdf / pdf() - 1| over the produced samples
    rtol: float
    atol: float
    examples: tuple[dict[str, Any], ...] = ()
    delta: int = 0                 # samples of a Dirac lobe (a mask's pass-through), not produced

    @property
    def verdict(self) -> str:
        """"passed" or "failed"."""
        return "passed" if self.passed else "failed"

    @property
    def pvalue(self) -> float:
        """1: deterministic, no p-value below 1 is ever claimed."""
        return 1.0

    @property
    def alpha(self) -> float:
        """0: deterministic, no false alarms are budgeted."""
        return 0.0

    @property
    def statistic(self) -> float:
        """NaN: a deterministic check has no test statistic (the counts are its figures)."""
        return math.nan

    def confidence_interval(self, confidence_level: float = 0.95) -> ConfidenceInterval:
        """Clopper-Pearson interval of the fraction of produced samples whose weight is wrong
        or invalid ((mismatches + bad_weights) / produced); NaN ends when none was produced.
        0 of ``produced`` for samplers without a weight."""
        level = check_confidence_level(confidence_level)
        if self.produced == 0:
            return ConfidenceInterval(math.nan, math.nan)
        ci = stats.binomtest(self.mismatches + self.bad_weights, self.produced).proportion_ci(level, "exact")
        return ConfidenceInterval(float(ci.low), float(ci.high))

    @property
    def failures(self) -> list[Failure]:
        """One Failure per kind of bad weight (mismatch, NaN/Inf/negative) with its examples."""
        out = []
        for check, count, kind in (("weight_mismatch", self.mismatches, "weight != eval/pdf"),
                                   ("bad_weight", self.bad_weights, "NaN/Inf/negative weight")):
            if count:
                detail = (f"{kind} ({count} of {self.produced} produced samples; largest relative "
                          f"difference {self.max_rel_error:.3g})")
                examples = tuple(e for e in self.examples if e["check"] == kind)
                out.append(Failure(check, count, detail, examples))
        return out

    def to_payload(self) -> dict[str, Any]:
        """JSON-able, in the shape a suite stores a sampler check (passed, pvalue, tests,
        failures, normalization): deterministic, so pvalue is 1 and a mismatch is a failure."""
        tests = [{"test": "weight == eval/pdf", "statistic": float(self.mismatches), "df": 0, "pvalue": 1.0,
                  "detects": f"weight off eval/pdf by > {self.atol:g} + {self.rtol:g} rel + float32 rounding",
                  "adjusted": 1.0},
                 {"test": "NaN/Inf/negative weights", "statistic": float(self.bad_weights), "df": 0,
                  "pvalue": 1.0, "detects": "invalid weights", "adjusted": 1.0}]
        return {"passed": self.passed, "pvalue": self.pvalue, "tests": tests,
                "failures": [f.to_dict() for f in self.failures],
                "normalization": [float("nan"), float("nan")]}

    def __str__(self) -> str:
        head = (f"{self.verdict.upper()}: {self.produced} of {self.n} samples produced; "
                f"{self.mismatches} weight(s) differ from eval/pdf beyond {self.atol:g} + {self.rtol:g} "
                f"relative + float32 rounding (largest relative difference {self.max_rel_error:.2g}); "
                f"{self.bad_weights} NaN/Inf/negative weight(s)")
        return "\n".join([head] + [f"  {e}" for e in self.examples])


def weight_consistency(sampler: Any, *, sample_count: int = 1_000_000, seed: int = 0, rtol: float = 1e-4,
                       atol: float = 1e-6, max_examples: int = 5) -> WeightCheck:
    """For every sample Mitsuba produces: the weight it returns (a Spectrum: BSDF f cos / pdf,
    phase function value / pdf, emitter radiance / pdf) must equal ``eval(x) / pdf(x)``
    re-evaluated at the returned float32 direction, per channel; weights must be finite and
    non-negative.

    A weight mismatch is invisible to a chi-square test (it only sees where samples go) and
    biases every estimate that uses the weight: a weight missing cos theta_o, or 0.1 % too
    large, fails here deterministically.  Tolerance, float32 rounding only: ``atol + rtol
    |eval/pdf|`` (rtol 1e-4: about 840 float32 ulps, for a weight computed along another
    chain of float32 operations) plus the largest change of eval/pdf when one component of
    the direction moves by 4 float32 ulps (computed for the samples outside the plain
    tolerance only).  That term matters where eval/pdf is steep in the direction: an
    environment map's sun edge (radiance 0.4 next to 2000 one texel away) and its poles
    (theta from acos of a float32 near 1).  Failed samples (zero weight) are not compared:
    the failure-count test of ``check_mitsuba_sampler`` judges whether they are as many as
    the pdf says.  Microfacet distributions have no weight: nothing is compared.
    """
    n = int(sample_count)
    if n < 1:
        raise ValueError(f"'sample_count' must be positive, got {sample_count!r}")
    u = rest.points(n, sampler.udim, seed=seed, case_id=_WEIGHT_CASE)
    b = sampler.sample_batch(u)
    idx = np.flatnonzero(b.valid)
    # the rows taken and compared in the core: numpy's indexing and arithmetic on a million
    # (N, 3) rows had taken 80 ms, most of it page faults
    xv = rest.take_rows(b.x, b.valid)
    p = sampler.pdf(xv)
    with np.errstate(all="ignore"):
        pdf_rel = np.where(p > 0, np.abs(rest.take_rows(b.sample_pdf, b.valid) - p) / p, np.inf)
    max_pdf_rel = float(np.max(pdf_rel)) if pdf_rel.size else 0.0
    examples: list[dict[str, Any]] = []
    mismatches = bad = 0
    max_rel = 0.0
    if b.weight is not None:
        constant = len(b.weight) > 0 and b.weight.strides[0] == 0   # one weight (_to_numpy's view)
        w = (np.broadcast_to(b.weight[0], (idx.size, b.weight.shape[1])) if constant
             else rest.take_rows(b.weight, b.valid))
        e = sampler.eval(xv)
        mis, bad_mask, max_rel = rest.weight_agreement(w, e, p, atol, rtol)
        if mis.any():
            sel = np.flatnonzero(mis)

            def weight_of(y: np.ndarray) -> np.ndarray:
                with np.errstate(all="ignore"):
                    return sampler.eval(y) / sampler.pdf(y)[:, None]

            with np.errstate(all="ignore"):
                ratio = e[sel] / p[sel, None]
            spread = rounding_spread(weight_of, xv[sel], ratio)
            mis[sel] = ~np.all(np.abs(w[sel] - ratio) <= atol + rtol * np.abs(ratio) + spread, axis=1)
        mismatches, bad = int(mis.sum()), int(bad_mask.sum())
        for label, mask in (("weight != eval/pdf", mis), ("NaN/Inf/negative weight", bad_mask)):
            for j in np.flatnonzero(mask)[:max_examples]:
                with np.errstate(all="ignore"):
                    ratio_j = e[j] / p[j]
                examples.append({"check": label, "index": int(idx[j]), "u": b.u[idx[j]].tolist(),
                                 "direction": xv[j].tolist(), "weight": w[j].tolist(),
                                 "eval/pdf": ratio_j.tolist(), "eval": e[j].tolist(), "pdf": float(p[j])})
    return WeightCheck(mismatches == 0 and bad == 0, n, int(idx.size), mismatches, bad, max_rel, max_pdf_rel,
                       rtol, atol, tuple(examples), 0 if b.delta is None else int(b.delta.sum()))
