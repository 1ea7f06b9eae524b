"""The equal-area map of a spherical cap onto the hemisphere, for checking a light that covers
a small cone of directions.

An area light seen from a reference point covers a small cap of the sphere of directions
(a sphere of radius 0.5 at distance 2: 1.5 % of it).  Checked on the whole sphere, the light
falls into a few hundred of the check's cells and its rim cuts them along curves that the
cubature's nodes can straddle: at 1e6 samples the cubature then loses ~5e-5 of the mass at
the rim, beyond its error bound, and the failure count and the fine chi-square reject a
correct sampler.  A cap {d : <d, axis> >= cos_alpha} that contains the light is mapped onto
the hemisphere by

    z' = (<d, axis> - cos_alpha) / (1 - cos_alpha),   azimuth about the axis kept,

which multiplies solid angle by 1 / (1 - cos_alpha) everywhere (Archimedes: area on the
sphere is uniform in z), so a density per steradian p(d) becomes p(d) (1 - cos_alpha) on the
hemisphere, and a weight eval / p becomes weight / (1 - cos_alpha).  It is a fixed bijection:
the hypothesis tested is the same, the light fills the check's grid (more power), and for a
sphere light the cap is its cone, whose rim becomes the hemisphere's horizon.  A direction
outside the cap maps below the horizon (z' < 0): outside the domain, reported as such.

:class:`CapView` shows a light's sampler through the map to the statistical check; the
reported pdf and the weight are checked on the world directions themselves
(``checks.check_mitsuba_sampler``), where float32 ulps have their renderer's meaning (in the
map, a coordinate near the horizon has ulps far finer than the world direction's).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

import reference_estimators as rest

from harness.adapters.mitsuba.batch import UNIT_SLACK
from harness.adapters.mitsuba.views import FEW_ROWS, MappedView

__all__ = ["Cap", "CapView", "bounding_cap", "box_cap"]

#: directions this little outside the cap (in cos theta) are float32 rounding of its rim
_RIM_SLACK = 2e-7


class Cap:
    """The cap {d : <d, axis> >= cos_alpha} and its equal-area map onto the hemisphere z >= 0."""

    domain, point_dim = "hemisphere", 3   # the check's domain in the map: (N, 3) points
    breaks = None                          # the density's steps and kinks there: not known

    def __init__(self, axis: Sequence[float], cos_alpha: float):
        a = np.asarray(axis, dtype=float)
        if a.shape != (3,) or not np.all(np.isfinite(a)) or np.linalg.norm(a) == 0:
            raise ValueError(f"'axis' must be a non-zero 3-vector, got {axis!r}")
        if not -1 < cos_alpha < 1:
            raise ValueError(f"'cos_alpha' must be in (-1, 1), got {cos_alpha!r}")
        self.axis = a / np.linalg.norm(a)
        self.cos_alpha = float(cos_alpha)
        self.scale = 1.0 - self.cos_alpha     # solid angle of the cap / 2 pi
        helper = np.array([1.0, 0.0, 0.0]) if abs(self.axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        t = np.cross(helper, self.axis)
        self.t = t / np.linalg.norm(t)
        self.b = np.cross(self.axis, self.t)

    def to_hemisphere(self, d: np.ndarray) -> np.ndarray:
        """World directions d (N, 3) -> points of the hemisphere (N, 3); NaN rows stay NaN.
        Directions within float32 rounding of the rim land on the horizon.  The azimuth's
        cosine and sine as ratios, no trigonometry: one batch call to the core
        (:func:`reference_estimators.cap_to_hemisphere`; numpy had cost 90 ns a direction)."""
        return rest.cap_to_hemisphere(d, self.axis, self.t, self.b, self.cos_alpha, self.scale, _RIM_SLACK)

    def to_domain(self, d: np.ndarray) -> np.ndarray:
        """:meth:`to_hemisphere`: the map as :class:`~harness.adapters.mitsuba.views.MappedView`
        calls it."""
        return self.to_hemisphere(d)

    def density(self, h: np.ndarray, world_pdf: np.ndarray) -> np.ndarray:
        """(N,): the density on the hemisphere at h (N, 3) of the world pdf values there: their
        float32 rounding times 1 - cos alpha in float32, 0 below the horizon
        (:func:`reference_estimators.cap_density`)."""
        return rest.cap_density(h, world_pdf, self.scale)

    def to_world(self, x: np.ndarray) -> np.ndarray:
        """Points of the hemisphere (N, 3) (normalised first) -> world directions (N, 3); a
        point below the horizon maps outside the cap (at most to the cap's antipode).  The
        azimuth's cosine and sine are x / r and y / r, no trigonometry: the cubature maps tens
        of millions of nodes, one batch call to the core
        (:func:`reference_estimators.cap_to_world`; numpy had cost 90 ns a node)."""
        return rest.cap_to_world(x, self.axis, self.t, self.b, self.cos_alpha, self.scale)

    def spec(self) -> dict[str, object]:
        return {"axis": self.axis.tolist(), "cos_alpha": self.cos_alpha}

    def view(self, sampler: Any) -> CapView:
        """``sampler`` seen through this map, as the check tests it."""
        return CapView(sampler, self)


class CapView(MappedView):
    """``sampler`` (world directions, pdf per steradian) seen through a :class:`Cap`'s map,
    ``CapView(sampler, cap)`` (:class:`~harness.adapters.mitsuba.views.MappedView`, the cap its
    ``map``): ``sample(u)`` gives points of the hemisphere (NaN rows kept), ``pdf(h)`` the
    density per unit area of the hemisphere, the world pdf times 1 - cos alpha (0 below the
    horizon), ``domain`` "hemisphere"; and the cubature's nodes as float32 world directions
    (``float32_directions``).

    Off the draw (cubature nodes) the pdf is evaluated at the float32 rounding of the
    mapped-back direction.  The density is the world pdf times the map's constant Jacobian in
    float32, the world pdf's own precision, so that the cubature stops at its rounding
    (harness.samplers.cubature.rounding_floor)."""

    def float32_directions(self, lo: np.ndarray, hi: np.ndarray,
                           nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """The world directions of the tensor rule's nodes on boxes [lo, hi] (M, 2) of the
        hemisphere through the cap's map, as the sampler's float32_pdf takes them (float32
        columns in the core's interleaved order, and a per-node ok): ``pdf``'s, the same bits,
        in one pass (:func:`reference_estimators.cubature_cap_float32_directions`); the
        ``directions`` of :class:`~harness.samplers.domains.Float32DirectionPdf`.  None for up
        to FEW_ROWS nodes: ``pdf`` then looks them up among the draw's points, as before."""
        if lo.shape[0] * np.size(nodes) ** 2 <= FEW_ROWS:
            return None
        c = self.map
        return rest.cubature_cap_float32_directions(lo, hi, nodes, c.axis, c.t, c.b, c.cos_alpha, c.scale,
                                                    UNIT_SLACK)

    def float32_density(self, columns: np.ndarray) -> np.ndarray:
        """``pdf`` at the hemisphere points whose world directions are the float32 columns
        (3, N) (:meth:`float32_directions`): the sampler's float32_pdf there, rounded to
        float32, times the Jacobian in float32, as float32 (``pdf``'s density, cap_density's
        product, widened where it is summed)."""
        p = np.asarray(self.sampler.float32_pdf(columns), dtype=np.float32)
        return p * np.float32(self.map.scale)


def bounding_cap(ref: Sequence[float], center: Sequence[float], radius: float) -> Cap | None:
    """The cap of directions from ``ref`` that holds the ball (``center``, ``radius``): the
    ball's cone; None where ``ref`` is inside the ball (no cap smaller than the sphere)."""
    d = np.asarray(center, dtype=float) - np.asarray(ref, dtype=float)
    dist = float(np.linalg.norm(d))
    if not dist > radius * (1 + 1e-6):
        return None
    return Cap(d / dist, math.sqrt(1 - (radius / dist) ** 2))


def box_cap(ref: Sequence[float], lo: Sequence[float], hi: Sequence[float]) -> Cap | None:
    """The cap of directions from ``ref`` about the box's centre that holds the box [lo, hi]
    (its 8 corners: the directions to a convex set lie in the convex cone its corners span);
    None where ``ref`` is in the box or the cap would exceed a hemisphere."""
    r, lo, hi = (np.asarray(v, dtype=float) for v in (ref, lo, hi))
    if np.all((r >= lo) & (r <= hi)):
        return None
    axis = (lo + hi) / 2 - r
    axis /= np.linalg.norm(axis)
    corners = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)]) - r
    cos = float(np.min(corners @ axis / np.linalg.norm(corners, axis=1)))
    return Cap(axis, cos - 1e-6) if cos > 1e-3 else None
