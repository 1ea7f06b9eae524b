"""Reads what a report shows from a results database: measurements and image pairs.

Nothing is recomputed here.  A database that has seen several runs of a suite keeps every
run's measurements; a report shows each suite's latest finished run (or the run asked for)
and counts the cases of earlier runs it no longer measures as superseded.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from harness.suite.readers import connect_read_only, reading, run_filter
from harness.suite.store import image_dir, read_stored

__all__ = ["Results", "load_results", "SAMPLER_PREFIX"]

SAMPLER_PREFIX = "sampler:"   # integrand column of sampler checks: "sampler:<label>"


@dataclass
class Results:
    """The latest measurements of a database, with their details parsed.

    ``measurements``: one row per case and measurement (columns of the store's table, plus
    ``detail`` as a dict, ``row``, the write order, and ``kind``: "estimator", "sampler" or
    "render").  ``image_pairs``: case key -> (name of the reference image, name of the
    estimate image), for cases having both; ``t_maps``: case key -> name of its bias test's |t|
    map at the most significant scale, for cases having one.
    """

    db: Path
    measurements: pd.DataFrame
    image_pairs: dict[str, tuple[str, str]]
    superseded: int                       # case keys hidden because a later run replaced them
    labels: dict[str, tuple[str, str]] = field(default_factory=dict)  # case key -> (integrand, technique)
    runs: list[dict[str, Any]] = field(default_factory=list)  # the runs shown: run, suite, alpha, families
    t_maps: dict[str, str] = field(default_factory=dict)      # case key -> its |t| map's image name

    @property
    def cases(self) -> pd.DataFrame:
        """Estimator and render cases (not sampler checks): their measurements."""
        return self.measurements[self.measurements["kind"] != "sampler"]

    def of_kind(self, kind: str) -> pd.DataFrame:
        """The measurements of one kind of case: "estimator", "sampler" or "render"."""
        return self.measurements[self.measurements["kind"] == kind]

    @property
    def samplers(self) -> pd.DataFrame:
        """Sampler-check rows (chi_square, mcmc)."""
        return self.of_kind("sampler")

    def image(self, name: str) -> np.ndarray:
        """A stored image, float32 (height, width, channels)."""
        con = connect_read_only(self.db)
        try:
            row = con.execute("SELECT file FROM images WHERE name = ?", (name,)).fetchone()
        finally:
            con.close()
        if row is None:
            raise KeyError(f"no image {name!r} in {self.db}")
        return np.asarray(read_stored(image_dir(self.db) / row[0]), dtype=np.float32)


def load_results(db: str | Path, suite: str | None = None, run: int | None = None) -> Results:
    """The measurements of ``db`` (optionally of one suite): each suite's latest finished run,
    or run ``run``."""
    path = Path(db)
    if not path.is_file():
        raise FileNotFoundError(f"no results database at {path} (run `harness run SUITE --db {path}` first)")
    with reading(path) as con:
        where, params = run_filter(con, path, suite=suite, run=run)
        m = pd.read_sql_query("SELECT m.rowid AS row, m.*, c.definition FROM measurements m "
                              "LEFT JOIN cases c ON c.case_key = m.case_key" + where + " ORDER BY m.rowid",
                              con, params=params)
        every, _ = run_filter(con, path, suite=suite, all_runs=True)
        all_keys = {k for (k,) in con.execute(f"SELECT DISTINCT m.case_key FROM measurements m{every}",
                                              params[:1] if suite else ())}
        tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        names = [r[0] for r in con.execute("SELECT name FROM images")] if "images" in tables else []
        labels = {r[0]: (r[1], r[2]) for r in con.execute("SELECT case_key, integrand, technique FROM cases")}
        shown = sorted(set(int(r) for r in m["run"])) if "run" in m else []
        runs = ([{"run": r[0], "suite": r[1], "alpha": r[2], "families": json.loads(r[3] or "[]")}
                 for r in con.execute(f"SELECT run, suite, alpha, families FROM runs WHERE run IN "
                                      f"({','.join('?' * len(shown))})", shown)] if "runs" in tables else [])

    m["detail"] = [json.loads(d) if isinstance(d, str) and d else {} for d in m["detail"]]
    keep_keys = set(m["case_key"])
    rendered = {n.rpartition("/")[0] for n in names if n.endswith("/estimate")}
    m["xfail"] = [d.get("xfail", "") for d in m["detail"]]   # a known finding's reason
    m["kind"] = ["sampler" if i.startswith(SAMPLER_PREFIX) else
                 "render" if k in rendered or '"adapter"' in str(d) else "estimator"
                 for i, k, d in zip(m["integrand"], m["case_key"], m["definition"])]
    m = m.drop(columns=["definition"]).reset_index(drop=True)

    images = set(names)
    pairs = {}
    for name in names:
        key, _, kind = name.rpartition("/")
        if kind == "reference" and f"{key}/estimate" in images and key in keep_keys:
            pairs[key] = (name, f"{key}/estimate")
    order = {k: i for i, k in enumerate(dict.fromkeys(m["case_key"]))}  # the suite's order of cases
    pairs = dict(sorted(pairs.items(), key=lambda kv: order.get(kv[0], len(order))))
    t_maps = {key: f"{key}/tmap" for key in pairs if f"{key}/tmap" in images}
    return Results(path, m, pairs, len(all_keys - keep_keys), labels, runs, t_maps)
