"""The map of the directions towards a rectangle light onto the light's own unit square, for
checking its sampler there.

Seen through a cap (:mod:`harness.adapters.mitsuba.cap`), a rectangle's outline is four arcs
across the check's cells, and a bitmap's texel lines are more curves: steps along curves,
which the cubature resolves box by box (14-23 million pdf calls for the CDF tables alone at
1e6 samples, about a second a check).  Parameterised instead by the point its direction hits,

    P(s) = corner + s0 e0 + s1 e1,   s in [0, 1]^2

(Mitsuba's rectangle: the local point (2 s0 - 1, 2 s1 - 1, 0), s its uv), the light is the
whole square, its outline the square's edges and its texel lines lines of the square, which
the check's cubature and CDF tables cut at (``breaks``).  The density per unit area of the
square is the world pdf per steradian times the solid angle a unit of s-area subtends from
the reference point,

    q(s) = p(w(s)) |e0 x e1| |<n, w(s)>| / |P(s) - ref|^2,   w(s) = (P(s) - ref) / |P(s) - ref|,

a fixed bijection of the directions that hit the rectangle onto the square: the hypothesis
tested is the same.  A direction that misses the rectangle's plane in front of ``ref`` maps
outside the square, (-1, -1), and is reported as outside the domain; one within float32
rounding of an edge (:attr:`Rectangle.slack`) lands on it.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

import reference_estimators as rest

from harness.adapters.mitsuba.views import MappedView

__all__ = ["Rectangle"]

#: The least edge slack (in s): a float32 direction's rounding seen head-on and near
_EDGE_SLACK = 1e-6
#: Past this slack a rectangle is seen too obliquely, or lies too far from the origin, for
#: float32 to place its samples on the square (``of_rectangle`` declines it, and the light is
#: tested in its cap's map)
_MAX_SLACK = 1e-4
#: A float32 unit direction's rounding, as an angle: each component's half ulp, 2^-24 relative
_FLOAT32_ANGLE = 2.0**-24


class Rectangle:
    """The parallelogram corner + s0 e0 + s1 e1 (s in [0, 1]^2, world space) seen from
    ``ref``, and the map of directions from ``ref`` onto its square; ``texels`` (width,
    height): a bitmap's texel grid along s0 and s1, whose lines and centres are the density's
    ``breaks``."""

    domain, point_dim = "square", 2   # the check's domain in the map: (N, 2) points

    def __init__(self, ref: Sequence[float], corner: Sequence[float], e0: Sequence[float],
                 e1: Sequence[float], texels: tuple[int, int] | None = None):
        r, c, a, b = (np.asarray(v, dtype=float) for v in (ref, corner, e0, e1))
        for name, v in (("ref", r), ("corner", c), ("e0", a), ("e1", b)):
            if v.shape != (3,) or not np.all(np.isfinite(v)):
                raise ValueError(f"'{name}' must be a finite 3-vector, got {v!r}")
        cross = np.cross(a, b)
        self.area = float(np.linalg.norm(cross))    # |e0 x e1|: the square's unit of area, in world area
        if not self.area > 0:
            raise ValueError(f"'e0' and 'e1' must span a plane, got {a!r} and {b!r}")
        self.ref, self.corner, self.e0, self.e1 = r, c, a, b
        self.normal = cross / self.area
        self.height = float(self.normal @ (c - r))   # the plane's signed distance from ref
        if abs(self.height) <= 1e-9 * max(np.linalg.norm(a), np.linalg.norm(b)):
            raise ValueError("'ref' lies in the rectangle's plane: it sees the light edge-on")
        # the dual basis in the plane: f_i . e_j = delta_ij, so s_i = (P - corner) . f_i
        self.dual = np.linalg.solve(np.array([[a @ a, a @ b], [a @ b, b @ b]]), np.stack([a, b]))
        self.texels = None if texels is None else (int(texels[0]), int(texels[1]))
        # how far outside the square float32 rounding can put a sample on an edge (in s, which
        # a displacement d in the plane moves by at most |d| max|f_i|): the sampled point's own
        # coordinates, rounded (|P| 2^-24), and the direction to it, rounded (an angle of 2^-24 a
        # component, which moves the hit by dist / cos times that, cos = |height| / dist: dist^2
        # / |height|, largest at the farthest corner); four times the bound, at least
        # _EDGE_SLACK (1e-6 from the catalogue's points: dist 1.7-2.2, cos 0.3-0.6)
        corners = [c + i * a + j * b for i in (0, 1) for j in (0, 1)]
        far = max(float(np.linalg.norm(p - r)) for p in corners)
        size = max(float(np.linalg.norm(p)) for p in corners)
        shear = float(np.linalg.norm(self.dual, axis=1).max())
        bound = _FLOAT32_ANGLE * (far * far / abs(self.height) + size) * shear
        self.slack = max(_EDGE_SLACK, 4 * bound)

    @classmethod
    def of_rectangle(cls, ref: Sequence[float], to_world: np.ndarray | None,
                     texels: tuple[int, int] | None = None, *, float32: bool = True) -> Rectangle | None:
        """Mitsuba's rectangle shape with transform ``to_world`` (4 x 4; None: the identity),
        from ``ref``; None where ``ref`` lies in its plane or sees it so obliquely that its
        :attr:`slack` would pass 1e-4 of a side (a sample's float32 rounding could then put it
        that far off the square: a light 20 sides away at a 0.1 % rise, say).  ``float32``: the
        variant's geometry is single precision, so the transform and ``ref`` are rounded to
        float32 first, as Mitsuba holds them (in float64 the light 100 units from the origin sat
        up to 2e-6 of a side off Mitsuba's own, beyond the slack)."""
        m = np.eye(4) if to_world is None else np.asarray(to_world, dtype=float)
        r = np.asarray(ref, dtype=float)
        if float32:
            m, r = (v.astype(np.float32).astype(float) for v in (m, r))
        corner = (m @ [-1.0, -1.0, 0.0, 1.0])[:3]
        try:
            rect = cls(r, corner, m[:3, 0] * 2, m[:3, 1] * 2, texels)
        except ValueError:
            return None
        return rect if rect.slack <= _MAX_SLACK else None

    @property
    def frame(self) -> tuple:
        """(corner - ref, e0, e1, n, dual basis (2, 3), <n, corner - ref>, |e0 x e1|): the map as
        the core's kernels take it (:func:`reference_estimators.rect_to_square`)."""
        return (self.corner - self.ref, self.e0, self.e1, self.normal, self.dual, self.height, self.area)

    def to_domain(self, d: np.ndarray) -> np.ndarray:
        """World directions d (N, 3) from ``ref`` -> points s (N, 2) of the square where their
        rays hit the rectangle's plane; NaN rows stay NaN; rays that miss the plane in front
        of ``ref`` give (-1, -1); within :attr:`slack` of the square, onto its edge.  One pass
        in the core (:func:`reference_estimators.rect_to_square`; numpy had cost 0.15 s a
        million directions)."""
        return rest.rect_to_square(d, self.frame, self.slack)

    def to_world(self, s: np.ndarray) -> np.ndarray:
        """Points s (N, 2) -> unit world directions (N, 3) from ``ref`` towards P(s)
        (:func:`reference_estimators.rect_to_world`)."""
        return rest.rect_to_world(s, self.frame)

    def density(self, s: np.ndarray, world_pdf: np.ndarray) -> np.ndarray:
        """(N,): the density on the square at s (N, 2) of the world pdf values there: their
        float32 rounding times the steradians per unit area of the square, |e0 x e1| |<n, w>| /
        |w|^3 (w = P(s) - ref), in float32; 0 outside the square
        (:func:`reference_estimators.rect_density`)."""
        return rest.rect_density(s, world_pdf, self.frame)

    @property
    def breaks(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Where the density may step or kink along s0 and s1: a bitmap's texel lines (a
        nearest filter's steps) and centres (a bilinear filter's kinks); None without one."""
        if self.texels is None:
            return None
        return tuple(np.unique(np.concatenate([np.arange(1, n) / n, (np.arange(n) + 0.5) / n]))
                     for n in self.texels)

    def spec(self) -> dict[str, object]:
        return {"corner": self.corner.tolist(), "e0": self.e0.tolist(), "e1": self.e1.tolist(),
                "texels": list(self.texels) if self.texels else None, "slack": self.slack}

    def view(self, sampler: Any) -> MappedView:
        """``sampler`` seen through this map, as the check tests it: points of the square,
        ``pdf`` the density per unit area of the square (0 outside it), ``breaks`` the
        rectangle's (:class:`~harness.adapters.mitsuba.views.MappedView`)."""
        return MappedView(sampler, self)
