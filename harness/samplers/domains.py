"""Sampling domains and their equal-measure parameterisations.

Every domain is mapped onto the unit interval or square with a constant Jacobian (except the
half line), so equal cells there are cells of equal measure:

    interval [a, b]   s = (x - a) / (b - a)                  |D| = b - a
    half_line [0,inf) s = x / (1 + x)                         dx/ds = 1 / (1 - s)^2 (not constant)
    square [0, 1]^2   s = (x, y)                              |D| = 1
    disk (unit)       s = (r^2, phi / 2 pi)                   |D| = pi
    hemisphere (z>0)  s = (cos theta, phi / 2 pi)             |D| = 2 pi   (solid angle)
    sphere            s = ((1 - cos theta) / 2, phi / 2 pi)   |D| = 4 pi
                      (theta from +z, or from +y or +x: Domain("sphere", pole="y"))

A claimed density pdf(x) becomes q(s) = |D| pdf(x(s)) in parameter space (pdf(x(s)) dx/ds
on the half line), the density the cubature integrates and the histograms are compared with.
"""
from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

import reference_estimators as rest
from reference_estimators.arguments import stream_arg

from harness.samplers.cubature import FLOAT32_FLOOR, rounding_floor

__all__ = ["DOMAINS", "Domain", "Float32DirectionPdf", "MomentColumns", "ParamDensity", "as_domain",
           "checked_breaks", "pdf_floor"]

DOMAINS = ("interval", "half_line", "square", "disk", "hemisphere", "sphere")

#: The sphere's pole: the point's components (x', y', z') in the frame whose z' is the pole,
#: a cyclic permutation of (x, y, z) (a rotation, exact in floating point).  Pole "y" puts
#: theta = acos(y) and phi = atan2(x, z): a y-up lat-long map's rows (Mitsuba's envmap) are
#: then cuts of the first parameter, its columns of the second (:meth:`Domain.breaks`).
_POLES = {"z": [0, 1, 2], "y": [2, 0, 1], "x": [1, 2, 0]}


