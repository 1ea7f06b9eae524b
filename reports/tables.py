"""Stored measurements -> tables: one row per case, numbers for CSV, formatted cells for
HTML and Markdown.

``wide_table`` pivots the long measurements table (one row per case and measurement) into
one row per case with, per measurement M, the columns M, M_lo, M_hi (95 % interval), M_n,
M_pvalue, M_verdict where stored.  ``summary_columns`` and ``sampler_columns`` say how each
displayed column is formatted; the HTML page and the Markdown output both use them.
"""
from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import pandas as pd

from harness.suite.verdicts import FAILING, PASSING
from reports.data import SAMPLER_PREFIX, Results

__all__ = ["Cell", "Column", "value_of", "wide_table", "summary_columns", "sampler_columns", "render_rows",
           "to_markdown", "to_csv", "BAD", "GOOD", "HIDDEN", "verdict_class", "fmt_num", "fmt_p", "p_equals",
           "fmt_n", "fmt_interval"]

# measurements in display order; others follow alphabetically
ORDER = ("bias", "variance", "convergence_slope", "convergence", "efficiency_ratio", "efficiency",
         "log10_efficiency_clock", "log10_efficiency", "rmse", "relmse", "target_half_width", "chi_square",
         "mcmc")
# in CSV only: the efficiency ratio and the efficiency in clock ticks say it better (the one in
# 1/s has an interval of one run's machine state); a render's error_vs_time value is its relMSE,
# and the RMSE at the top budget is drawn, with its interval, in the convergence figure
HIDDEN = {"variance", "log10_efficiency", "error_vs_time", "rmse"}
LABELS = {
    "bias": ("bias [95% CI]", "estimate − exact value, 95 % Student-t interval (from all contributions, "
                              "or from the replicas for stratified and Sobol' points); below it the "
                              "estimate ± its standard error and n = samples"),
    "convergence_slope": ("RMSE slope [95% CI]", "log-log slope of RMSE against samples per estimate, "
                                                 "permutation-test 95 % interval; n = replicas over all "
                                                 "budgets"),
    "convergence": ("error slope [95% CI]", "log-log slope of the error against the budget, 95 % interval"),
    "efficiency_ratio": ("1/(V·T) ratio [95% CI]", "efficiency 1/(variance × time) as a ratio "
                                                         "against the baseline technique, 95 % interval; "
                                                         "n = samples"),
    "log10_efficiency_clock": ("log10 1/(V·T_clock) [95% CI]",
                               "efficiency 1/(variance × time) per technique, time in ticks of the "
                               "reference clock timed beside each replica, so the machine's state "
                               "cancels: other runs on this machine type fall in its 95 % interval "
                               "(the figure in 1/s, in the CSV, has an interval of this run's machine "
                               "state only); n = samples"),
    "efficiency": ("efficiency ratio [95% CI]", "efficiency ratio against the baseline configuration "
                                                      "(1/(relMSE × time) for renders), 95 % interval"),
    "rmse": ("RMSE [95% CI]", "root-mean-square error at the largest budget, 95 % interval; "
                              "n = samples per estimate"),
    "relmse": ("relMSE [95% CI]", "relative mean squared error of the image at the largest budget, "
                                  "95 % interval; n = replicas"),
    "equal_time_relmse": ("relMSE at equal time", "relMSE interpolated to a common render time; "
                                                  "n = replicas"),
    "target_half_width": ("CI half-width", "half-width of the bias test's interval "
                                           "against its precision target"),
}
# a CI failure, and a missed precision target (shown as bad, though a run does not fail on it)
BAD = FAILING | {"not reached"}
GOOD = PASSING


def shown_verdict(verdict: Any, xfail: Any) -> str:
    """The verdict as the report shows it: "xfailed" where a case with an ``xfail`` reason
    failed (a known finding, neutral), else the stored one."""
    v = str(verdict or "")
    return "xfailed" if xfail and v in FAILING else v


def verdict_class(verdict: str) -> str:
    """CSS class of a verdict: 'bad' (a CI failure), 'good', or 'neutral' (inconclusive, not judged)."""
    return "bad" if verdict in BAD else ("good" if verdict in GOOD else "neutral")


