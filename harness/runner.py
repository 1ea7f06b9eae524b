"""Runs a suite's cases on the reference core and tabulates the estimates.

A thin path for now (one estimate per case, results in memory); storage, replicas and
measurements grow around it without changing what a case is.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Iterator

import pandas as pd

import reference_estimators as rest

from .suite import Case, Suite

__all__ = ["run_suite", "estimates_table", "format_table"]


def run_suite(suite: Suite, *, threads: int | None = None,
              progress: Callable[[int, int, Case], None] | None = None) -> Iterator[tuple[Case, rest.Estimate]]:
    """Yields (case, estimate) in suite order; ``progress(done, total, case)`` after each."""
    threads = threads if threads is not None else suite.threads
    for i, case in enumerate(suite.cases):
        est = rest.integrate(case.integrand, case.technique, case.samples, seed=suite.seed,
                             case_id=case.case_id, threads=threads)
        if progress:
            progress(i + 1, len(suite.cases), case)
        yield case, est


def estimates_table(results: list[tuple[Case, rest.Estimate]]) -> pd.DataFrame:
    """One row per case: the figures with their uncertainty and n, and what to watch."""
    rows = []
    for case, e in results:
        t = rest.technique(case.integrand, case.technique)
        rows.append({
            "integrand": case.integrand,
            "technique": case.technique,
            "n": e.n,
            "estimate": e.mean,
            "stderr": e.stderr,
            "exact": e.reference,
            "z": e.z_score(),
            "seconds": e.seconds,
            "log10_efficiency": e.log10_efficiency,
            "efficiency_rel_error": e.variance_rel_error,
            "notes": _notes(e, t),
        })
    return pd.DataFrame(rows)


def _notes(e: rest.Estimate, t: rest.Technique) -> str:
    notes = [f"{k}: {v}" for k, v in e.issues.items()]
    if t.finite_variance is False:
        notes.append("infinite variance: z not normal")
    elif not e.variance_reliable:
        notes.append(f"variance uncertain ±{e.variance_rel_error:.0%}")
    if e.stderr == 0:
        notes.append("zero variance")
    return "; ".join(notes)


def format_table(df: pd.DataFrame) -> str:
    """The table as aligned text: estimate ± stderr, and the efficiency as a power of ten
    with its statistical uncertainty (from the variance's own error; timing noise excluded)."""
    columns = {
        "integrand": (df["integrand"], "<"),
        "technique": (df["technique"], "<"),
        "n": (df["n"].map(lambda n: f"{n:.0e}" if n >= 10**5 else str(n)), ">"),
        "estimate ± stderr": ([f"{m:.9g} ± {s:.2g}" for m, s in zip(df["estimate"], df["stderr"])], ">"),
        "exact": (df["exact"].map(lambda v: f"{v:.9g}"), ">"),
        "z": (df["z"].map(lambda z: f"{z:+.2f}" if math.isfinite(z) else str(z)), ">"),
        "time [s]": (df["seconds"].map(lambda s: f"{s:.3f}"), ">"),
        "1/(V·T)": ([_power_of_ten(le, r) for le, r in zip(df["log10_efficiency"], df["efficiency_rel_error"])], ">"),
        "notes": (df["notes"], "<"),
    }
    cells = {k: [str(v) for v in vals] for k, (vals, _) in columns.items()}
    width = {k: max(len(k), *(len(v) for v in cells[k])) for k in cells}
    lines = ["  ".join(f"{k:{a}{width[k]}}" for k, (_, a) in columns.items()).rstrip()]
    for i in range(len(df)):
        lines.append("  ".join(f"{cells[k][i]:{a}{width[k]}}" for k, (_, a) in columns.items()).rstrip())
    return "\n".join(lines)


def _power_of_ten(le: float, rel: float) -> str:
    if not math.isfinite(le):
        return "inf" if le > 0 else str(le)
    e = math.floor(le)
    err = f" ±{100 * rel:.2g}%" if math.isfinite(rel) and rel > 0 else ""
    return f"{10 ** (le - e):.2f}e{e:+d}{err}"