@dataclass(frozen=True)
class Domain:
    """A sampling domain and its equal-measure parameterisation s in [0, 1]^k."""

    kind: str
    lo: float = 0.0
    hi: float = 1.0
    pole: str = "z"     # the sphere's: the axis theta is measured from (below)

    def __post_init__(self):
        if not isinstance(self.kind, str) or self.kind not in DOMAINS:
            raise ValueError(f"'domain' must be one of {DOMAINS}, got {self.kind!r}")
        if not isinstance(self.pole, str) or self.pole not in _POLES:
            raise ValueError(f"'pole' must be one of {tuple(_POLES)}, got {self.pole!r}")
        if self.pole != "z" and self.kind != "sphere":
            raise ValueError(f"'pole' {self.pole!r} is for the sphere only; the {self.kind} has none "
                             "to choose")
        if self.kind != "interval" and (self.lo, self.hi) != (0.0, 1.0):
            raise ValueError(f"ends are for the interval only; the {self.kind} has none to choose")
        try:
            ends = [float(v) for v in (self.lo, self.hi)
                    if isinstance(v, numbers.Real) and not isinstance(v, bool)]
        except OverflowError:     # an integer past the doubles
            ends = []
        # an infinite end, or a length past the doubles, made every cell and map NaN
        if not (len(ends) == 2 and ends[0] < ends[1] and math.isfinite(ends[1] - ends[0])):
            raise ValueError(f"an interval's ends must be finite numbers a < b, b - a a double (the half "
                             f"line is 'half_line'), got ({self.lo!r}, {self.hi!r})")
        object.__setattr__(self, "lo", ends[0])
        object.__setattr__(self, "hi", ends[1])

    @property
    def k(self) -> int:
        """Dimension of the parameter space: 1 on the interval and half line, else 2."""
        return 1 if self.kind in ("interval", "half_line") else 2

    @property
    def udim(self) -> int:
        """Number of canonical uniforms a sampler of this domain takes by default."""
        return self.k

    @property
    def point_dim(self) -> int:
        """Components of a point: 1 (interval, half line), 2 (square, disk), 3 (unit vectors)."""
        return {"interval": 1, "half_line": 1, "square": 2, "disk": 2, "hemisphere": 3,
                "sphere": 3}[self.kind]

    def jacobian(self, s: np.ndarray) -> np.ndarray | float:
        """Measure of the domain per unit of parameter space at s (|D| where constant)."""
        if self.kind == "half_line":
            return 1.0 / (1.0 - s[:, 0]) ** 2
        return self._measure()

    def jacobian_at_points(self, x: np.ndarray | None) -> np.ndarray | float:
        """:meth:`jacobian` at the parameters of domain points x: (1 + x)^2 on the half line
        (1 / (1 - s)^2 with s = x / (1 + x)), else |D| (x not read: None will do)."""
        if self.kind == "half_line":
            return (1.0 + x) ** 2
        return self._measure()

    def _measure(self) -> float:
        """|D| of a domain with a constant Jacobian."""
        return {"interval": self.hi - self.lo, "square": 1.0, "disk": math.pi, "hemisphere": 2 * math.pi,
                "sphere": 4 * math.pi}[self.kind]

    def breaks(self, *coordinates: Any) -> tuple[np.ndarray | None, ...]:
        """The parameter-space breaks (:func:`checked_breaks`) of a density that may step or
        kink where its natural coordinates take the given values, one sequence (or None) per
        coordinate: x on an interval or the half line; x, y on the square; r, phi on the disk;
        theta, phi on the hemisphere and sphere (radians, theta from the pole, phi from +x
        toward +y about +z; about another pole, from the next axis in cyclic order toward the
        one after: from +z toward +x about +y).  A lat-long map's texel edges, say, are
        ``Domain("sphere").breaks(pi * arange(1, H) / H, 2 * pi * arange(W) / W)``."""
        if len(coordinates) != self.k:
            raise ValueError(f"the {self.kind} has {self.k} coordinate(s), got {len(coordinates)} sequences")
        maps = {"interval": [lambda x: (x - self.lo) / (self.hi - self.lo)],
                "half_line": [lambda x: x / (1 + x)],
                "square": [lambda x: x, lambda y: y],
                "disk": [lambda r: r * r, _azimuth],
                "hemisphere": [np.cos, _azimuth],
                "sphere": [lambda t: (1 - np.cos(t)) / 2, _azimuth]}[self.kind]
        return tuple(None if c is None else f(np.asarray(c, dtype=float)) for f, c in zip(maps, coordinates))

    def to_points(self, s: np.ndarray) -> np.ndarray:
        """Points x(s) of parameters s (N, k): (N,) or (N, point_dim).  One pass in the core
        (:func:`reference_estimators.domain_points`)."""
        return self.from_pole_frame(rest.domain_points(self.kind, s, self.lo, self.hi))

    def to_params(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(s of shape (N, k), mask of points inside the domain).  Unit vectors may be off
        by 1e-5 in squared norm (float32 renderers).  One pass in the core
        (:func:`reference_estimators.domain_params`)."""
        if self.pole != "z":
            x = np.asarray(x)[:, _POLES[self.pole]]
        return rest.domain_params(self.kind, x, self.lo, self.hi)

    def dithered_params(self, x: np.ndarray, u: np.ndarray | None = None, *,
                        stream: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(:meth:`to_params`' s of the points x each coordinate moved within its float32
        rounding interval by the uniforms u (x's shape;
        :func:`reference_estimators.dither_float32`), its mask of x as given): one pass in the
        core (:func:`reference_estimators.dithered_domain_params`), the same bits as the two
        calls.  ``stream`` = (seed, case_id) in place of u: the uniforms
        ``reference_estimators.points(N, coordinates, seed=seed, case_id=case_id)``, drawn
        inside the core's pass (about another pole, drawn here first: they move with the
        columns)."""
        if self.pole != "z":
            if u is None and stream is not None:   # drawn here: they move with the columns
                seed, case_id = stream_arg(stream)
                u = rest.points(len(x), 3, seed=seed, case_id=case_id) if len(x) else np.empty((0, 3))
                stream = None
            x = np.asarray(x)[:, _POLES[self.pole]]
            u = None if u is None else np.asarray(u)[:, _POLES[self.pole]]
        return rest.dithered_domain_params(self.kind, x, u, self.lo, self.hi, stream=stream)

    @property
    def pole_columns(self) -> list[int] | None:
        """The columns that take points given in the frame whose z is the pole to the domain's
        own frame (None for the z pole: the identity)."""
        return None if self.pole == "z" else np.argsort(_POLES[self.pole]).tolist()

    def from_pole_frame(self, x: np.ndarray) -> np.ndarray:
        """Points (N, 3) given in the frame whose z is the pole, in the domain's own frame."""
        columns = self.pole_columns
        return x if columns is None else x[:, columns]


#: Directions whose length is 1 within this are rounded to float32 as given for
#: :attr:`Float32DirectionPdf.float32_columns` (others are normalised first; the cubature's
#: nodes are unit vectors to about 1e-16, so none is).
FLOAT32_UNIT_SLACK = 1e-6


@dataclass(frozen=True)
class Float32DirectionPdf:
    """A pdf on the hemisphere or sphere that a float32 renderer evaluates: called as any pdf
    on float64 directions x (N, 3), and as ``float32_columns(c)`` on float32 unit directions
    given as columns c (3, N) (rows x, y, z, each C-contiguous), returning (N,) densities,
    float32 or float64, one per column in its order (the cubature's own order of its nodes:
    :func:`reference_estimators.cubature_float32_directions`).  The contract:
    ``float32_columns(c) == pdf(x)`` wherever c is x's coordinates rounded to float32 (x of
    length 1 within :data:`FLOAT32_UNIT_SLACK`), which a float32 renderer's pdf meets by
    rounding the directions it is given (Mitsuba's adapter: ``harness.adapters.mitsuba.batch``).
    The check's cubature then maps its nodes straight to float32 columns
    (:func:`reference_estimators.cubature_float32_directions`) and sums float32 densities as
    returned: the same integrals, bit for bit, without an (N, 3) array of float64 directions
    written, read back and rounded, or a float64 copy of the densities, for each of the 1-100
    million nodes of a check's CDF tables and base grid.

    ``directions``: where the pdf's domain points are not the renderer's directions (an area
    light seen through its cap's equal-area map, ``harness.adapters.mitsuba.cap.CapView``),
    ``directions(lo, hi, nodes)`` gives the float32 columns ``float32_columns`` takes for the
    tensor rule's nodes on parameter boxes [lo, hi] (M, 2), and a per-node ok (N,), in
    :func:`reference_estimators.cubature_float32_directions`' order, or None to decline the
    call (``pdf`` then gets the nodes' float64 points); None: the domain's own directions.

    The declaration also says the densities carry float32 rounding (a float32 renderer's,
    up to a constant factor: a planted fault's scale, an area light's float32 Jacobian), so
    the check's cubature stops at the float32 floor
    (:data:`harness.samplers.cubature.FLOAT32_FLOOR`) without judging values: a lobe narrower
    than the pre-grid's cells is zero at every centre a plain pdf is judged at.  A pdf
    computed in float64 on the rounded directions is better passed plain (its floor then 0:
    the float32 floor would stop its cubature short, the error charged, the power lost)."""

    pdf: Callable[[np.ndarray], Any]
    float32_columns: Callable[[np.ndarray], Any]
    directions: Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray] | None] | None \
        = None

    def __call__(self, x: np.ndarray) -> Any:
        return self.pdf(x)