# --- numbers -> text ---------------------------------------------------------------------------
def _finite(v: Any) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(v)


def fmt_num(v: Any, fmt: str = ".3g") -> str:
    return f"{v:{fmt}}".replace("-", "−") if _finite(v) else "—"


def fmt_interval(v: Any, lo: Any, hi: Any, fmt: str = ".3g") -> str:
    if not _finite(v):
        return "—"
    if not (_finite(lo) and _finite(hi)):
        return fmt_num(v, fmt)
    return f"{fmt_num(v, fmt)} [{fmt_num(lo, fmt)}, {fmt_num(hi, fmt)}]"


def fmt_p(p: Any) -> str:
    if not _finite(p):
        return "—"
    return "<1e-300" if p == 0 else f"{p:.2g}"


def p_equals(p: Any) -> str:
    """"p = 0.04", or "p < 1e-300" where it underflowed."""
    text = fmt_p(p)
    return f"p {text[0]} {text[1:]}" if text.startswith("<") else f"p = {text}"


def fmt_n(n: Any) -> str:
    return f"{int(n):,}" if _finite(n) else "—"


# --- the wide numeric table --------------------------------------------------------------------
def _measurement_order(names: list[str]) -> list[str]:
    known = [m for m in ORDER if m in names]
    return known + sorted(set(names) - set(known))


def wide_table(m: pd.DataFrame) -> pd.DataFrame:
    """One row per case of ``m`` (measurements of Results, or a part), in stored order, with
    every stored measurement's value, interval, n, p-value and verdict as numbers."""
    rows: dict[str, dict[str, Any]] = {}
    for r in m.itertuples(index=False):
        row = rows.setdefault(r.case_key, {"suite": r.suite, "kind": r.kind, "integrand": r.integrand,
                                           "technique": r.technique, "case_key": r.case_key,
                                           "alpha": r.alpha, "xfail": getattr(r, "xfail", "")})
        k = r.measurement
        row.update({k: r.value, f"{k}_lo": r.lo, f"{k}_hi": r.hi, f"{k}_n": r.n, f"{k}_pvalue": r.pvalue,
                    f"{k}_verdict": r.verdict})
        d = r.detail
        if k == "bias":
            row.update({"estimate": d.get("estimate"), "stderr": d.get("stderr"),
                        "flags": "; ".join(d.get("flags", []))
                        + "".join(f"; {c}: {v}" for c, v in (d.get("counts") or {}).items())})
        elif k in ("convergence_slope", "convergence") and "expected" in d:
            row[f"{k}_expected"] = d["expected"]
            row[f"{k}_z"], row[f"{k}_bound"] = d.get("z"), d.get("bound")
        elif k in ("efficiency_ratio", "efficiency") and "baseline" in d:
            row[f"{k}_baseline"] = d["baseline"]
        elif k in ("chi_square", "mcmc"):
            row[f"{k}_failures"] = "; ".join(f"{f['check']}: {f['count']}" for f in d.get("failures", []))
    df = pd.DataFrame(list(rows.values()))
    if df.empty:
        return df
    base = ["suite", "kind", "integrand", "technique", "case_key", "alpha", "estimate", "stderr", "flags"]
    order = [c for c in base if c in df]
    for k in _measurement_order(list(m["measurement"].unique())):
        order += [c for c in df.columns if c == k or (c.startswith(k + "_") and c not in order
                                                      and c[len(k) + 1:] in _SUFFIXES)]
    order += [c for c in df.columns if c not in order]
    df = df[order]
    df = df.loc[:, [c for c in df.columns if df[c].notna().any() and not (df[c].astype(str) == "").all()]]
    for c in [c for c in df.columns if c.endswith("_n")]:
        df[c] = df[c].astype("Int64")   # counts print as integers in CSV
    return df


_SUFFIXES = ("lo", "hi", "n", "pvalue", "verdict", "expected", "baseline", "failures", "z", "bound")


# --- displayed columns -------------------------------------------------------------------------
@dataclass(frozen=True)
class Cell:
    text: str
    note: str = ""       # a second, smaller line: sample count, baseline, expected rate
    verdict: str = ""    # set for verdict cells (colouring)


