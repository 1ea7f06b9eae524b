"""Python face of the C++ core: catalogue look-ups, samplers and estimators over numpy arrays,
and estimates computed in pieces (accumulator states of chunk ranges, merged in chunk order).

Every call validates its arguments here (through arguments.py) and names the argument and
the rule when one is wrong; the heavy work runs in C++ with the GIL released.
"""
from __future__ import annotations

import atexit
import math
import numbers
from typing import Any

import numpy as np

from . import _core
from .arguments import chunk_range, count_arg, points_arg, seed_arg, threads_arg
from .estimate import Estimate

__all__ = [
    "Integrand", "Sampler", "Technique",
    "catalogue", "integrand", "techniques", "technique",
    "samplers", "sampler", "rejection_sampler", "tabulated_integrand",
    "uniform", "importance", "rejection", "roulette", "splitting", "mis", "snis", "with_points", "clamped",
    "points",
    "integrate", "integrate_chunks", "estimate_from_states", "estimate_of_states", "merge_states",
    "contributions", "accumulate", "accumulate_chunk",
    "estimate_from_samples", "hardware_threads", "side_extremes", "value_tails", "merge_tails", "build_info",
    "profile_stages",
]

Integrand = _core.Integrand
Technique = _core.Technique
_CATALOGUE: dict[str, tuple[Any, dict[str, Any]]] = {
    f.name: (f, {t.name: t for t in ts}) for f, ts in _core.catalogue()
}
# emptied at exit, before the interpreter tears down its modules: the core's objects held here
# could otherwise outlive the core's own teardown, which nanobind reports as leaked instances
atexit.register(_CATALOGUE.clear)


class Sampler:
    """A sampling triple over numpy arrays: ``sample(u)``, ``pdf(x)``, ``invert(x)``, plus
    ``draw(n, seed=...)`` which works for rejection samplers too.

    Points have shape (N, dim) (or (N,) in 1D); pdfs are densities with respect to the
    domain's measure (length, area, or solid angle on the sphere) and 0 outside the support.
    """

    def __init__(self, core: Any):
        self._core = core

    name = property(lambda self: self._core.name)
    params = property(lambda self: dict(self._core.params))
    domain = property(lambda self: self._core.domain)
    dim = property(lambda self: self._core.dim)
    udim = property(lambda self: self._core.udim, doc="canonical uniforms per point")
    method = property(lambda self: self._core.method)
    invertible = property(lambda self: self._core.invertible)
    polar = property(lambda self: self._core.polar,
                     doc="whether the pdf reads a direction's cos(theta) alone (estimates draw no azimuth)")
    polar_function = property(lambda self: self._core.polar_function,
                              doc="the function of cos(theta) the pdf is, by name ('' for none); an "
                                  "integrand with the same polar_function is this pdf, bit for bit, and "
                                  "estimates compute it once")
    kernel = property(lambda self: self._core.kernel,
                      doc="the path sample() takes for whole vectors of points: 'small table in vector "
                          "lanes' (a 2-D table that fits small_table2d.h, AVX-512 builds) or 'batch loop'")

    def sample(self, u: Any) -> tuple[np.ndarray, np.ndarray]:
        """Points and their pdf values from canonical uniforms u in [0, 1] of shape (N, udim)
        (ValueError, with the count and examples, for values outside it or NaN)."""
        return self._core.sample(points_arg(u, self.udim, "u"))

    def pdf(self, x: Any) -> np.ndarray:
        """Claimed density at points x of shape (N, dim); 0 outside the support."""
        return self._core.pdf(points_arg(x, self.dim, "x"))

    def invert(self, x: Any) -> np.ndarray:
        """Canonical uniforms that map to x; NaN rows for points outside the support."""
        return self._core.invert(points_arg(x, self.dim, "x"))

    def draw(self, n: int, *, seed: int = 0,
             threads: int | None = None) -> tuple[np.ndarray, np.ndarray, dict]:
        """n points, their pdf values and diagnostics (candidates, bound violations with
        examples), from the chunked PCG32 streams: identical for any thread count."""
        x, p, diag = self._core.draw(count_arg(n, "n"), seed_arg(seed), 0, 0, threads_arg(threads))
        return x, p, diag

    def __repr__(self) -> str:
        return f"Sampler({self._core.describe()}, {self.method}, domain={self.domain})"