def pdf_floor(pdf: Callable[[np.ndarray], Any], dom: Domain, shape: tuple[int, ...]) -> float:
    """The relative change of a box integral of ``pdf`` on ``dom`` below which the check's
    cubature stops refining (:func:`harness.samplers.cubature.rounding_floor`): the float32
    floor for a declared :class:`Float32DirectionPdf`, without a call; for any other pdf,
    judged from its values at the centres of the regular grid ``shape`` on the parameter
    space.  Those centres cannot tell a lobe that misses them all: the Beckmann alpha = 0.01
    lobes at the pole, zero at every centre of a 32 x 64 grid, had their boxes refined to the
    depth limit chasing float32 noise (73 million pdf calls for the marginal's table at
    theta_i = 0, 1.3 million with the declared floor)."""
    if isinstance(pdf, Float32DirectionPdf):
        return FLOAT32_FLOOR
    centres = (np.stack(np.meshgrid(*[np.arange(m) for m in shape], indexing="ij"), axis=-1)
               .reshape(-1, dom.k) + 0.5) / np.array(shape)
    return rounding_floor(pdf(dom.to_points(centres)))


@dataclass(frozen=True)
class MomentColumns:
    """The columns (q, h q, h^2 q) of a density's values q, h = q / (q + c) bounded in [0, 1)
    (h = 0 when c <= 0): what the sampler check's pdf moment test integrates.  A
    :class:`ParamDensity` with these columns has the core integrate them from q's values
    (:func:`reference_estimators.cubature_moment_sums`, the same bits as this call's array)."""

    c: float

    def __call__(self, q: np.ndarray) -> np.ndarray:
        h = q / (q + self.c) if self.c > 0 else np.zeros_like(q)
        return np.column_stack([q, h * q, h * h * q])