@dataclass(frozen=True)
class Column:
    header: str
    title: str                          # what the column is, with units (a tooltip in HTML)
    cell: Callable[[dict[str, Any]], Cell]
    numeric: bool = False


def value_of(row: dict[str, Any], key: str) -> Any:
    """row[key], or None where missing, NaN or NA."""
    v = row.get(key)
    return None if v is None or (pd.api.types.is_scalar(v) and pd.isna(v)) else v


def _value_column(k: str) -> Column:
    header, title = LABELS.get(k, (f"{k} [95% CI]", f"stored measurement {k!r}, 95 % interval"))
    fmt = "+.2f" if k in ("convergence_slope", "convergence") else ".3g"

    def cell(row: dict[str, Any]) -> Cell:
        notes = [f"n = {fmt_n(row.get(f'{k}_n'))}"] if value_of(row, f"{k}_n") is not None else []
        if k == "bias" and value_of(row, "estimate") is not None:   # the estimate under its bias
            notes.insert(0, f"estimate {fmt_num(value_of(row, 'estimate'), '.9g')} ± "
                            f"{fmt_num(value_of(row, 'stderr'), '.2g')}")
        if value_of(row, f"{k}_expected") is not None:
            notes.append(f"expected {fmt_num(row[f'{k}_expected'], '+.2f')}")
        if value_of(row, f"{k}_baseline") is not None:
            notes.append(f"vs {row[f'{k}_baseline']}")
        if value_of(row, f"{k}_verdict") in ("infinite variance", "unreliable"):   # no interval, and why
            notes.append(str(row[f"{k}_verdict"]))
        # the value on the first line, its interval under it (unbroken), so the table fits a screen
        v, lo, hi = value_of(row, k), value_of(row, f"{k}_lo"), value_of(row, f"{k}_hi")
        if _finite(v) and _finite(lo) and _finite(hi):
            notes.insert(0, f"[{fmt_num(lo, fmt)}, {fmt_num(hi, fmt)}]")
        return Cell(fmt_num(v, fmt) if _finite(v) else "—", ", ".join(notes))
    return Column(header, title, cell, numeric=True)


def _verdict_cell(row: dict[str, Any], k: str) -> Cell:
    shown = shown_verdict(value_of(row, f"{k}_verdict"), value_of(row, "xfail"))
    note = _p_note(row, k)
    if shown == "xfailed":
        note = f"{note}; xfail: {row['xfail']}" if note else f"xfail: {row['xfail']}"
    return Cell(shown or "—", note, verdict=shown)


def _p_note(row: dict[str, Any], k: str) -> str:
    """The p-value under a verdict; for a slope whose one-sided p rounds to 1, the margin
    instead: how many standard errors the slope lies inside its bound."""
    p = value_of(row, f"{k}_pvalue")
    if p is None:
        return ""
    z, bound = value_of(row, f"{k}_z"), value_of(row, f"{k}_bound")
    if p >= 0.995 and z is not None and bound is not None and math.isfinite(z):
        return f"p ≈ 1: {-z:.1f} s.e. inside the bound {bound:+.2f}"
    return p_equals(p)


def summary_columns(wide: pd.DataFrame) -> list[Column]:
    """The summary table's columns for the cases in ``wide`` (a wide_table of one kind of case)."""
    cols = [Column("integrand", "integrand or scene", lambda r: Cell(str(r["integrand"]))),
            Column("technique", "estimator technique or renderer configuration",
                   lambda r: Cell(str(r["technique"])))]
    present = [c for c in wide.columns if f"{c}_lo" in wide or f"{c}_verdict" in wide or f"{c}_n" in wide]
    for k in _measurement_order(present):
        if k in HIDDEN or k in ("chi_square", "mcmc"):
            continue
        cols.append(_value_column(k))
        if f"{k}_verdict" in wide:
            cols.append(Column("verdict (p)", f"verdict of the {k} test, Holm-corrected across the suite "
                                              "at its α; p-value before the correction (slopes: one-sided, "
                                              "H0 the error falls at least as fast as the bound; where p "
                                              "rounds to 1, how many standard errors the slope is inside it)",
                               lambda r, k=k: _verdict_cell(r, k)))
        elif f"{k}_pvalue" in wide:
            cols.append(Column("p", f"p-value of the {k} test",
                               lambda r, k=k: Cell(fmt_p(value_of(r, f"{k}_pvalue"))),
                               numeric=True))
    if "flags" in wide:
        cols.append(Column("notes", "warnings of the bias test: heavy tails, skewed batches, faults",
                           lambda r: Cell(str(value_of(r, "flags") or ""))))
    return cols


