"""A light's sampler seen through a fixed map of its directions onto the check's domain: the
part the cap's map (:mod:`harness.adapters.mitsuba.cap`) and the rectangle's
(:mod:`harness.adapters.mitsuba.rectangle`) share.

An area light covers a small region of the sphere of directions, and its rim cuts the
sphere's cells along curves; a fixed bijection of a region holding the light onto the check's
domain makes the light fill the domain's cells, and tests the same hypothesis.  The drawn
points' pdf is the world pdf at the very float32 directions the sampler returned (the map's
float64 round trip loses them, and at a light's rim one ulp decides whether the ray traced
back hits it); elsewhere (cubature nodes) at the map's direction of the point.
"""
from __future__ import annotations

from typing import Any

import numpy as np

import reference_estimators as rest

__all__ = ["MappedView"]

#: Rows up to which ``MappedView.pdf`` looks each one up among the last draw's points (a
#: user's query, an example); larger calls are the cubature's nodes or the draw itself.
FEW_ROWS = 4096


class MappedView:
    """``sampler`` (world directions, pdf per steradian) seen through ``mapping``: ``sample(u)``
    gives the map's points of the directions drawn (NaN rows kept), ``pdf(x)`` the density
    per unit measure of the map's domain (``domain``, points of ``point_dim`` coordinates,
    where it may step or kink: ``breaks``).  The mapping (a
    :class:`~harness.adapters.mitsuba.cap.Cap` or a
    :class:`~harness.adapters.mitsuba.rectangle.Rectangle`) gives ``domain``, ``point_dim``,
    ``breaks``, ``to_domain`` (world directions (N, 3) -> points), ``to_world`` (points ->
    world directions) and ``density`` (points and the world pdf there -> the density on the
    domain).  ``pdf`` at the points of the last draw (all its rows, or the rows it produced, in
    its order, as the check passes them; or any few of them) is the world pdf at the
    directions returned for them.

    Where the sampler has ``sample_with_pdf``, the draw keeps the pdf each sample call
    reported, and ``pdf`` on the draw keeps the world pdf there: ``reported_draw`` hands both
    to the reported-pdf check with the draw's directions, which a second draw of the same
    uniforms had cost an area light's check (its sample calls' time halved: 23-87 -> 10-31 ms
    a million ray-traced samples, check_time_split's sample column)."""

    def __init__(self, sampler: Any, mapping: Any):
        self.sampler, self.map, self.udim = sampler, mapping, sampler.udim
        self.domain, self.point_dim, self.breaks = mapping.domain, mapping.point_dim, mapping.breaks
        self._drawn = np.empty((0, self.point_dim))   # the last draw's points (NaN rows: not produced)
        self._world = np.empty((0, 3))                # and the world directions returned for them
        self._produced = np.zeros(0, dtype=bool)
        self._produced_count = 0
        self._lookup: Any = None            # the draw's rows, for a few-row lookup (RowLookup)
        self._reported: np.ndarray | None = None    # the draw's reported pdf (N,), if the sampler has one
        self._world_pdf: np.ndarray | None = None   # the world pdf at the draw's directions (N,), once asked

    def sample(self, u: np.ndarray) -> np.ndarray:
        with_pdf = getattr(self.sampler, "sample_with_pdf", None)
        if with_pdf is None:
            world, self._reported = self.sampler.sample(u), None
        else:
            world, reported = with_pdf(u)
            self._reported = np.asarray(reported, dtype=float).reshape(-1)
        world = np.asarray(world, dtype=float)
        self._world_pdf = None
        x = self.map.to_domain(world)
        x.flags.writeable = False   # the draw as pdf() recognises it (_same_memory): never changed in place
        self._drawn, self._world = x, world
        self._produced = rest.finite_rows(x)
        self._produced_count = int(self._produced.sum())
        self._lookup = rest.RowLookup(x)
        return x

    def _world_of_drawn(self, x: np.ndarray) -> np.ndarray | None:
        """The world directions returned for x if x is the last draw (whole, or its produced
        rows), else None."""
        if x.shape == self._drawn.shape and (_same_memory(x, self._drawn)
                                             or np.array_equal(x, self._drawn, equal_nan=True)):
            return self._world
        produced = self._produced_count   # counted once a draw: the cubature asks this of every call
        if x.shape[0] == produced and produced and np.array_equal(x, self._drawn[self._produced]):
            return self._world[self._produced]
        return None

    def pdf(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float).reshape(-1, self.point_dim)
        world = self._world_of_drawn(x)
        if world is not None:
            p = np.asarray(self.sampler.pdf(world), dtype=float).reshape(-1)
            if world.shape[0] == self._world.shape[0]:
                self._world_pdf = p
            else:   # the produced rows: the others' pdf is the sampler's at a NaN row, 0
                self._world_pdf = np.zeros(self._world.shape[0])
                self._world_pdf[self._produced] = p
            return self.map.density(x, p)
        world = self.map.to_world(x)
        if self._lookup is not None and x.shape[0] <= FEW_ROWS:   # a few rows: any drawn among them
            i = self._lookup.find(x)
            drawn = i >= 0
            world[drawn] = self._world[i[drawn]]
        return self.map.density(x, self.sampler.pdf(world))

    def reported_draw(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None] | None:
        """(the last draw's world directions (N, 3), NaN rows not produced; the pdf each
        sample call reported (N,); the world pdf at them (N,) where ``pdf`` was asked it on the
        draw, else None), or None where the sampler reports no pdf."""
        if self._reported is None:
            return None
        return self._world, self._reported, self._world_pdf


def _same_memory(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether a and b are the same values in the same memory (the check's points passed back
    as drawn, a view of the very array, which sample() made read-only): then equal without a
    comparison (a million directions compared took 0.06 s of an area light's check)."""
    return (a.dtype == b.dtype and a.strides == b.strides
            and a.__array_interface__["data"][0] == b.__array_interface__["data"][0])