def catalogue() -> list[Integrand]:
    """The catalogue's integrands, each with name, domain, dim and exact reference."""
    return [f for f, _ in _CATALOGUE.values()]


def integrand(name: str | Integrand) -> Integrand:
    """The catalogue integrand called ``name``."""
    if isinstance(name, Integrand):
        return name
    if name not in _CATALOGUE:
        raise ValueError(f"unknown integrand {name!r}; the catalogue has: {', '.join(_CATALOGUE)}")
    return _CATALOGUE[name][0]


def techniques(f: str | Integrand) -> dict[str, Technique]:
    """The techniques the catalogue pairs with integrand ``f``, by name."""
    f = integrand(f)
    return dict(_CATALOGUE[f.name][1]) if f.name in _CATALOGUE else {"uniform": uniform(f)}


def technique(f: str | Integrand, t: str | Technique) -> Technique:
    """Technique ``t`` for integrand ``f``: a catalogue name, or a Technique as given."""
    if isinstance(t, Technique):
        return t
    known = techniques(f)
    if t not in known:
        raise ValueError(f"unknown technique {t!r} for integrand {integrand(f).name!r}; "
                         f"its techniques: {', '.join(known)}")
    return known[t]


def samplers() -> list[dict[str, Any]]:
    """The sampler registry: name, method, domain, parameters with defaults, description."""
    return _core.sampler_registry()


def sampler(name: str, *, table: Any = None, **params: float) -> Sampler:
    """A catalogue sampler by name, e.g. ``sampler("ggx", alpha=0.01)``.

    Piecewise-constant samplers take ``table``: 1D values, or a (rows, cols) array for
    ``piecewise_constant_2d`` (rows along y).
    """
    for key, value in params.items():
        if not isinstance(value, numbers.Real) or isinstance(value, bool):
            raise TypeError(f"sampler {name!r}: parameter {key!r} must be a number, got {value!r}")
    tab = None if table is None else np.ascontiguousarray(table, dtype=np.float64)
    return Sampler(_core.make_sampler(name, {k: float(v) for k, v in params.items()}, tab))


def rejection_sampler(target: str | Integrand, proposal: Sampler, c: float) -> Sampler:
    """The rejection method: density target / reference, from proposal with bound c.

    Every candidate with target(x) > c * proposal.pdf(x) is counted as a bound violation
    and reported with examples by ``draw``; it is never silently accepted.
    """
    return Sampler(_core.make_rejection_sampler(integrand(target), _core_sampler(proposal), float(c)))


def tabulated_integrand(values: Any, a: float = 0.0, b: float = 1.0) -> Integrand:
    """Piecewise-constant integrand on [a, b] from values (exact reference: their mean * (b-a))."""
    v = np.ascontiguousarray(values, dtype=np.float64)
    if v.ndim != 1:
        raise ValueError(f"'values' must be one-dimensional, got shape {v.shape}")
    return _core.tabulated_integrand(v, float(a), float(b))


def uniform(f: str | Integrand) -> Technique:
    """Uniform Monte Carlo on f's domain (background eq. 3)."""
    return _core.uniform_technique(integrand(f))


def importance(s: Sampler) -> Technique:
    """Importance sampling f(X)/p(X) with X drawn from sampler s (background eq. 4)."""
    return _core.importance_technique(_core_sampler(s))


def rejection(proposal: Sampler, c: float) -> Technique:
    """The rejection method as an estimator: Y = c 1{xi c p(X) < f(X)}, E[Y] = integral of f
    when f <= c p holds; violations are counted and reported."""
    return _core.hit_or_miss_technique(_core_sampler(proposal), float(c))


