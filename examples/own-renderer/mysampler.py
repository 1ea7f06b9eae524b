"""A team's own BSDF sampler: cosine-weighted directions on the hemisphere (z up).

``CosineHemisphere`` is correct; ``SkewedCosine`` is its subtly wrong twin (the radius is
u0 ** 0.52 instead of sqrt(u0): slightly too many directions near the pole) with the same
claimed pdf.  ``Absorbing`` produces no direction (a NaN row) for a fraction of the uniforms,
as a BSDF with an albedo below one does; its pdf integrates to the albedo (``total``).
"""
from __future__ import annotations

import numpy as np


class CosineHemisphere:
    domain = "hemisphere"
    exponent = 0.5

    def sample(self, u: np.ndarray) -> np.ndarray:
        """Unit vectors (N, 3) from uniforms (N, 2)."""
        r, phi = u[:, 0] ** self.exponent, 2 * np.pi * u[:, 1]
        return np.column_stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(1 - r * r, 0.0))])

    def pdf(self, w: np.ndarray) -> np.ndarray:
        """cos(theta) / pi per steradian."""
        return np.maximum(w[:, 2], 0.0) / np.pi


class SkewedCosine(CosineHemisphere):
    exponent = 0.52


class Absorbing(CosineHemisphere):
    """Reflects with probability ``albedo`` (then a cosine direction), else no sample."""

    def __init__(self, albedo: float = 0.8):
        self.albedo = self.total = albedo

    def sample(self, u: np.ndarray) -> np.ndarray:
        kept = u[:, 0] < self.albedo
        w = super().sample(np.column_stack([np.where(kept, u[:, 0] / self.albedo, 0.5), u[:, 1]]))
        w[~kept] = np.nan
        return w

    def pdf(self, w: np.ndarray) -> np.ndarray:
        return self.albedo * super().pdf(w)


good = CosineHemisphere()
skewed = SkewedCosine()
