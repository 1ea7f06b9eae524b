"""The plan: the work units a suite's measurements need, and nothing else.

A unit is named by a :class:`Unit` (case fingerprint, stream, budget, replica, chunk range,
kind).  For estimator cases a unit is a contiguous range of at most ``UNIT_CHUNKS`` core chunks
of one estimate; a sampler check is one unit per measurement; a render is one unit per image.
Shared work is planned once: the bias test's batches also give the variance, the convergence
replicas also give the efficiency and the error against time.  No reference run is planned
where an exact value exists (the catalogue's values are exact, some scenes have exact images),
no renderer or sampler test unless a case asks for one.

The units of the replicas an estimator case's efficiency is measured from (its largest
convergence budget, :func:`efficiency_stream`) also time the reference clock beside them
(harness.stats.timing.CLOCK): their payloads carry its reading, and the clock's description is
part of the case key.

Fingerprints (``case_key``, ``sampler_key``, ``render_key``, ``reference_key``) hash what fixes
a case's numbers, the harness code that computes its units included (harness.fingerprint); a
unit's random stream depends on its case's settings, stream and replica, never on that code.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from typing import Any

import reference_estimators as rest

from harness.adapters.base import ENVIRONMENT
from harness.fingerprint import code_fingerprint
from harness.stats.tails import TailSample
from harness.stats.timing import CLOCK
from harness.suite.model import Case, RenderCase, SamplerCase, Suite

__all__ = ["UNIT_CHUNKS", "BIAS_STREAM", "Unit", "case_key", "sampler_key", "sampler_spec", "render_key",
           "reference_key", "render_stream", "reference_stream", "render_seed", "core_case_id", "bias_budget",
           "bias_stream", "convergence_budgets", "chosen_budgets", "efficiency_stream", "estimator_units",
           "sampler_units", "render_units", "reference_units", "plan", "unit_count", "render_unit_count",
           "MAX_UNITS", "MAX_TAIL_BATCH", "tail_keeps", "units_per_estimate"]

UNIT_CHUNKS = 32                     # core chunks (of 65 536 samples) per stored unit
MAX_UNITS = 1 << 20                  # units a suite may plan: each is held in memory, then a database row
MAX_TAIL_BATCH = 1 << 28             # contributions of the batch a tail unit holds in memory (2 GiB)
BIAS_STREAM = 0                      # stream 0: the bias test's batches; 1 + i: convergence budget i;
TARGET_STREAM = 200                  # 200 + s: the bias test's batches at look s >= 1 of a target
_FORMAT = 2                          # bump when a unit's meaning changes: old rows stop matching
#                                      (2: the bias test's state units carry their contributions' tails)
_SAMPLER_PAYLOAD = 2                 # sampler-check payloads: 2 adds residual grids and marginals (report)
_RENDER_FORMAT = 1                   # bump when a render unit's meaning changes
RENDER = "render"                    # the kind of a render unit
# the harness code (harness.fingerprint) that computes each kind's units: part of their keys
_ESTIMATOR_CODE = ("suite/estimators.py", "stats/estimator.py", "stats/tails.py", "usercode.py")
_SAMPLER_CODE = ("samplers", "adapters", "suite/sampler_checks.py", "usercode.py")
_RENDER_CODE = ("adapters", "suite/renders.py", "usercode.py")


@dataclass(frozen=True, order=True)
class Unit:
    """The key of one stored unit of work (one row of the store's ``units`` table)."""

    case_key: str
    stream: int
    budget: int       # contributions (samples, spp) in the estimate this unit is part of
    replica: int
    chunk_begin: int
    chunk_end: int
    kind: str         # "state", "tail", a sampler measurement, or "render"

    def row(self) -> tuple[str, int, int, int, int, int, str]:
        """The fields in order, as the store's columns take them (dataclasses.astuple deep-
        copies every field: a tenth of the runner's own time on a suite of 256 units)."""
        return (self.case_key, self.stream, self.budget, self.replica, self.chunk_begin, self.chunk_end,
                self.kind)


def _hash(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:24]


# --- fingerprints --------------------------------------------------------------------------------
def case_key(suite: Suite, case: Case) -> str:
    """Fingerprint of what fixes a case's random numbers and contributions: for a user's
    estimator its target, dimension, point set and the hash of its source (a change of the
    code invalidates its stored units)."""
    what = ({"estimator": case.estimator, "source": case.source, "dim": case.dim, "points": case.points}
            if case.estimator else {"integrand": case.integrand, "technique": case.technique})
    return _hash({**what, "seed": suite.seed, "case_id": case.case_id, "unit_chunks": UNIT_CHUNKS,
                  "format": _FORMAT, "core": rest.__version__, "build": rest.core_fingerprint(),
                  "code": code_fingerprint(*_ESTIMATOR_CODE), "clock": CLOCK})


def sampler_key(suite: Suite, sc: SamplerCase) -> str:
    """Fingerprint of a sampler check: the sampler, its parameters, domain, samples and seed."""
    definition = {"sampler": sc.name, "params": list(sc.params), "domain": sc.domain, "samples": sc.samples,
                  "seed": suite.seed, "case_id": sc.case_id, "format": _FORMAT, "payload": _SAMPLER_PAYLOAD,
                  "core": rest.__version__, "build": rest.core_fingerprint(),
                  "code": code_fingerprint(*_SAMPLER_CODE)}
    if sc.target:   # a user's sampler: a change of its source invalidates the check
        definition.update(target=sc.target, source=sc.source, total=sc.total, udim=sc.udim)
    if sc.adapter:  # a renderer's sampler: its library version is part of what is tested
        from harness.adapters.mitsuba.samplers import make_sampler

        fingerprint = make_sampler(json.loads(sc.spec)).fingerprint()
        definition.update(adapter=sc.adapter, spec=sc.spec, fingerprint=fingerprint)
    return _hash(definition)


def sampler_spec(suite: Suite, sc: SamplerCase) -> str:
    """What a worker needs to rebuild the sampler (JSON); a user's is loaded from the suite
    file's folder."""
    return json.dumps({"name": sc.name, "params": dict(sc.params), "domain": sc.domain, "samples": sc.samples,
                       "adapter": sc.adapter, "spec": json.loads(sc.spec) if sc.spec else None,
                       "target": sc.target, "base": str(suite.path.parent), "total": sc.total,
                       "udim": sc.udim})


def _settings(fingerprint: dict[str, Any]) -> dict[str, Any]:
    """A renderer fingerprint without its ``environment`` (harness.adapters.base.ENVIRONMENT)."""
    return {k: v for k, v in fingerprint.items() if k != ENVIRONMENT}


def render_stream(suite: Suite, fingerprint: dict[str, Any]) -> str:
    """What a render case's seeds derive from: the renderer's settings (its fingerprint but the
    environment, so the same suite draws the same seeds on every machine, build and library
    version) and the suite seed."""
    return _hash({"renderer": _settings(fingerprint), "seed": suite.seed, "format": _RENDER_FORMAT})


def render_key(suite: Suite, fingerprint: dict[str, Any]) -> str:
    """Fingerprint of a render case's images: its seeds' source (:func:`render_stream`), the
    renderer's environment and the harness's adapter code."""
    return _hash({"stream": render_stream(suite, fingerprint), "environment": fingerprint.get(ENVIRONMENT),
                  "code": code_fingerprint(*_RENDER_CODE)})


def reference_stream(suite: Suite, rc: RenderCase, fingerprint: dict[str, Any]) -> str:
    """What a rendered reference's seeds derive from: its renderer's settings, budget, parts and
    the suite seed."""
    return _hash({"reference": _settings(fingerprint), "spp": rc.reference_spp, "parts": rc.reference_parts,
                  "seed": suite.seed, "format": _RENDER_FORMAT})


def reference_key(suite: Suite, rc: RenderCase, fingerprint: dict[str, Any]) -> str:
    """Fingerprint of a rendered reference: its seeds' source, its renderer's environment and the
    harness's adapter code."""
    return _hash({"stream": reference_stream(suite, rc, fingerprint),
                  "environment": fingerprint.get(ENVIRONMENT), "code": code_fingerprint(*_RENDER_CODE)})


def render_seed(stream_key: str, unit: Unit) -> int:
    """A render's seed (31 bits): independent streams per case (``stream_key``: its
    :func:`render_stream` or :func:`reference_stream`), stream and replica."""
    return int(hashlib.sha256(f"{stream_key}/{unit.stream}/{unit.replica}".encode()).hexdigest()[:8],
               16) & 0x7FFFFFFF


def core_case_id(case: Case, stream: int) -> int:
    """The core's case_id field of an estimator stream: case position and purpose, disjoint for all."""
    return (case.case_id << 8) | stream


# --- budgets -----------------------------------------------------------------------------------
def bias_budget(suite: Suite, case: Case, look: int = 0) -> int:
    """Contributions per batch of the bias test (at look ``look`` of a precision target)."""
    return (case.samples << look) // suite.batches


def bias_stream(look: int) -> int:
    return BIAS_STREAM if look == 0 else TARGET_STREAM + look


def convergence_budgets(suite: Suite, case: Case) -> list[int]:
    """The suite's budgets, or five geometric ones (factor 4) from samples/4096 to samples/16
    (at least 16 and 64)."""
    if suite.budgets:
        return list(suite.budgets)
    top = max(case.samples // 16, 64)
    return [max(top >> (2 * k), 16) for k in range(4, -1, -1)]


def chosen_budgets(measurements: tuple[str, ...],
                   budgets: list[int] | tuple[int, ...]) -> list[tuple[int, int]]:
    """(index, budget) of the convergence budgets the measurements need: all of them for a
    convergence fit or the error against time, only the largest for efficiency alone."""
    wanted = set(measurements)
    if wanted & {"convergence", "error_vs_time"}:
        return list(enumerate(budgets))
    if "efficiency" in wanted:
        return [(len(budgets) - 1, budgets[-1])]
    return []


def efficiency_stream(suite: Suite, case: Case) -> tuple[int, int] | None:
    """(stream, budget) of the replicas a case's efficiency is measured from: its largest
    convergence budget.  Their units time the reference clock beside them.  None if the case
    does not measure efficiency."""
    if "efficiency" not in case.measurements:
        return None
    budgets = convergence_budgets(suite, case)
    return len(budgets), budgets[-1]


# --- units -------------------------------------------------------------------------------------
def units_per_estimate(budget: int) -> int:
    """How many units one estimate of ``budget`` contributions is stored in."""
    return -(-(-(-budget // rest.CHUNK_SIZE)) // UNIT_CHUNKS)


def unit_count(suite: Suite, case: Case) -> int:
    """How many units :func:`estimator_units` plans at most for a case over all its looks
    (with the fallback tail unit), counted without making them (a suite asking for 1e15
    samples is refused before any is made)."""
    wanted = set(case.measurements)
    n = 0
    if wanted & {"bias", "variance"}:
        for look in range(case.looks):
            n += suite.batches * units_per_estimate(bias_budget(suite, case, look)) + ("bias" in wanted)
    for _, b in chosen_budgets(case.measurements, convergence_budgets(suite, case)):
        n += suite.replicas * units_per_estimate(b)
    return n


def render_unit_count(rc: RenderCase) -> int:
    """How many units :func:`render_units` and :func:`reference_units` plan, counted."""
    bias = bool(set(rc.measurements) & {"bias", "variance"})
    return rc.replicas * (bias + len(chosen_budgets(rc.measurements, rc.budgets))) + rc.reference_parts


def _estimate_units(key: str, stream: int, budget: int, replica: int) -> list[Unit]:
    chunks = -(-budget // rest.CHUNK_SIZE)
    return [Unit(key, stream, budget, replica, c, min(c + UNIT_CHUNKS, chunks), "state")
            for c in range(0, chunks, UNIT_CHUNKS)]


def tail_keeps(suite: Suite, case: Case, look: int = 0) -> tuple[int, int]:
    """(keep, part_keep): the order statistics per side the bias test's tail sample keeps over
    all contributions of its batches at look ``look`` (TailSample.for_count), and how many each
    of its state units keeps: twice its share, plus 32, at most ``keep``.  The union of the
    units' tails is then exact unless one unit holds far more than its share of the top
    ``keep`` (over 12 standard deviations above it for i.i.d. batches); TailSample.from_parts
    says so, and a tail unit reads the contributions again."""
    b = bias_budget(suite, case, look)
    keep = TailSample.for_count(b * suite.batches).keep
    units = suite.batches * units_per_estimate(b)
    return keep, min(keep, -(-2 * keep // units) + 32)


def estimator_units(suite: Suite, case: Case, look: int = 0, *, full_tail: bool = False) -> list[Unit]:
    """An estimator case's units at look ``look`` of its precision target (0 without one).
    The bias test's state units carry their contributions' tails (:func:`tail_keeps`);
    ``full_tail``: also a "tail" unit that reads every batch's contributions again, one batch
    in memory at a time, for when the units' tails cannot give the tail sample exactly."""
    key = case_key(suite, case)
    wanted = set(case.measurements)
    units: list[Unit] = []
    if wanted & {"bias", "variance"}:
        b, stream = bias_budget(suite, case, look), bias_stream(look)
        for k in range(suite.batches):
            units += _estimate_units(key, stream, b, k)
        if "bias" in wanted and full_tail:
            units.append(Unit(key, stream, b, 0, 0, 0, "tail"))
    for i, b in chosen_budgets(case.measurements, convergence_budgets(suite, case)):
        for r in range(suite.replicas):
            units += _estimate_units(key, 1 + i, b, r)
    return units


def sampler_units(suite: Suite, sc: SamplerCase) -> list[Unit]:
    """One unit per measurement of a sampler check: it is cheap, and stored so a rerun skips it."""
    key = sampler_key(suite, sc)
    return [Unit(key, 0, sc.samples, 0, 0, 0, m) for m in sc.measurements]


def render_units(rc: RenderCase, key: str) -> list[Unit]:
    """A render case's replica renders: ``replicas`` at ``spp`` for bias and variance, and
    ``replicas`` at each budget its other measurements need."""
    units: list[Unit] = []
    if set(rc.measurements) & {"bias", "variance"}:
        units += [Unit(key, 0, rc.spp, r, 0, 0, RENDER) for r in range(rc.replicas)]
    for i, b in chosen_budgets(rc.measurements, rc.budgets):
        units += [Unit(key, 1 + i, b, r, 0, 0, RENDER) for r in range(rc.replicas)]
    return units


def reference_units(rc: RenderCase, ref_key: str) -> list[Unit]:
    """The ``reference_parts`` independent renders of a rendered reference."""
    per = rc.reference_spp // rc.reference_parts
    return [Unit(ref_key, 0, per, k, 0, 0, RENDER) for k in range(rc.reference_parts)]


def plan(suite: Suite, looks: dict[str, int] | None = None) -> dict[str, list[Unit]]:
    """Units of the suite's estimator cases and sampler checks per case key, in a fixed order;
    ``looks`` gives the current look of cases with a precision target (0 when absent).  Render
    units need the renderers' fingerprints: :func:`render_units` plans them."""
    out: dict[str, list[Unit]] = {}
    for case in suite.cases:
        key = case_key(suite, case)
        out[key] = estimator_units(suite, case, (looks or {}).get(key, 0))
    for sc in suite.samplers:
        out[sampler_key(suite, sc)] = sampler_units(suite, sc)
    return out