def roulette(s: Sampler, q: float, c: float = 0.0, *, reweight: bool = True) -> Technique:
    """Russian roulette over importance sampling with s: f is evaluated only with survival
    probability q; survivors count (f/p - (1-q) c) / q, the terminated count c (background
    section 3.1; unbiased).  ``reweight=False`` is the biased twin: survivors count f/p."""
    return _core.russian_roulette_technique(_core_sampler(s), float(q), float(c), bool(reweight))


def splitting(f: str | Integrand, m: int) -> Technique:
    """Splitting on a 2-D box: one outer sample x0, m inner samples x1, Y = |D| mean f(x0, x1_j)."""
    return _core.splitting_technique(integrand(f), count_arg(m, "m"))


def mis(samplers: list[Sampler], heuristic: str = "balance") -> Technique:
    """Multiple importance sampling, one sample per sampler, with the balance (beta = 1) or
    power (beta = 2) heuristic (Veach 1997)."""
    powers = {"balance": 1.0, "power": 2.0}
    if heuristic not in powers:
        raise ValueError(f"'heuristic' must be 'balance' or 'power', got {heuristic!r}")
    return _core.mis_technique([_core_sampler(s) for s in samplers], powers[heuristic])


def snis(s: Sampler, batch: int) -> Technique:
    """Self-normalised importance sampling over batches of ``batch`` samples: the ratio
    |D| sum f/p / sum 1/p.  Consistent, with a bias of order 1/batch (deliberately biased)."""
    return _core.self_normalized_technique(_core_sampler(s), count_arg(batch, "batch"))


def with_points(t: Technique, points: str) -> Technique:
    """Technique t drawing its canonical uniforms from 'random', 'stratified' (jittered) or
    'sobol' (Owen-scrambled) points."""
    return _core.with_points(t, points)


def clamped(t: Technique, clamp: float) -> Technique:
    """Technique t with contributions cut at ``clamp`` (deliberately biased low)."""
    return _core.with_clamp(t, float(clamp))


def points(n: int, dim: int, kind: str = "random", *, seed: int = 0, case_id: int = 0, replica: int = 0,
           threads: int | None = None, chunk_begin: int = 0, chunk_end: int | None = None) -> np.ndarray:
    """Canonical points in (0, 1): what a technique with this point set and ``dim`` uniforms
    per sample consumes for an estimate of n samples, shape (n, dim); with ``chunk_begin`` /
    ``chunk_end``, only the rows of chunks [chunk_begin, chunk_end) of that estimate
    (chunks of ``CHUNK_SIZE`` samples, the last one partial): the same bits as those rows of
    the whole set."""
    if isinstance(dim, bool) or not isinstance(dim, numbers.Integral) or dim < 1:
        raise ValueError(f"'dim' must be a positive integer, got {dim!r}")
    n = count_arg(n, "n")
    begin, end = chunk_range(n, chunk_begin, chunk_end)
    return _core.points(n, int(dim), kind, seed_arg(seed), seed_arg(case_id, "case_id"),
                        seed_arg(replica, "replica"), threads_arg(threads), begin, end)


def accumulate_chunk(values: Any, *, first: int = 0, points: Any = None) -> dict[str, Any]:
    """The accumulator state (as ``integrate_chunks`` returns) of one chunk of contributions
    computed elsewhere, e.g. by a user's estimator from :func:`points` of that chunk:
    ``first`` is the index of values[0] within the estimate, ``points`` (N, dim) the canonical
    points that gave the values, named (first 3 coordinates) in the examples of NaN, infinite
    or negative values.  States of consecutive chunks merge, in chunk order, with
    :func:`estimate_of_states`; ``seconds`` is 0 (the caller knows what it timed)."""
    y = np.ascontiguousarray(values, dtype=np.float64)
    if y.ndim != 1:
        raise ValueError(f"'values' must be one-dimensional, got shape {y.shape}")
    if y.size == 0:
        raise ValueError("'values' must not be empty")
    u = None
    if points is not None:
        u = np.ascontiguousarray(points, dtype=np.float64)
        if u.ndim == 1:
            u = u[:, None]
        if u.ndim != 2 or u.shape[0] != y.size:
            raise ValueError(f"'points' must have shape ({y.size}, dim), one row per value, got {u.shape}")
    return _core.accumulate_chunk(y, seed_arg(first, "first"), u)


