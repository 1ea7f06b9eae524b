"""Executes work units locally on threads or on a Dask cluster; the caller's process is the
only writer to the store, so a result is stored exactly once, whoever computed it.

A unit is computed from plain values (names and numbers), so Dask workers need nothing but
the installed package, and a unit's result is the same bits wherever it runs.
"""
from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import reference_estimators as rest
from reference_estimators import _core

from harness.suite.plan import Unit
from harness.stats import TailSample

__all__ = ["UnitJob", "compute", "run_local", "run_dask"]

# (unit key, integrand, technique, seed, core case id): everything compute() needs
UnitJob = tuple[tuple, str, str, int, int]


def compute(job: UnitJob) -> tuple[tuple, dict[str, Any], float]:
    """The unit's payload and its wall time (s).  'state' units hold the accumulator state of
    their chunk range; 'tail' units the largest deviations above and below the median of the
    estimate's contributions (for the tail-index test)."""
    key, integrand, technique, seed, core_case = job
    _, _, budget, replica, c0, c1, kind = key
    if kind in ("chi_square", "mcmc", "weight"):
        return key, *_sampler_check(kind, integrand, seed)
    f = rest.integrand(integrand)
    t = rest.technique(f, technique)
    start = time.perf_counter()
    if kind == "state":
        payload = _core.integrate_chunks(f, t, budget, seed, core_case, replica, c0, c1, 1)
    else:
        tails = TailSample.for_count(budget)
        tails.add(rest.contributions(f, t, budget, seed=seed, case_id=core_case, replica=replica, threads=1))
        payload = {"center": tails.center, "upper": tails.upper.tolist(), "lower": tails.lower.tolist()}
    return key, payload, time.perf_counter() - start


def _sampler_check(kind: str, spec_json: str, seed: int) -> tuple[dict[str, Any], float]:
    """A sampler-check unit: 'integrand' carries the sampler's JSON spec (plan.sampler_spec)."""
    import json

    import numpy as np

    from harness.samplers.check import check_sampler, mcmc_crosscheck

    spec = json.loads(spec_json)
    start = time.perf_counter()
    if spec.get("adapter"):  # a renderer's sampler, which may fail to produce samples
        from harness.adapters.mitsuba.samplers import check_mitsuba_sampler, make_sampler, weight_consistency

        ms = make_sampler(spec["spec"])
        if kind == "weight":
            return weight_consistency(ms, sample_count=spec["samples"], seed=seed).to_payload(), \
                time.perf_counter() - start
        r = check_mitsuba_sampler(ms, sample_count=spec["samples"], seed=seed)
    elif kind == "chi_square":
        s = rest.sampler(spec["name"], **spec["params"])
        r = check_sampler(lambda u: s.sample(u)[0], s.pdf, spec["domain"], sample_count=spec["samples"], seed=seed)
    else:
        s = rest.sampler(spec["name"], **spec["params"])
        r = mcmc_crosscheck(lambda u: s.sample(u)[0], s.pdf, spec["domain"], sample_count=min(spec["samples"], 20_000),
                            seed=seed)
    payload = {"passed": r.passed, "pvalue": r.pvalue, "tests": json.loads(r.tests.to_json(orient="records")),
               "failures": json.loads(json.dumps(list(r.failures), default=float)),
               "normalization": [float(v) for v in r.normalization],
               # for the report's heatmaps and marginal plots, rounded to keep rows small; pooled cells null
               "residuals": {g: np.where(np.isnan(v), None, np.round(v, 2)).tolist() for g, v in r.residuals.items()},
               "marginals": {a: {k: np.round(v, 2).tolist() for k, v in m.items()} for a, m in r.marginals.items()}}
    return payload, time.perf_counter() - start


def run_local(jobs: list[UnitJob], threads: int) -> Iterator[tuple[tuple, dict[str, Any], float]]:
    """Units on a thread pool (the core releases the GIL), results as they finish."""
    with ThreadPoolExecutor(max_workers=max(threads, 1)) as pool:
        yield from pool.map(compute, jobs)


def run_dask(jobs: list[UnitJob], address: str, threads: int) -> Iterator[tuple[tuple, dict[str, Any], float]]:
    """Units on a Dask cluster: ``address`` of a scheduler, or "local" for a LocalCluster of
    ``threads`` single-threaded worker processes."""
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = LocalCluster(n_workers=max(threads, 1), threads_per_worker=1, processes=True,
                           dashboard_address=None) if address == "local" else None
    client = Client(cluster if cluster is not None else address)
    try:
        futures = client.map(compute, jobs, pure=False)
        for fut in as_completed(futures):
            yield fut.result()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def execute(units: Iterable[Unit], job_of: Callable[[Unit], UnitJob], sink: Callable[[tuple, dict, float], None],
            *, threads: int, dask: str | None = None) -> int:
    """Computes the units and hands each result to ``sink``; returns how many ran."""
    jobs = [job_of(u) for u in units]
    results = run_dask(jobs, dask, threads) if dask else run_local(jobs, threads)
    n = 0
    for key, payload, seconds in results:
        sink(key, payload, seconds)
        n += 1
    return n
