"""Checks of Mitsuba samplers that Mitsuba's own chi-square cannot make: a chi-square check
that allows for samples Mitsuba fails to produce, and the check that the weight a sampler
returns equals eval / pdf.

    check_mitsuba_sampler(s)      # a SamplerCheck, like check_sampler's, failures allowed for
    weight_consistency(s)         # a WeightCheck: weight == eval / pdf, sample pdf == pdf()

Failed samples.  A sample Mitsuba could not produce (zero weight) is a NaN row of
``sampler.sample``; ``check_mitsuba_sampler`` is harness.samplers' check_with_missing (the
failure count by an exact binomial test against N (1 - P), the directions produced against
pdf / P).  A pdf 0.5 % too large is caught by the failure count where P < 1 and by the
normalisation (P > 1 + 1e-3) otherwise.

``check_mitsuba_sampler`` refuses scalar variants: its cubature evaluates the pdf at ~10^7
points, one Python call each there.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

import reference_estimators as rest

from harness.adapters.mitsuba.runtime import is_jit
from harness.samplers.check import SamplerCheck, check_with_missing
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
    """
    if _scalar_variant(sampler):
        raise ValueError("check_mitsuba_sampler needs a JIT variant ('llvm_ad_rgb'): the cubature evaluates "
                         "the pdf at ~10^7 points, per-sample Python calls of the "
                         f"{sampler.variant!r} variant would take hours")
    return check_with_missing(sampler.sample, sampler.pdf, sampler.domain, sample_count=sample_count,
                              seed=seed, alpha=alpha, udim=sampler.udim)


def _scalar_variant(sampler: Any) -> bool:
    variant = getattr(sampler, "variant", None)
    return isinstance(variant, str) and not is_jit(variant)