def integrate(f: str | Integrand, t: str | Technique, n: int, *, seed: int = 0, threads: int | None = None,
              case_id: int = 0, replica: int = 0, higher_moments: bool = True) -> Estimate:
    """Estimate the integral of f with technique t from n contributions.

    For stratified or Sobol' point sets the contributions are not independent: the estimate
    then has ``stderr`` NaN, and its error must come from replicas (``harness.stats``).
    Samples come in chunks of ``CHUNK_SIZE`` with one PCG32 stream per chunk keyed by
    (seed, case_id, replica, chunk), merged in chunk order: the result is bitwise the same
    for any ``threads``.  ``higher_moments`` adds M3/M4 (skewness, kurtosis, the variance's
    own uncertainty) at about 3 % of the run time.
    """
    fi = integrand(f)
    ti = technique(fi, t)
    raw = _core.integrate(fi, ti, count_arg(n, "n"), seed_arg(seed), seed_arg(case_id, "case_id"),
                          seed_arg(replica, "replica"), threads_arg(threads), bool(higher_moments))
    return Estimate.from_core(raw, integrand=fi.name, technique=ti.name, reference=fi.reference,
                              nonnegative=fi.nonnegative, iid=ti.iid)


def integrate_chunks(f: str | Integrand, t: str | Technique, n: int, chunk_begin: int, chunk_end: int, *,
                     seed: int = 0, case_id: int = 0, replica: int = 0, threads: int | None = None,
                     tail_keep: int = 0, tail_median: bool = False) -> dict[str, Any]:
    """The accumulator state of chunks [chunk_begin, chunk_end) of the estimate ``integrate``
    makes from n samples with the same seed, case_id and replica (chunks of ``CHUNK_SIZE``
    samples, the last one partial).

    The state is a dict of plain numbers and lists (JSON-serialisable, to be stored as is):
    count, Welford moments M2..M4, compensated sum, min, max, issue counts with examples,
    drawn and candidate counts, wall time (s), chunks and threads.  ``estimate_from_states``
    merges the states of all chunk ranges, in chunk order, into the estimate.

    With ``tail_keep`` > 0 the state also holds, under "tails", what :func:`value_tails`
    returns for the finite contributions accumulated (``tail_median``: with the upper median
    of the range's first chunk), drawn in the same pass: the bias test's tail sample without a
    second pass over the contributions.
    """
    fi = integrand(f)
    ti = technique(fi, t)
    n = count_arg(n, "n")
    begin, end = chunk_range(n, chunk_begin, chunk_end)
    return _core.integrate_chunks(fi, ti, n, seed_arg(seed), seed_arg(case_id, "case_id"),
                                  seed_arg(replica, "replica"), begin, end, threads_arg(threads),
                                  count_arg(tail_keep, "tail_keep", zero=True), bool(tail_median))


def value_tails(values: Any, keep: int, *, median: bool = False) -> dict[str, Any]:
    """The tails of ``values`` (NaN and infinities ignored), JSON-serialisable: "upper" for the
    largest values and "lower" for the largest of -values, each {"peak": the largest (None if
    no value), "ties": how many equal it, "below": the ``keep`` largest strictly below it,
    descending}, and "median": the upper median (``median`` True; else None).  One pass in
    C++: candidates are screened against a rising threshold, so an atom (zeros, a clamp) is
    counted, not sorted.  :func:`merge_tails` merges the tails of several sets exactly."""
    y = np.ascontiguousarray(values, dtype=np.float64)
    if y.ndim != 1:
        raise ValueError(f"'values' must be one-dimensional, got shape {y.shape}")
    return _core.value_tails(y, count_arg(keep, "keep", zero=True), bool(median))


