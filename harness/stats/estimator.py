"""What an estimate is computed from: a catalogue integrand x technique of the C++ core
(:class:`CatalogueEstimator`), or a team's own estimator, a callable mapping canonical
uniforms of shape (N, dim) in (0, 1) to contributions of shape (N,) (:class:`Contributions`).

Both draw their uniforms from the same chunked PCG32 streams: chunk c of replica r of case k
comes from stream (seed, k, r, c), so an estimate does not depend on how its chunks are
grouped or on the thread count.  Both give accumulator states of chunk ranges that merge, in
chunk order, into the estimate: the suite runner stores, resumes and reproduces a user's
estimator exactly as it does the catalogue's (for the same code: a user's callable must be a
pure function of its uniforms).
"""
from __future__ import annotations

import math
import numbers
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

import reference_estimators as rest

from harness.stats.validate import count
from harness.usercode import array_result, call, callable_name

__all__ = ["Estimator", "CatalogueEstimator", "Contributions", "estimator"]

POINT_SETS = ("random", "stratified", "sobol")


class Estimator(Protocol):
    """What the statistics need of an estimator, wherever it comes from."""

    integrand: str                 # what is estimated (catalogue name, or the callable's module:attr)
    technique: str                 # how (technique name, or the user's label)
    reference: float               # the exact value; NaN where unknown
    iid: bool                      # independent contributions (random points)
    biased: bool                   # biased on purpose (its bias test must reject)
    finite_variance: bool | None   # known analytically; None: unknown
    evaluations: int               # integrand evaluations per contribution (1 for callables)

    def state(self, n: int, chunk_begin: int, chunk_end: int, *, seed: int, case_id: int,
              replica: int, tail_keep: int = 0, tail_median: bool = False) -> dict[str, Any]:
        """The accumulator state of chunks [chunk_begin, chunk_end) of an estimate of n samples;
        with ``tail_keep`` > 0 also the tails of its finite contributions under "tails"
        (rest.value_tails; ``tail_median``: with the upper median of the first chunk's)."""
        ...

    def values(self, n: int, *, seed: int, case_id: int, replica: int) -> np.ndarray:
        """The n contributions of that estimate (faulty ones NaN)."""
        ...

    def from_states(self, states: list[dict[str, Any]]) -> rest.Estimate:
        """The estimate from states of its chunk ranges, in chunk order."""
        ...

    def estimate(self, n: int, *, seed: int = 0, case_id: int = 0, replica: int = 0,
                 threads: int | None = None) -> rest.Estimate:
        ...


@dataclass(frozen=True)
class CatalogueEstimator:
    """An integrand x technique of the C++ core (``reference_estimators``)."""

    f: rest.Integrand
    t: rest.Technique

    integrand = property(lambda self: self.f.name)
    technique = property(lambda self: self.t.name)
    reference = property(lambda self: self.f.reference)
    iid = property(lambda self: self.t.iid)
    biased = property(lambda self: self.t.biased)
    finite_variance = property(lambda self: self.t.finite_variance)
    evaluations = property(lambda self: self.t.evaluations)

    def state(self, n: int, chunk_begin: int, chunk_end: int, *, seed: int, case_id: int,
              replica: int, tail_keep: int = 0, tail_median: bool = False) -> dict[str, Any]:
        return rest.integrate_chunks(self.f, self.t, n, chunk_begin, chunk_end, seed=seed, case_id=case_id,
                                     replica=replica, threads=1, tail_keep=tail_keep, tail_median=tail_median)

    def values(self, n: int, *, seed: int, case_id: int, replica: int) -> np.ndarray:
        return rest.contributions(self.f, self.t, n, seed=seed, case_id=case_id, replica=replica, threads=1)

    def from_states(self, states: list[dict[str, Any]]) -> rest.Estimate:
        return rest.estimate_from_states(self.f, self.t, states)

    def estimate(self, n: int, *, seed: int = 0, case_id: int = 0, replica: int = 0,
                 threads: int | None = None) -> rest.Estimate:
        return rest.integrate(self.f, self.t, n, seed=seed, case_id=case_id, replica=replica, threads=threads)


