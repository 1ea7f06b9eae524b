"""Mitsuba 3 phase functions as batch sample / pdf / eval triples for the sampler checks.

    s = phase_sampler({"type": "hg", "g": 0.9}, wi=45)
    x = s.sample(u)       # u (N, 3) -> directions wo (N, 3) on the sphere
    s.pdf(x)              # (N,) per steradian: the pdf of phase.eval_pdf
    s.eval(x)             # (N, channels): the phase function's value, whose ratio to pdf the weight is

Conventions (Mitsuba's).  A medium interaction at the origin with ``mei.wi`` the direction
towards the previous vertex (minus the direction light travels in), given as a polar angle in
degrees in [0, 180] (azimuth 0) or any non-zero 3-vector, and the shading frame
``Frame3f(wi)`` that Mitsuba's media set.  Directions wo are world-space unit vectors on the
whole sphere; forward scattering (Henyey-Greenstein g > 0) sends wo near -wi, and
E[<wo, wi>] = -g.  ``phase.sample(ctx, mei, u0, (u1, u2))`` returns (wo, weight, pdf);
``phase.eval_pdf(ctx, mei, wo)`` (value, pdf).  A phase function has no Dirac lobe and never
fails to produce a sample, so the check expects P = 1.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from harness.adapters.mitsuba.batch import MitsubaSampler, plugin_label, polar_angle, zeros
from harness.adapters.mitsuba.runtime import using_variant

__all__ = ["PhaseSampler", "phase_sampler"]


def _incident(wi: float | Sequence[float]) -> tuple[float, float, float]:
    """A polar angle in degrees in [0, 180] (azimuth 0) or a non-zero 3-vector, as a unit vector."""
    if np.ndim(wi) == 0:
        theta = float(wi)
        if not 0 <= theta <= 180:
            raise ValueError(f"'wi' as an angle must be a polar angle in degrees in [0, 180], got {wi!r}")
        t = math.radians(theta)
        return (math.sin(t), 0.0, math.cos(t))
    v = np.asarray(wi, dtype=float)
    norm = float(np.linalg.norm(v)) if v.shape == (3,) else 0.0
    if v.shape != (3,) or not np.all(np.isfinite(v)) or norm == 0:
        raise ValueError(f"'wi' must be a polar angle in degrees or a non-zero 3-vector, got {wi!r}")
    return tuple(float(c) for c in v / norm)  # type: ignore[return-value]


class PhaseSampler(MitsubaSampler):
    """A Mitsuba phase function at a fixed incident direction ``wi`` (see the module): udim 3
    (u0 picks the component of a ``blendphase``), the sphere."""

    kind = "phase"
    udim = 3
    domain = "sphere"
    sample_outputs = ("x", "weight", "pdf")

    def __init__(self, plugin: dict[str, Any], wi: float | Sequence[float] = 0.0,
                 variant: str = "llvm_ad_rgb", name: str | None = None):
        if not isinstance(plugin, dict) or not isinstance(plugin.get("type"), str):
            raise ValueError("'plugin' must be a Mitsuba phase function dict with a 'type' key, "
                             f"got {plugin!r}")
        self.plugin = dict(plugin)
        self.wi = _incident(wi)
        super().__init__(variant, name or f"{plugin_label(self.plugin)} θi={polar_angle(self.wi):g}°")
        phase = self._build_checked(f"a phase function from {self.plugin!r}")
        with using_variant(self.variant) as mi:
            if not isinstance(phase, mi.PhaseFunction):
                raise ValueError(f"'plugin': {self.plugin['type']!r} is not a phase function")

    def _build(self, mi: Any) -> Any:
        return mi.load_dict(self.plugin)

    def _mei(self, mi: Any, width: int | None) -> Any:
        mei = zeros(mi, "MediumInteraction3f", width)
        wi = mi.Vector3f(*self.wi)
        mei.wi = wi
        mei.sh_frame = mi.Frame3f(wi)
        return mei

    def _sample_kernel(self, mi, phase, width, u0, u1, u2):
        ctx = mi.PhaseFunctionContext(None)
        wo, weight, pdf = phase.sample(ctx, self._mei(mi, width), u0, mi.Point2f(u1, u2))
        return wo, weight, pdf

    def _pdf_kernel(self, mi, phase, width, x, y, z):
        _, pdf = phase.eval_pdf(mi.PhaseFunctionContext(None), self._mei(mi, width), mi.Vector3f(x, y, z))
        return pdf

    def _eval_kernel(self, mi, phase, width, x, y, z):
        value, _ = phase.eval_pdf(mi.PhaseFunctionContext(None), self._mei(mi, width), mi.Vector3f(x, y, z))
        return value

    def _spec(self) -> dict[str, Any]:
        return {"plugin": self.plugin, "wi": list(self.wi)}


def phase_sampler(plugin: dict[str, Any], *, wi: float | Sequence[float] = 0.0, variant: str = "llvm_ad_rgb",
                  name: str | None = None) -> PhaseSampler:
    """A Mitsuba phase function (``hg``, ``rayleigh``, ``isotropic``, ``blendphase`` or any
    other ``mi.load_dict`` phase dict) as a sampler on the sphere of directions wo, density
    per steradian, at incident direction ``wi`` (polar angle in degrees in [0, 180], or a
    3-vector; Mitsuba's mei.wi, see the module)."""
    return PhaseSampler(plugin, wi, variant, name)