def merge_tails(parts: list[dict[str, Any]], keep: int) -> dict[str, Any]:
    """The tails (as :func:`value_tails` gives them) of the union of the parts' values, from the
    parts, merged in the order given; exact when each part kept at least ``keep`` per side.
    The median is the first part's."""
    parts = list(parts)
    if not parts:
        raise ValueError("'parts' must hold at least one tails dict (from value_tails or integrate_chunks)")
    return _core.merge_tails(parts, count_arg(keep, "keep", zero=True))


_STATE_KEYS = frozenset(("n", "mean", "m2", "m3", "m4", "sum", "comp", "min", "max", "scale_exp", "scale_set",
                         "counts", "examples", "drawn", "candidates", "seconds", "chunks", "threads"))


def estimate_from_states(f: str | Integrand, t: str | Technique, states: list[dict[str, Any]]) -> Estimate:
    """The estimate of f with technique t from the accumulator states of ``integrate_chunks``,
    merged (Chan et al.) in the order given; give them in chunk order, each chunk once.

    The same states always give the same bits.  With one chunk per state the result is
    bitwise what ``integrate`` computes in one call; with wider chunk ranges the moments may
    differ from it in the last bits (the merge is not associative), counts never do.
    ``seconds`` is the sum of the states' wall times.
    """
    fi = integrand(f)
    ti = technique(fi, t)
    return estimate_of_states(states, integrand=fi.name, technique=ti.name, reference=fi.reference,
                              nonnegative=fi.nonnegative, iid=ti.iid)


def merge_states(states: list[dict[str, Any]]) -> dict[str, Any]:
    """One accumulator state from several (of consecutive chunk ranges), merged in the order
    given: what ``integrate_chunks`` returns for the whole range."""
    return _core.merge_states(_checked_states(states))


def estimate_of_states(states: list[dict[str, Any]], *, reference: float | None = None, iid: bool = True,
                       integrand: str | None = None, technique: str | None = None,
                       nonnegative: bool = False) -> Estimate:
    """The estimate from accumulator states (``integrate_chunks``, ``accumulate_chunk``)
    merged in the order given, for estimators outside the catalogue: ``reference`` is the
    exact value if known, ``iid`` False for stratified or Sobol' points (``stderr`` is then
    NaN), ``nonnegative`` makes negative contributions an issue."""
    raw = _core.estimate_from_state(merge_states(states))
    return Estimate.from_core(raw, integrand=integrand, technique=technique, reference=reference,
                              nonnegative=nonnegative, iid=iid)


def contributions(f: str | Integrand, t: str | Technique, n: int, *, seed: int = 0,
                  threads: int | None = None, case_id: int = 0, replica: int = 0) -> np.ndarray:
    """The n per-sample contributions Y that ``integrate`` with the same arguments averages
    (samples it would exclude for a bad pdf or a point outside the domain are NaN)."""
    fi = integrand(f)
    n = count_arg(n, "n")
    return _core.contributions(fi, technique(fi, t), n, seed_arg(seed), seed_arg(case_id, "case_id"),
                               seed_arg(replica, "replica"), threads_arg(threads))


def accumulate(values: Any, *, threads: int | None = None) -> Estimate:
    """Mean, variance and diagnostics of given contributions, by the core's accumulators."""
    y = np.ascontiguousarray(values, dtype=np.float64)
    if y.ndim != 1:
        raise ValueError(f"'values' must be one-dimensional, got shape {y.shape}")
    if y.size == 0:
        raise ValueError("'values' must not be empty")
    return Estimate.from_core(_core.accumulate(y, threads_arg(threads)))


def build_info() -> dict[str, Any]:
    """How the core was built: ``isa`` its kernels were compiled for (there is no runtime
    dispatch: they run as built), ``vector_doubles`` per vector, ``rng_lanes`` of PCG32,
    ``march`` (-march), ``compiler``, ``chunk_size``; and ``cpu_isa``, the best this CPU runs."""
    return dict(_core.build_info())