@dataclass(frozen=True)
class Contributions:
    """A user's estimator: ``function(u)`` maps canonical uniforms u of shape (N, dim) in
    (0, 1) (float64) to N contributions Y whose mean estimates ``reference``.

    It is called once per chunk (``rest.CHUNK_SIZE`` rows, the last chunk partial) with that
    chunk's points: ``points`` "random" (i.i.d.), "stratified" (jittered) or "sobol"
    (Owen-scrambled); for the last two the contributions are not independent and the error
    comes from replicas.  An exception inside it, or a result of the wrong shape, is a
    :class:`~harness.usercode.UserCodeError` naming ``name``, the input's shape and dtype and
    the expected output.  NaN and infinite contributions are counted and reported with the
    uniforms that gave them, never averaged.  ``label`` is what tables show (default: the
    callable's name).  The run time of an estimate is the wall time of the calls plus the
    accumulation, on one thread.
    """

    function: Callable[[np.ndarray], Any]
    dim: int
    reference: float = math.nan
    label: str = ""
    points: str = "random"
    name: str = ""

    biased = False
    finite_variance = None
    evaluations = 1

    def __post_init__(self) -> None:
        if not callable(self.function):
            raise TypeError(f"'function' must be callable, got {type(self.function).__name__}")
        if isinstance(self.dim, bool) or not isinstance(self.dim, numbers.Integral) or self.dim < 1:
            raise ValueError(f"'dim' must be a positive integer (uniforms per sample), got {self.dim!r}")
        object.__setattr__(self, "dim", int(self.dim))   # a numpy integer too (a shape's entry)
        if self.points not in POINT_SETS:
            raise ValueError(f"'points' must be one of {', '.join(POINT_SETS)}, got {self.points!r}")
        ref = self.reference
        if isinstance(ref, bool) or not isinstance(ref, numbers.Real) or math.isinf(ref):
            raise ValueError(f"'reference' must be a finite number (or NaN: unknown), got {ref!r}")
        object.__setattr__(self, "reference", float(ref))
        if not self.name:
            object.__setattr__(self, "name", callable_name(self.function))
        if not self.label:
            object.__setattr__(self, "label", self.name.rpartition(":")[2] or self.name)

    integrand = property(lambda self: self.name)
    technique = property(lambda self: self.label)
    iid = property(lambda self: self.points == "random")

    def __call__(self, u: np.ndarray) -> np.ndarray:
        """The contributions of uniforms u (N, dim), checked: float64 of shape (N,)."""
        rows = u.shape[0]
        y = call(self.function, self.name, u, what=f"contributions of shape ({rows},)")
        return array_result(y, (rows,), self.name, f"uniforms of shape {u.shape}, {u.dtype}")

    def _points(self, n: int, chunk: int, seed: int, case_id: int, replica: int) -> np.ndarray:
        return rest.points(n, self.dim, self.points, seed=seed, case_id=case_id, replica=replica, threads=1,
                           chunk_begin=chunk, chunk_end=chunk + 1)

    def state(self, n: int, chunk_begin: int, chunk_end: int, *, seed: int, case_id: int,
              replica: int, tail_keep: int = 0, tail_median: bool = False) -> dict[str, Any]:
        start = time.perf_counter()
        states, tails = [], []
        for c in range(chunk_begin, chunk_end):
            u = self._points(n, c, seed, case_id, replica)
            y = self(u)
            states.append(rest.accumulate_chunk(y, first=c * rest.CHUNK_SIZE, points=u))
            if tail_keep > 0:
                tails.append(rest.value_tails(y, tail_keep, median=tail_median and c == chunk_begin))
        merged = rest.merge_states(states)
        merged["seconds"] = time.perf_counter() - start
        if tails:
            merged["tails"] = rest.merge_tails(tails, tail_keep)
        return merged

    def values(self, n: int, *, seed: int, case_id: int, replica: int) -> np.ndarray:
        chunks = -(-n // rest.CHUNK_SIZE)
        return np.concatenate([self(self._points(n, c, seed, case_id, replica)) for c in range(chunks)])

    def from_states(self, states: list[dict[str, Any]]) -> rest.Estimate:
        return rest.estimate_of_states(states, reference=self.reference, iid=self.iid, integrand=self.name,
                                       technique=self.label)

    def estimate(self, n: int, *, seed: int = 0, case_id: int = 0, replica: int = 0,
                 threads: int | None = None) -> rest.Estimate:
        """An estimate of n contributions (``threads`` is ignored: a callable runs on one)."""
        n = count(n, "n")
        chunks = -(-n // rest.CHUNK_SIZE)
        return self.from_states([self.state(n, 0, chunks, seed=seed, case_id=case_id, replica=replica)])


def estimator(integrand: Any, technique: Any = None, *, dim: int | None = None,
              reference: float | None = None) -> Estimator:
    """The estimator an API call names: a catalogue integrand (name or object) with a
    technique, a contributions callable with ``dim`` (and ``reference``), or an Estimator."""
    if isinstance(integrand, (CatalogueEstimator, Contributions)):
        if technique is not None or dim is not None or reference is not None:
            raise TypeError(f"{type(integrand).__name__} takes no technique, dim or reference: it has them")
        return integrand
    if callable(integrand) and not isinstance(integrand, (str, rest.Integrand)):
        if technique is not None:
            raise TypeError("a contributions callable takes no technique; give dim= (and reference=)")
        if dim is None:
            raise TypeError(f"{callable_name(integrand)}: a contributions callable needs dim=, the canonical "
                            "uniforms per sample")
        return Contributions(integrand, dim, math.nan if reference is None else reference)
    if dim is not None or reference is not None:
        raise TypeError("dim and reference apply to contributions callables; a catalogue integrand has them")
    if technique is None:
        raise TypeError("a catalogue integrand needs a technique (see reference_estimators.techniques)")
    f = rest.integrand(integrand)
    return CatalogueEstimator(f, rest.technique(f, technique))
