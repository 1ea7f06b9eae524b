"""Planted faults for power checks: a Mitsuba sampler whose pdf or weight is deliberately
wrong (:class:`Mutant`), and the weight faults the catalogue plants (:func:`no_cosine`).
Every check of ``harness.adapters.mitsuba.checks`` must catch them
(``catalogue.wrong_catalogue`` lists the planted faults, tests/adapters measure it)."""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from harness.adapters.mitsuba.samplers import MitsubaSampler, SampleBatch

__all__ = ["Mutant", "no_cosine"]


class Mutant:
    """A sampler with a planted fault, for power checks: its samples come from ``base`` and its
    pdf from ``pdf_from`` (default ``base``) times ``pdf_scale``; ``weight_fault(batch)``
    rewrites the weights ``sample_batch`` returns (e.g. drops cos theta_o)."""

    def __init__(self, base: MitsubaSampler, name: str, *, pdf_scale: float = 1.0,
                 pdf_from: MitsubaSampler | None = None,
                 weight_fault: Callable[[SampleBatch], np.ndarray] | None = None):
        self.base, self.name, self.pdf_scale = base, name, pdf_scale
        self.pdf_from, self.weight_fault = pdf_from or base, weight_fault
        self.domain, self.udim = base.domain, base.udim
        self.variant, self.kind = base.variant, base.kind

    def sample(self, u: np.ndarray) -> np.ndarray:
        return self.base.sample(u)

    def sample_batch(self, u: np.ndarray) -> SampleBatch:
        b = self.base.sample_batch(u)
        if self.weight_fault is None or b.weight is None:
            return b
        return SampleBatch(b.u, b.x, self.weight_fault(b), b.sample_pdf, b.valid)

    def pdf(self, x: np.ndarray, *, normalize: bool = True) -> np.ndarray:
        return self.pdf_scale * self.pdf_from.pdf(x, normalize=normalize)

    def eval(self, x: np.ndarray, *, normalize: bool = True) -> np.ndarray | None:
        return self.base.eval(x, normalize=normalize)

    def fingerprint(self) -> dict[str, Any]:
        return {**self.base.fingerprint(), "mutant": self.name}

    def __repr__(self) -> str:
        return f"Mutant({self.name!r} of {self.base!r})"


def no_cosine(b: SampleBatch) -> np.ndarray:
    """A ``weight_fault``: the weight without cos theta_o (f / pdf instead of f cos / pdf)."""
    with np.errstate(all="ignore"):
        return b.weight / np.abs(b.x[:, 2:3])

