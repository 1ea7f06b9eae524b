"""Results of the Python API stored where ``harness report`` and ``harness show`` find them.

    import harness
    r = harness.check_unbiased(my_estimator, 2, 0.349, sample_count=10**6)
    s = harness.check_sampler(ggx.sample, ggx.pdf, "hemisphere")
    harness.record("results/mine.sqlite", {"nee": r}, suite="mine")
    harness.record("results/mine.sqlite", {"ggx": s}, suite="mine", domain="hemisphere")
    # then: harness report --db results/mine.sqlite

Each result becomes the measurement rows a suite run writes for the same kind of check, so
the report draws it as it draws a suite's: an UnbiasedResult a "bias" row, a
ConvergenceResult a "convergence_slope" row (with its RMSE table: the report's convergence
figure; its integrand keeps the result's, the name becomes its technique, so results of one
integrand share a figure), an Efficiency a "log10_efficiency" row ("log10_efficiency_clock" with T
in reference-clock ticks), a SamplerCheck (check_sampler,
mcmc_crosscheck) a "chi_square" row with its residual grids and marginals.  A case is keyed
by suite, name and kind of result: recording it again replaces its rows.  Recorded results
of a suite accumulate in one run (file "harness.record"), which a suite run of the same name
supersedes.  The single tests
are judged at their own alpha, not Holm-corrected together (they were not run as a family).
"""
from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from harness.samplers.result import SamplerCheck
from harness.stats import CLOCK, ConvergenceResult, Efficiency, UnbiasedResult, failure_counts
from harness.suite.store import Store

__all__ = ["record"]


def record(db: str | Path, results: Mapping[str, Any], *, suite: str = "python",
           domain: str | None = None) -> int:
    """Stores ``results`` (name -> result of check_unbiased, check_technique, check_sampler,
    mcmc_crosscheck, convergence_rate or efficiency) in ``db`` under ``suite``; returns the
    number of rows written.  ``domain`` names a sampler check's domain in tables."""
    if not isinstance(results, Mapping):
        raise TypeError(f"'results' must be a mapping of names to results, got {type(results).__name__}")
    for what, value in (("'suite'", suite), *(("a result's name", k) for k in results)):
        if not isinstance(value, str) or not value:
            raise ValueError(f"{what} must be a non-empty string, got {value!r}")
    rows: list[dict[str, Any]] = []
    cases: list[tuple[str, str, str, dict[str, Any]]] = []
    for name, result in results.items():
        kind = type(result).__name__
        key = hashlib.sha256(f"record/{suite}/{name}/{kind}".encode()).hexdigest()[:24]
        made = _rows(result, name, domain)
        if made is None:
            raise TypeError(f"{name!r}: cannot record a {kind}; expected an UnbiasedResult, SamplerCheck, "
                            "ConvergenceResult or Efficiency")
        integrand, technique, measurements = made
        cases.append((key, integrand, technique, {"recorded": kind, "name": name}))
        rows += [{"case_key": key, "suite": suite, "integrand": integrand, "technique": technique, **m}
                 for m in measurements]
    store = Store(db)
    try:
        with store.translated():
            run = store.record_run(suite)   # first: a suite file's name is refused before anything is written
            for key, integrand, technique, definition in cases:
                store.add_case(key, suite, integrand, technique, definition)
            store.put_measurements(rows, run=run)
    finally:
        store.close()
    return len(rows)


def _rows(r: Any, name: str, domain: str | None) -> tuple[str, str, list[dict[str, Any]]] | None:
    if isinstance(r, UnbiasedResult):
        finite = math.isfinite(r.stderr)
        lo, hi = r.confidence_interval(0.95) if finite else (math.nan, math.nan)
        verdict = {"consistent": "unbiased"}.get(r.verdict, r.verdict)
        return name, "check_unbiased", [{
            "measurement": "bias", "value": r.estimate - r.reference, "lo": lo - r.reference,
            "hi": hi - r.reference, "n": r.n, "pvalue": r.pvalue, "alpha": r.alpha, "verdict": verdict,
            "detail": {"estimate": r.estimate, "stderr": r.stderr, "t": r.statistic, "flags": list(r.flags),
                       "tail_end": r.tail_end, "counts": failure_counts(r.failures)}}]
    if isinstance(r, ConvergenceResult):
        lo, hi = r.confidence_interval()
        return r.integrand, name, [{
            "measurement": "convergence_slope", "value": r.slope, "lo": lo, "hi": hi, "n": r.n,
            "pvalue": r.pvalue, "alpha": r.alpha, "verdict": r.verdict,
            "detail": {"expected": r.expected, "bound": r.expected + r.tolerance, "z": r.statistic,
                       "table": r.table.to_dict("list")}}]
    if isinstance(r, Efficiency):
        z = r.log10_half_width(0.95)
        clock = r.time_unit == "clock"   # T in reference-clock ticks: an interval across runs
        detail = ({"clock_ticks": r.seconds, "unit": "1/clock tick", "clock": dict(CLOCK),
                   "interval": "across runs (the machine's state cancels)"} if clock else
                  {"seconds": r.seconds, "unit": "1/s", "interval": "this run's machine state"})
        return name, r.technique, [{
            "measurement": "log10_efficiency_clock" if clock else "log10_efficiency", "value": r.log10_value,
            "lo": r.log10_value - z, "hi": r.log10_value + z, "n": r.n, "detail": detail}]
    if isinstance(r, SamplerCheck):
        if domain is None:
            raise TypeError(f"{name!r}: recording a sampler check needs domain= (the report draws its cells)")
        p = r.to_payload()
        return f"sampler:{name}", domain, [{
            "measurement": "chi_square", "value": r.pvalue, "n": r.n, "pvalue": r.pvalue, "alpha": r.alpha,
            "verdict": r.verdict,
            "detail": {k: p[k] for k in ("tests", "failures", "normalization", "residuals", "marginals")}}]
    return None