@dataclass(frozen=True)
class WeightCheck:
    """Outcome of :func:`weight_consistency`.  ``passed``: no weight differs from eval / pdf
    beyond the tolerance and none is NaN, infinite or negative (vacuously True for samplers
    without a weight: microfacet distributions).  ``pdf_consistent``: the pdf each sample call
    reports agrees with ``pdf()`` (reported separately: it matters for MIS weights, not for
    the weight).  Counts are over the produced samples; ``n`` samples were drawn.

    A deterministic check: it never rejects by chance, so ``pvalue`` is 1 (the value a
    suite's Holm correction sees) and ``alpha`` 0; its verdict is its ``failures``."""

    passed: bool
    pdf_consistent: bool
    n: int
    produced: int
    mismatches: int                # weight vs eval/pdf beyond tolerance, any channel
    bad_weights: int               # NaN, infinite or negative weight
    pdf_mismatches: int            # sample pdf vs pdf() beyond tolerance
    max_rel_error: float           # largest |weight / (eval/pdf) - 1| over the produced samples
    max_pdf_rel_error: float       # largest |sample pdf / pdf() - 1|
    rtol: float
    atol: float
    pdf_rtol: float
    examples: tuple[dict[str, Any], ...] = ()

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
        """One Failure per kind of bad weight (mismatch, NaN/Inf/negative) with its examples;
        a sample pdf that disagrees with pdf() is informational, not a failure."""
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
        failures, normalization): deterministic, so pvalue is 1 and a mismatch is a failure;
        the sample-pdf agreement is a test row, informational (never a failure)."""
        tests = [{"test": "weight == eval/pdf", "statistic": float(self.mismatches), "df": 0, "pvalue": 1.0,
                  "detects": f"weight off eval/pdf by > {self.atol:g} + {self.rtol:g} rel + float32 rounding",
                  "adjusted": 1.0},
                 {"test": "NaN/Inf/negative weights", "statistic": float(self.bad_weights), "df": 0,
                  "pvalue": 1.0, "detects": "invalid weights", "adjusted": 1.0},
                 {"test": "sample pdf == pdf() (informational)", "statistic": float(self.pdf_mismatches),
                  "df": 0, "pvalue": 1.0,
                  "detects": f"largest relative difference {self.max_pdf_rel_error:.3g}", "adjusted": 1.0}]
        return {"passed": self.passed, "pvalue": self.pvalue, "tests": tests,
                "failures": [f.to_dict() for f in self.failures],
                "normalization": [float("nan"), float("nan")]}

    def __str__(self) -> str:
        head = (f"{self.verdict.upper()}: {self.produced} of {self.n} samples produced; "
                f"{self.mismatches} weight(s) differ from eval/pdf beyond {self.atol:g} + {self.rtol:g} "
                f"relative + float32 rounding (largest relative difference {self.max_rel_error:.2g}); "
                f"{self.bad_weights} NaN/Inf/negative weight(s); {self.pdf_mismatches} sample pdf(s) differ "
                f"from pdf() beyond {self.pdf_rtol:g} relative + rounding (largest "
                f"{self.max_pdf_rel_error:.2g})")
        return "\n".join([head] + [f"  {e}" for e in self.examples])


_NUDGE_ULPS = 4


def _nudged(x32: np.ndarray) -> Iterator[np.ndarray]:
    """x (float32 values) with one component moved by 4 float32 ulps up or down: 6 copies."""
    for c in range(3):
        for to in (np.inf, -np.inf):
            y = x32.copy()
            col = y[:, c]
            for _ in range(_NUDGE_ULPS):
                col = np.nextafter(col, np.float32(to), dtype=np.float32)
            y[:, c] = col
            yield y.astype(np.float64)


def _rounding_spread(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, at: np.ndarray) -> np.ndarray:
    """max |f(x') - f(x)| over the 6 nudged copies x' of x: what float32 rounding of the
    direction can change f by (NaN-safe: a non-finite change counts as infinite)."""
    spread = np.zeros_like(at)
    for y in _nudged(x.astype(np.float32)):
        with np.errstate(all="ignore"):
            d = np.abs(f(y) - at)
        spread = np.maximum(spread, np.where(np.isfinite(d), d, np.inf))
    return spread


def weight_consistency(sampler: Any, *, sample_count: int = 1_000_000, seed: int = 0, rtol: float = 1e-4,
                       atol: float = 1e-6, pdf_rtol: float = 1e-3, max_examples: int = 5) -> WeightCheck:
    """For every sample Mitsuba produces: the weight it returns (a Spectrum: BSDF f cos / pdf,
    emitter radiance / pdf) must equal ``eval(x) / pdf(x)`` re-evaluated at the returned
    float32 direction, per channel; weights must be finite and non-negative.  Separately, the
    pdf the sample call reports must equal ``pdf(x)``.

    A weight mismatch is invisible to a chi-square test (it only sees where samples go) and
    biases every estimate that uses the weight: a weight missing cos theta_o, or 0.1 % too
    large, fails here deterministically.  Tolerance: ``atol + rtol |eval/pdf|`` plus what
    float32 rounding of the direction can explain, measured, not guessed: the largest change
    of eval/pdf when one component of the direction moves by 4 float32 ulps (computed for the
    samples outside the plain tolerance only).  That term matters where eval/pdf is steep in
    the direction: an environment map's sun edge (radiance 0.4 next to 2000 one texel away)
    and its poles (theta from acos of a float32 near 1); elsewhere rtol 1e-4 (about 800
    float32 ulps) dominates, and correct plugins stay below 1e-5.  The sample pdf gets
    ``pdf_rtol`` (it may be computed another way, e.g. from the sampled microfacet normal
    rather than the half vector of the returned direction) plus the same rounding term.
    Failed samples (zero weight) are not compared: the failure-count test of
    ``check_mitsuba_sampler`` judges whether they are as many as the pdf says.  Microfacet
    distributions have no weight: only the pdf agreement is checked.
    """
    n = int(sample_count)
    if n < 1:
        raise ValueError(f"'sample_count' must be positive, got {sample_count!r}")
    u = rest.points(n, sampler.udim, seed=seed, case_id=_WEIGHT_CASE)
    b = sampler.sample_batch(u)
    idx = np.flatnonzero(b.valid)
    xv = b.x[idx]
    p = sampler.pdf(xv, normalize=False)
    sp = b.sample_pdf[idx]
    examples: list[dict[str, Any]] = []

    def where(j: int) -> dict[str, Any]:
        return {"index": int(idx[j]), "u": b.u[idx[j]].tolist(), "direction": xv[j].tolist()}

    with np.errstate(all="ignore"):
        pdf_diff = np.abs(sp - p)
        pdf_rel = np.where(p > 0, pdf_diff / p, np.inf)
    pdf_bad = ~(pdf_diff <= pdf_rtol * np.abs(p))
    if pdf_bad.any():
        sel = np.flatnonzero(pdf_bad)
        spread = _rounding_spread(lambda y: sampler.pdf(y, normalize=False), xv[sel], p[sel])
        pdf_bad[sel] = ~(pdf_diff[sel] <= pdf_rtol * np.abs(p[sel]) + spread)
    mismatches = bad = 0
    max_rel = 0.0
    if b.weight is not None:
        w = b.weight[idx]
        e = sampler.eval(xv, normalize=False)
        with np.errstate(all="ignore"):
            ratio = e / p[:, None]
            diff = np.abs(w - ratio)
            rel = np.where(np.abs(ratio) > atol, diff / np.abs(ratio), diff)
        bad_mask = ~np.all(np.isfinite(w) & (w >= 0), axis=1)
        mis = ~np.all(diff <= atol + rtol * np.abs(ratio), axis=1) & ~bad_mask
        if mis.any():
            sel = np.flatnonzero(mis)

            def weight_of(y: np.ndarray) -> np.ndarray:
                with np.errstate(all="ignore"):
                    return sampler.eval(y, normalize=False) / sampler.pdf(y, normalize=False)[:, None]

            spread = _rounding_spread(weight_of, xv[sel], ratio[sel])
            mis[sel] = ~np.all(diff[sel] <= atol + rtol * np.abs(ratio[sel]) + spread, axis=1)
        good = ~bad_mask
        max_rel = float(np.max(np.nan_to_num(rel[good], nan=np.inf))) if good.any() else 0.0
        mismatches, bad = int(mis.sum()), int(bad_mask.sum())
        for label, mask in (("weight != eval/pdf", mis), ("NaN/Inf/negative weight", bad_mask)):
            for j in np.flatnonzero(mask)[:max_examples]:
                examples.append({"check": label, **where(j), "weight": w[j].tolist(),
                                 "eval/pdf": ratio[j].tolist(), "eval": e[j].tolist(), "pdf": float(p[j])})
    for j in np.flatnonzero(pdf_bad)[:max_examples]:
        examples.append({"check": "sample pdf != pdf()", **where(j), "sample_pdf": float(sp[j]),
                         "pdf": float(p[j])})
    max_pdf_rel = float(np.max(pdf_rel)) if pdf_rel.size else 0.0
    return WeightCheck(mismatches == 0 and bad == 0, not pdf_bad.any(), n, int(idx.size), mismatches, bad,
                       int(pdf_bad.sum()), max_rel, max_pdf_rel, rtol, atol, pdf_rtol, tuple(examples))