@dataclass(frozen=True)
class ParamDensity:
    """A claimed density in its domain's parameter space, q(s) = pdf(x(s)) times the Jacobian
    (:meth:`Domain.jacobian`), or columns made of it (``columns``: q's values (N,) to (N, m),
    say q and q^2): called on parameter points s (N, k) like any integrand of
    :mod:`harness.samplers.cubature`, and integrated over boxes by a tensor rule
    (:meth:`rule_integrals`) without the nodes' parameter array."""

    dom: Domain
    pdf: Callable[[np.ndarray], np.ndarray]
    columns: Callable[[np.ndarray], np.ndarray] | None = None
    pdf_batch: int | None = None    # points a call of pdf in the cubature's rule (None: its default)

    def values(self, x: np.ndarray) -> np.ndarray:
        """q (or its columns) at domain points x."""
        return self._columns_of(np.asarray(self.pdf(x), dtype=float) * self.dom.jacobian_at_points(x))

    def _columns_of(self, q: np.ndarray) -> np.ndarray:
        return q if self.columns is None else self.columns(q)

    def __call__(self, s: np.ndarray) -> np.ndarray:
        return self.values(self.dom.to_points(s))

    def rule_integrals(self, lo: np.ndarray, hi: np.ndarray, nodes: np.ndarray,
                       weights: np.ndarray) -> np.ndarray:
        """(M, m) integrals of q over the parameter boxes [lo, hi] (M, k) by the tensor rule
        with points ``nodes`` per axis and ``weights`` (g^k,)
        (:func:`reference_estimators.cubature_sums`): the core maps the nodes to domain points
        directly (:func:`reference_estimators.cubature_points`; to float32 columns for a
        :class:`Float32DirectionPdf`), and a constant Jacobian multiplies each box's sum rather
        than every value (the same integrals to rounding)."""
        dom = self.dom
        # (q alone or its moment columns, which the core makes from any order; other columns
        # are made in numpy from box-major values)
        if isinstance(self.pdf, Float32DirectionPdf) and dom.point_dim == 3 and (
                self.columns is None or isinstance(self.columns, MomentColumns)):
            directions = self.pdf.directions
            columns, ok = (rest.cubature_float32_directions(dom.kind, lo, hi, nodes, dom.pole_columns,
                                                            FLOAT32_UNIT_SLACK)
                           if directions is None else directions(lo, hi, nodes) or (None, None))
            if ok is not None and ok.all():   # unit vectors all (nodes' are; else the float64 path says why)
                values = self.pdf.float32_columns(columns)   # in the columns' interleaved order
                jacobian = dom.jacobian_at_points(None)
                return self._integrals(lo, hi, values, jacobian, weights, interleaved=True)
        x = rest.cubature_points(dom.kind, lo, hi, nodes, (dom.lo, dom.hi), dom.pole_columns)
        return self._integrals(lo, hi, self.pdf(x), dom.jacobian_at_points(x), weights)

    def _integrals(self, lo: np.ndarray, hi: np.ndarray, pdf: np.ndarray, jacobian: np.ndarray | float,
                   weights: np.ndarray, interleaved: bool = False) -> np.ndarray:
        """rule_integrals from the pdf's values at the nodes (float32 ones summed as given) and
        the Jacobian there; ``interleaved``: the values in
        :func:`reference_estimators.cubature_float32_directions`' order (q or its moment
        columns, a constant Jacobian)."""
        moments = isinstance(self.columns, MomentColumns)
        if np.ndim(jacobian) == 0 and (self.columns is None or moments):   # the core's constant factor
            if moments:
                return rest.cubature_moment_sums(lo, hi, pdf, weights, self.columns.c, jacobian,
                                                 interleaved=interleaved)
            return rest.cubature_sums(lo, hi, pdf, weights, jacobian, interleaved=interleaved)
        q = np.asarray(pdf, dtype=float) * jacobian
        if moments:
            return rest.cubature_moment_sums(lo, hi, q, weights, self.columns.c)
        return rest.cubature_sums(lo, hi, self._columns_of(q), weights)


