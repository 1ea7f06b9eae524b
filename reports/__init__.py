"""Stored results -> a self-contained HTML comparison report, or its tables as CSV / Markdown.

    from reports import write_report
    write_report("results/default.sqlite", "results/default.html")            # or fmt="csv" / "markdown"

Modules, one job each: ``data`` reads the latest measurements and image pairs of a database,
``tables`` pivots and formats them, ``plots`` draws the figures (matplotlib, Agg),
``images`` tone-maps renders and draws the false-colour error map, ``html`` assembles the page.
"""
from __future__ import annotations

from pathlib import Path

from reports.data import Results, load_results
from reports.html import render_html
from reports.tables import to_csv, to_markdown, wide_table

__all__ = ["FORMATS", "Results", "load_results", "render_html", "to_csv", "to_markdown", "wide_table",
           "write_report"]

FORMATS = {"html": ".html", "csv": ".csv", "markdown": ".md"}


def write_report(db: str | Path, out: str | Path | None = None, *, fmt: str = "html",
                 suite: str | None = None, run: int | None = None) -> Path:
    """Writes the report of ``db`` (each suite's latest finished run, or run ``run``;
    optionally one suite) as ``fmt`` ("html", "csv" or "markdown") to ``out`` (default: the
    database's path with the format's suffix); returns the path written."""
    if fmt not in FORMATS:
        raise ValueError(f"'fmt' must be one of {', '.join(FORMATS)}, got {fmt!r}")
    results = load_results(db, suite, run)
    path = Path(out) if out is not None else Path(db).with_suffix(FORMATS[fmt])
    text = {"html": render_html, "csv": to_csv, "markdown": to_markdown}[fmt](results)
    if path.is_dir():
        raise ValueError(f"{path}: a folder; give the report a file name")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".partial")
    try:
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(path)
    except OSError:
        tmp.unlink(missing_ok=True)   # no half-written file left beside the target
        raise
    return path
