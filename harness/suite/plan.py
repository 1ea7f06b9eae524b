"""The plan: the work units a suite's measurements need, and nothing else.

A unit is a contiguous range of at most UNIT_CHUNKS core chunks of one estimate, keyed by
(case fingerprint, stream, budget, replica, chunk range, kind).  Shared work is planned once:
the bias test's batches also give the variance, the convergence replicas also give the
efficiency and the error against time.  No reference run is planned (the catalogue's values
are exact), no renderer or sampler test unless a case asks for one.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass

import reference_estimators as rest

from harness.suite.parse import MEASUREMENTS, Case, SamplerCase, Suite

__all__ = ["UNIT_CHUNKS", "MEASUREMENTS", "Unit", "case_key", "sampler_key", "sampler_spec", "bias_budget",
           "bias_stream", "convergence_budgets", "plan"]

UNIT_CHUNKS = 32                     # core chunks (of 65 536 samples) per stored unit
BIAS_STREAM = 0                      # stream 0: the bias test's batches; 1 + i: convergence budget i;
TARGET_STREAM = 200                  # 200 + s: the bias test's batches at look s >= 1 of a target
_FORMAT = 1                          # bump when a unit's meaning changes: old rows stop matching
_SAMPLER_PAYLOAD = 2                 # sampler-check payloads: 2 adds residual grids and marginals (report)


@dataclass(frozen=True, order=True)
class Unit:
    case_key: str
    stream: int
    budget: int       # contributions in the estimate this unit is part of
    replica: int
    chunk_begin: int
    chunk_end: int
    kind: str         # "state" or "tail"

    @property
    def key(self) -> tuple[str, int, int, int, int, int, str]:
        return (self.case_key, self.stream, self.budget, self.replica, self.chunk_begin, self.chunk_end, self.kind)


def case_key(suite: Suite, case: Case) -> str:
    """Fingerprint of what fixes a case's random numbers and contributions."""
    definition = {"integrand": case.integrand, "technique": case.technique, "seed": suite.seed,
                  "case_id": case.case_id, "unit_chunks": UNIT_CHUNKS, "format": _FORMAT,
                  "core": rest.__version__, "build": rest.core_fingerprint()}
    return hashlib.sha256(json.dumps(definition, sort_keys=True).encode()).hexdigest()[:24]


def sampler_key(suite: Suite, sc: SamplerCase) -> str:
    """Fingerprint of a sampler check: the sampler, its parameters, domain, samples and seed."""
    definition = {"sampler": sc.name, "params": list(sc.params), "domain": sc.domain, "samples": sc.samples,
                  "seed": suite.seed, "case_id": sc.case_id, "format": _FORMAT, "payload": _SAMPLER_PAYLOAD, "core": rest.__version__,
                  "build": rest.core_fingerprint()}
    if sc.adapter:  # a renderer's sampler: its library version is part of what is tested
        from harness.adapters.mitsuba.samplers import make_sampler

        definition.update(adapter=sc.adapter, spec=sc.spec, fingerprint=make_sampler(json.loads(sc.spec)).fingerprint())
    return hashlib.sha256(json.dumps(definition, sort_keys=True).encode()).hexdigest()[:24]


def sampler_spec(sc: SamplerCase) -> str:
    """What a worker needs to rebuild the sampler (JSON)."""
    return json.dumps({"name": sc.name, "params": dict(sc.params), "domain": sc.domain, "samples": sc.samples,
                       "adapter": sc.adapter, "spec": json.loads(sc.spec) if sc.spec else None})


def bias_budget(suite: Suite, case: Case, look: int = 0) -> int:
    """Contributions per batch of the bias test (at look ``look`` of a precision target)."""
    return (case.samples << look) // suite.batches


def bias_stream(look: int) -> int:
    return BIAS_STREAM if look == 0 else TARGET_STREAM + look


def convergence_budgets(suite: Suite, case: Case) -> list[int]:
    """The suite's budgets, or five geometric ones from samples/1024 to samples/16."""
    if suite.budgets:
        return list(suite.budgets)
    top = max(case.samples // 16, 64)
    return [max(top >> (2 * k), 16) for k in range(4, -1, -1)]


def _estimate_units(key: str, stream: int, budget: int, replica: int) -> list[Unit]:
    chunks = -(-budget // rest.CHUNK_SIZE)
    return [Unit(key, stream, budget, replica, c, min(c + UNIT_CHUNKS, chunks), "state")
            for c in range(0, chunks, UNIT_CHUNKS)]


def plan(suite: Suite, looks: dict[str, int] | None = None) -> dict[str, list[Unit]]:
    """Units per case key, in a fixed order; ``looks`` gives the current look of cases with a
    precision target (0 when absent)."""
    out: dict[str, list[Unit]] = {}
    for case in suite.cases:
        key = case_key(suite, case)
        wanted = set(case.measurements)
        units: list[Unit] = []
        if wanted & {"bias", "variance"}:
            look = (looks or {}).get(key, 0)
            b, stream = bias_budget(suite, case, look), bias_stream(look)
            for k in range(suite.batches):
                units += _estimate_units(key, stream, b, k)
            if "bias" in wanted:
                units.append(Unit(key, stream, b, 0, 0, 0, "tail"))
        budgets = convergence_budgets(suite, case)
        if wanted & {"convergence", "error_vs_time"}:
            chosen = list(enumerate(budgets))
        elif "efficiency" in wanted:
            chosen = [(len(budgets) - 1, budgets[-1])]
        else:
            chosen = []
        for i, b in chosen:
            for r in range(suite.replicas):
                units += _estimate_units(key, 1 + i, b, r)
        out[key] = units
    for sc in suite.samplers:  # one unit per check: it is cheap, and stored so a rerun skips it
        key = sampler_key(suite, sc)
        out[key] = [Unit(key, 0, sc.samples, 0, 0, 0, m) for m in sc.measurements]
    return out