def profile_stages(f: str | Integrand, t: str | Technique, n: int, *, seed: int = 0,
                   threads: int | None = None) -> dict[str, Any]:
    """Wall seconds of each prefix of ``integrate``'s pipeline on the same chunks and threads:
    ``points`` (the point set alone; 0 for rejection samplers, which draw inside the sampler);
    for techniques that draw points from samplers (importance, uniform on a sphere or
    hemisphere, MIS) ``sampled`` (the points also drawn, with their pdfs), ``screened`` (also
    checked for the sampler's domain and bad pdfs) and, for MIS, ``weighted`` (also every
    technique's pdf at every point), each None where the technique has no such stage;
    ``contributions`` (the integrand and the estimator's arithmetic too) and ``full`` (the
    whole estimate: the contributions' screening and accumulation too), with ``estimate``,
    the full run's Estimate (its ``busy`` seconds per thread).  Differences of consecutive
    prefixes give each stage's cost."""
    fi = integrand(f)
    d = _core.profile_stages(fi, technique(fi, t), count_arg(n, "n"), seed_arg(seed), threads_arg(threads))
    est = Estimate.from_core(d["estimate"])
    stages = {k: None if math.isnan(d[k]) else d[k] for k in ("sampled", "screened", "weighted")}
    return {"points": d["points"], **stages, "contributions": d["contributions"], "full": est.seconds,
            "estimate": est}


def side_extremes(values: Any, center: float, *, upper: bool, keep: int) -> tuple[float, int, np.ndarray]:
    """The largest positive deviations of ``values`` from ``center`` on one side: d = y - center
    (``upper``) or center - y, in float64 as numpy computes them, NaN values having none.
    Returns (peak, ties, below): the largest d (NaN if no d is positive), how many d equal it,
    and the ``keep`` largest d strictly below it, descending.  One pass in C++."""
    y = np.ascontiguousarray(values, dtype=np.float64)
    if y.ndim != 1:
        raise ValueError(f"'values' must be one-dimensional, got shape {y.shape}")
    peak, ties, below = _core.side_extremes(y, float(center), bool(upper), count_arg(keep, "keep"))
    return peak, ties, below


def estimate_from_samples(f: str | Integrand, points: Any, pdf: Any, *, sampler: Sampler | None = None,
                          threads: int | None = None) -> Estimate:
    """Importance-sampling estimate f(x)/pdf from points drawn elsewhere (e.g. a renderer's
    sampler).  Points outside ``sampler``'s domain (default: f's) and pdf values that are 0,
    negative, NaN or infinite are reported and excluded, never averaged."""
    fi = integrand(f)
    x = points_arg(points, fi.dim, "points")
    if len(x) == 0:
        raise ValueError("'points' must hold at least one sample, got none")
    p = np.ascontiguousarray(pdf, dtype=np.float64)
    raw = _core.estimate_from_samples(fi, x, p, None if sampler is None else _core_sampler(sampler),
                                      threads_arg(threads))
    return Estimate.from_core(raw, integrand=fi.name, technique="importance:given", reference=fi.reference,
                              nonnegative=fi.nonnegative)


def hardware_threads() -> int:
    """Threads a call with ``threads=None`` runs on: the machine's hardware threads (at least 1)."""
    return _core.hardware_threads()


# --- argument normalisation ------------------------------------------------------------------
def _core_sampler(s: Any) -> Any:
    if isinstance(s, Sampler):
        return s._core
    if isinstance(s, _core.Sampler):
        return s
    raise TypeError(f"expected a Sampler, got {type(s).__name__}")


def _checked_states(states: Any) -> list[dict[str, Any]]:
    states = list(states)
    if not states:
        raise ValueError("'states' must hold at least one accumulator state (from integrate_chunks)")
    for i, s in enumerate(states):
        if not isinstance(s, dict):
            raise TypeError(f"'states'[{i}] must be a dict from integrate_chunks, got {type(s).__name__}")
        missing = _STATE_KEYS - s.keys()
        if missing:
            raise ValueError(f"'states'[{i}] is not an accumulator state (from integrate_chunks): "
                             f"missing {', '.join(sorted(missing))}")
    return states