def _sampler_verdict(r: dict[str, Any]) -> Cell:
    shown = shown_verdict(r["verdict"], r.get("xfail"))
    return Cell(shown or "—", f"xfail: {r['xfail']}" if shown == "xfailed" else "", verdict=shown)


def sampler_columns() -> list[Column]:
    """Columns of the sampler-check table (rows: the samplers frame of Results, as dicts)."""
    def norm(r: dict[str, Any]) -> Cell:
        v = (r["detail"].get("normalization") or [math.nan, math.nan])
        return Cell("—" if not _finite(v[0]) else f"{v[0]:.6f} ± {v[1]:.1e}")

    def failures(r: dict[str, Any]) -> Cell:
        return Cell("; ".join(f"{f['check']}: {f['count']}" for f in r["detail"].get("failures", []))
                    or "none")

    return [
        Column("sampler", "catalogue sampler and parameters",
               lambda r: Cell(r["integrand"][len(SAMPLER_PREFIX):])),
        Column("domain", "sampling domain", lambda r: Cell(str(r["technique"]))),
        Column("check", "chi_square: cubature-based tests; mcmc: two-sample tests against emcee draws",
               lambda r: Cell(str(r["measurement"]))),
        Column("n", "samples drawn", lambda r: Cell(fmt_n(r["n"])), numeric=True),
        Column("p", "smallest Holm-adjusted p-value of the check's sub-tests",
               lambda r: Cell(fmt_p(r["pvalue"])),
               numeric=True),
        Column("verdict", "Holm across the suite's sampler checks at its α; "
                          "deterministic failures always fail",
               _sampler_verdict),
        Column("α", "the suite's family-wise false-alarm rate", lambda r: Cell(fmt_num(r["alpha"], "g")),
               numeric=True),
        Column("∫ pdf", "integral of the claimed pdf over the domain (cubature) ± its error bound", norm,
               numeric=True),
        Column("deterministic failures", "points outside the domain, zero/NaN/negative pdf, normalisation",
               failures),
    ]


def render_rows(rows: list[dict[str, Any]], columns: list[Column]) -> list[list[Cell]]:
    return [[c.cell(r) for c in columns] for r in rows]


# --- CSV and Markdown --------------------------------------------------------------------------
def to_csv(results: Results) -> str:
    """The wide table (every case and sampler check) as CSV: numbers, not formatted text."""
    return wide_table(results.measurements).to_csv(index=False)


def _markdown(rows: list[dict[str, Any]], columns: list[Column]) -> str:
    cells = render_rows(rows, columns)
    frame = pd.DataFrame([[c.text + (f" ({c.note})" if c.note else "") for c in row] for row in cells],
                         columns=[c.header for c in columns])
    return frame.to_markdown(index=False, colalign=["right" if c.numeric else "left" for c in columns])


def to_markdown(results: Results) -> str:
    """The summary table and the sampler-check table as Markdown (pandas + tabulate)."""
    parts = [f"# Results of {results.db.name}"]
    for kind, title in (("estimator", "Cases"), ("render", "Render cases")):
        wide = wide_table(results.of_kind(kind))
        if len(wide):
            parts += [f"## {title}", _markdown(wide.to_dict("records"), summary_columns(wide))]
    samp = results.samplers
    if len(samp):
        parts += ["## Sampler checks", _markdown(samp.to_dict("records"), sampler_columns())]
    if len(parts) == 1:
        parts.append("No measurements stored.")
    return "\n\n".join(parts) + "\n"
