"""Reads what a report shows from a results database: measurements and image pairs.

Nothing is recomputed here.  One choice is made: a database that has seen several runs of a
suite (a rebuilt core changes every case key) keeps the older rows, so a case, identified
by its suite, integrand, technique and stored definition (seed, samples, position in the
suite), is shown from its most recently written rows only; the others are counted as
superseded.  Cases without a row in the ``cases`` table (render cases may have none) are
identified by their key.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from harness.suite.store import connect_read_only, image_dir, read_exr

__all__ = ["Results", "load_results", "SAMPLER_PREFIX"]

SAMPLER_PREFIX = "sampler:"   # integrand column of sampler checks: "sampler:<label>"


@dataclass
class Results:
    """The latest measurements of a database, with their details parsed.

    ``measurements``: one row per case and measurement (columns of the store's table, plus
    ``detail`` as a dict, ``row``, the write order, and ``kind``: "estimator", "sampler" or
    "render").  ``image_pairs``: case key -> (name of the reference image, name of the
    estimate image), for cases having both.
    """

    db: Path
    measurements: pd.DataFrame
    image_pairs: dict[str, tuple[str, str]]
    superseded: int                       # case keys hidden because a later run replaced them
    labels: dict[str, tuple[str, str]] = field(default_factory=dict)  # case key -> (integrand, technique)

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
        return np.asarray(read_exr(image_dir(self.db) / row[0]), dtype=np.float32)


def load_results(db: str | Path, suite: str | None = None) -> Results:
    """The measurements of ``db`` (optionally of one suite), latest run per case."""
    path = Path(db)
    if not path.is_file():
        raise FileNotFoundError(f"no results database at {path} (run `harness run SUITE --db {path}` first)")
    con = connect_read_only(path)
    try:
        tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        if "measurements" not in tables:
            raise ValueError(f"{path} is not a results database (no measurements table)")
        where = " WHERE m.suite = ?" if suite else ""
        m = pd.read_sql_query("SELECT m.rowid AS row, m.*, c.definition FROM measurements m "
                              "LEFT JOIN cases c ON c.case_key = m.case_key" + where + " ORDER BY m.rowid",
                              con, params=(suite,) if suite else ())
        names = [r[0] for r in con.execute("SELECT name FROM images")] if "images" in tables else []
        labels = {r[0]: (r[1], r[2]) for r in con.execute("SELECT case_key, integrand, technique FROM cases")}
    finally:
        con.close()

    m["detail"] = [json.loads(d) if isinstance(d, str) and d else {} for d in m["detail"]]
    m["_ident"] = ["\x1f".join(t) for t in zip(m["suite"], m["integrand"], m["technique"],
                                                 m["definition"].fillna(m["case_key"]))]
    latest = m.groupby("_ident", sort=False)["row"].transform("max")
    keep_keys = set(m.loc[m["row"] == latest, "case_key"])
    rendered = {n.rpartition("/")[0] for n in names if n.endswith("/estimate")}
    m["xfail"] = [d.get("xfail", "") for d in m["detail"]]   # a known finding's reason
    m["kind"] = ["sampler" if i.startswith(SAMPLER_PREFIX) else
                 "render" if k in rendered or '"adapter"' in str(d) else "estimator"
                 for i, k, d in zip(m["integrand"], m["case_key"], m["definition"])]
    all_keys = set(m["case_key"])
    m = m[m["case_key"].isin(keep_keys)].drop(columns=["_ident", "definition"]).reset_index(drop=True)

    images = set(names)
    stale = all_keys - keep_keys
    pairs = {}
    for name in names:
        key, _, kind = name.rpartition("/")
        shown = key in keep_keys if suite else key not in stale
        if kind == "reference" and f"{key}/estimate" in images and shown:
            pairs[key] = (name, f"{key}/estimate")
    order = {k: i for i, k in enumerate(dict.fromkeys(m["case_key"]))}  # the suite's order of cases
    pairs = dict(sorted(pairs.items(), key=lambda kv: order.get(kv[0], len(order))))
    return Results(path, m, pairs, len(stale), labels)