def _azimuth(phi: np.ndarray) -> np.ndarray:
    """The parameter coordinate phi / 2 pi of azimuths phi (radians), wrapped into [0, 1)."""
    return np.mod(phi / (2 * math.pi), 1.0)


def checked_breaks(breaks: Sequence[Any] | None, dom: Domain) -> tuple[np.ndarray | None, ...] | None:
    """``breaks`` as the cubature takes them: per parameter axis of ``dom``, the sorted distinct
    coordinates in (0, 1) where a claimed density may step or kink (0 and 1 dropped: every
    box's ends), or None for an axis without.  Raises ValueError, naming 'breaks', for the
    wrong number of axes or coordinates that are not finite numbers in [0, 1]."""
    if breaks is None:
        return None
    if isinstance(breaks, np.ndarray) and breaks.ndim == 2:    # one row per axis
        breaks = list(breaks)
    if isinstance(breaks, (str, bytes)) or not isinstance(breaks, Sequence) or len(breaks) != dom.k:
        raise ValueError(f"'breaks' must be a sequence of {dom.k} coordinate sequence(s) (or None) for the "
                         f"{dom.kind}'s parameter axes, got {breaks!r:.200}")
    out = []
    for axis, b in enumerate(breaks):
        if b is None:
            out.append(None)
            continue
        try:
            v = np.asarray(b, dtype=float)
        except (TypeError, ValueError, OverflowError):
            raise ValueError(f"'breaks'[{axis}] must be numbers in [0, 1], got {b!r:.200}") from None
        if v.ndim != 1:     # a scalar here is a flat list of coordinates given for a 2-D domain
            raise ValueError(f"'breaks'[{axis}] must be a sequence of coordinates (or None), got {b!r:.200}")
        bad = ~(np.isfinite(v) & (v >= 0) & (v <= 1))
        if bad.any():
            raise ValueError(f"'breaks'[{axis}]: {int(bad.sum())} of {v.size} coordinates are not finite "
                             f"numbers in [0, 1] (the parameter space), e.g. {v[bad][:3].tolist()}")
        v = np.unique(v)
        out.append(v[(v > 0) & (v < 1)])
    return tuple(out)


def as_domain(d: str | tuple | Domain) -> Domain:
    """The :class:`Domain` a check's ``domain`` argument names: a Domain (returned as is), one
    of :data:`DOMAINS` ("interval" is [0, 1]), or ("interval", a, b) with a < b.  Raises
    ValueError naming the argument and the allowed values."""
    if isinstance(d, Domain):
        return d
    if isinstance(d, tuple):
        if len(d) == 3 and d[0] == "interval":
            try:
                return Domain("interval", d[1], d[2])
            except ValueError:
                pass
        raise ValueError(f"'domain' must be one of {DOMAINS} or ('interval', a, b) with finite a < b, "
                         f"got {d!r}")
    if d not in DOMAINS:
        raise ValueError(f"'domain' must be one of {DOMAINS} or ('interval', a, b), got {d!r}")
    return Domain(d)
