"""Planted faults for power checks: a Mitsuba sampler whose pdf, weight or reported pdf is
deliberately wrong (:class:`Mutant`), and the faults the catalogue plants: weights
(:func:`no_cosine`, :func:`scaled_weight`) and reported pdfs (:func:`lobe_pdf_reported`,
:func:`opacity_missing`, :func:`area_density_reported`, :func:`reported_from`).  Every check
of ``harness.adapters.mitsuba.checks`` must catch its kind (``catalogue.wrong_catalogue``
lists the planted faults, tests/adapters measure it).

Three kinds, one check each:
  pdf        pdf() wrong, consistently: the pdf reported with the samples is the same wrong
             pdf (``pdf_scale``, ``pdf_from``); only the chi-square sees where samples go.
  weight     the weight wrong (``weight_fault``); the weight check.
  reported   only the pdf the sample call reports wrong (``reported_fault``); samples and
             pdf() are right, so only the reported-pdf check sees it.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from harness.adapters.mitsuba.batch import MitsubaSampler, SampleBatch, float32_pdf_of

__all__ = ["Mutant", "area_density_reported", "lobe_pdf_reported", "no_cosine", "opacity_missing",
           "reported_from", "scaled_weight"]

Fault = Callable[[SampleBatch], np.ndarray]


class Mutant:
    """A sampler with a planted fault, for power checks: its samples come from ``base`` and its
    pdf from ``pdf_from`` (default ``base``) times ``pdf_scale`` (the pdf reported with each
    sample is then that pdf too); ``weight_fault(batch)`` rewrites the weights and
    ``reported_fault(batch)`` the reported pdfs ``sample_batch`` returns."""

    def __init__(self, base: MitsubaSampler, name: str, *, pdf_scale: float = 1.0,
                 pdf_from: MitsubaSampler | None = None, weight_fault: Fault | None = None,
                 reported_fault: Fault | None = None):
        self.base, self.name, self.pdf_scale = base, name, pdf_scale
        self.pdf_from, self.weight_fault, self.reported_fault = pdf_from or base, weight_fault, reported_fault
        self._pdf_fault = pdf_scale != 1.0 or pdf_from is not None
        self.domain, self.udim = base.domain, base.udim
        # the base's sphere pole and pdf breaks (an envmap's texel lines): hints to the cubature
        self.pole, self.breaks = getattr(base, "pole", "z"), getattr(self.pdf_from, "breaks", None)
        self.variant, self.kind = base.variant, base.kind
        self.mapping = getattr(base, "mapping", None)   # an area light's: its statistical tests run there
        self.check_threads = getattr(base, "check_threads", None)   # drjit's workers in a check
        self.pdf_batch = getattr(base, "pdf_batch", None)   # the cubature's directions a pdf call

    def sample(self, u: np.ndarray) -> np.ndarray:
        return self.base.sample(u)

    def sample_batch(self, u: np.ndarray) -> SampleBatch:
        b = self.base.sample_batch(u)
        spdf, weight = b.sample_pdf, b.weight
        if self._pdf_fault:
            spdf = np.where(b.valid, self.pdf(np.where(b.valid[:, None], b.x, 0.0)), spdf)
        if self.reported_fault is not None:
            spdf = np.where(b.valid, self.reported_fault(b), spdf)
        if self.weight_fault is not None and weight is not None:
            weight = self.weight_fault(b)
        return SampleBatch(b.u, b.x, weight, spdf, b.valid, b.delta, b.extra)

    def sample_with_pdf(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        b = self.sample_batch(u)
        return b.produced, b.sample_pdf

    def pdf(self, x: np.ndarray) -> np.ndarray:
        return self.pdf_scale * self.pdf_from.pdf(x)

    @property
    def float32_pdf(self) -> Callable[[np.ndarray], np.ndarray] | None:
        """``pdf`` at float32 unit directions as columns (3, N) (MitsubaSampler.float32_pdf),
        the scale applied in float64 as ``pdf`` applies it, where ``pdf_from``'s float32_pdf is
        its pdf (float32_pdf_of); None where not (``pdf_from`` replaces pdf alone, or has none):
        the check then integrates through ``pdf``."""
        fast = float32_pdf_of(self.pdf_from)
        if fast is None:
            return None
        scale = self.pdf_scale
        return lambda columns: scale * np.asarray(fast(columns), dtype=float)

    def eval(self, x: np.ndarray) -> np.ndarray | None:
        return self.base.eval(x)

    def fingerprint(self) -> dict[str, Any]:
        return {**self.base.fingerprint(), "mutant": self.name}

    def __repr__(self) -> str:
        return f"Mutant({self.name!r} of {self.base!r})"


def no_cosine(b: SampleBatch) -> np.ndarray:
    """A ``weight_fault``: the weight without cos theta_o (f / pdf instead of f cos / pdf)."""
    with np.errstate(all="ignore"):
        return b.weight / np.abs(b.x[:, 2:3])


def scaled_weight(factor: float) -> Fault:
    """A ``weight_fault``: the weight times ``factor`` (1.001: 0.1 % too large)."""
    return lambda b: b.weight * factor


def lobe_pdf_reported(lobes: dict[int, MitsubaSampler]) -> Fault:
    """A ``reported_fault`` for a mixture BSDF (``blendbsdf``, a plastic): the pdf of the lobe
    that was sampled reported instead of the mixture's.  ``lobes`` maps a BSDFFlags bit of
    ``sampled_type`` (e.g. 2 DiffuseReflection, 8 GlossyReflection) to a sampler of that lobe
    alone, at the same incident direction."""
    def fault(b: SampleBatch) -> np.ndarray:
        types = b.extra["sampled_type"].astype(np.int64)
        out = b.sample_pdf.copy()
        for bit, lobe in lobes.items():
            rows = b.valid & ((types & bit) != 0)
            if rows.any():
                out[rows] = lobe.pdf(b.x[rows])
        return out
    return fault


def opacity_missing(opacity: float) -> Fault:
    """A ``reported_fault`` for a ``mask``: the nested BSDF's pdf reported without the
    opacity factor (pdf / opacity)."""
    return lambda b: b.sample_pdf / opacity


def area_density_reported(b: SampleBatch) -> np.ndarray:
    """A ``reported_fault`` for an emitter on a shape: the density per unit area reported
    instead of per solid angle (the Jacobian dist^2 / cos theta_light left out)."""
    with np.errstate(all="ignore"):
        return b.sample_pdf * b.extra["cos"] / b.extra["dist"] ** 2


def reported_from(other: MitsubaSampler) -> Fault:
    """A ``reported_fault``: ``other``'s pdf at the sampled directions reported (e.g. a phase
    function's pdf with wi's sign flipped: forward and backward scattering swapped)."""
    return lambda b: other.pdf(np.where(b.valid[:, None], b.x, 0.0))
