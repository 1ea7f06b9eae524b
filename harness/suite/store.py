"""Results storage: SQLite in WAL mode, one row per finished work unit.

A unit's row holds its complete accumulator state (JSON; Python's float repr round-trips
every double exactly) and is written inside a transaction under a UNIQUE key, so a run killed
at any point leaves only whole rows, and a rerun skips exactly the units already stored.
Measurements computed from the units go to their own table, replaced per case on each run.
Images (renders, references) are EXR files (float32, via OpenImageIO) in a folder beside the
database, each written to a temporary name and renamed before its row is committed, so a
row always points at a complete file.
"""
from __future__ import annotations

import hashlib
import json
import os
import re
import sqlite3
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from harness.adapters.base import read_image
from harness.suite.plan import Unit

__all__ = ["Store", "load", "connect_read_only", "image_dir", "write_exr", "read_exr"]

_SCHEMA = """
CREATE TABLE IF NOT EXISTS cases (
    case_key   TEXT PRIMARY KEY,   -- fingerprint of everything that defines the case's numbers
    suite      TEXT NOT NULL,
    integrand  TEXT NOT NULL,
    technique  TEXT NOT NULL,
    definition TEXT NOT NULL       -- JSON
);
CREATE TABLE IF NOT EXISTS units (
    case_key    TEXT NOT NULL,
    stream      INTEGER NOT NULL,
    budget      INTEGER NOT NULL,
    replica     INTEGER NOT NULL,
    chunk_begin INTEGER NOT NULL,
    chunk_end   INTEGER NOT NULL,
    kind        TEXT NOT NULL,     -- 'state', 'tail', a sampler measurement or 'render'
    payload     TEXT NOT NULL,     -- JSON
    seconds     REAL NOT NULL,
    finished    REAL NOT NULL,
    UNIQUE (case_key, stream, budget, replica, chunk_begin, chunk_end, kind)
);
CREATE TABLE IF NOT EXISTS images (
    name    TEXT PRIMARY KEY,      -- e.g. "<case key>/reference" or "<case key>/replica-3"
    file    TEXT NOT NULL,         -- EXR beside the database, relative to its images folder
    height  INTEGER NOT NULL,
    width   INTEGER NOT NULL,
    channels INTEGER NOT NULL,
    finished REAL NOT NULL,
    sha256   TEXT                  -- of the EXR file's bytes: a damaged or replaced file is detected
);
CREATE TABLE IF NOT EXISTS measurements (
    case_key    TEXT NOT NULL,
    suite       TEXT NOT NULL,
    integrand   TEXT NOT NULL,
    technique   TEXT NOT NULL,
    measurement TEXT NOT NULL,
    value       REAL,
    lo          REAL,
    hi          REAL,
    n           INTEGER,
    pvalue      REAL,
    alpha       REAL,
    verdict     TEXT,
    detail      TEXT,
    UNIQUE (case_key, measurement)
);
"""

_UNIT_COLUMNS = "case_key, stream, budget, replica, chunk_begin, chunk_end, kind"


class Store:
    """One SQLite database file; safe to reopen after a crash."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.db = sqlite3.connect(self.path, isolation_level=None, timeout=60)
        self.db.execute("PRAGMA journal_mode=WAL")
        # WAL: a crash loses at most the last commits, never corrupts
        self.db.execute("PRAGMA synchronous=NORMAL")
        self.db.executescript(_SCHEMA)
        if "sha256" not in {r[1] for r in self.db.execute("PRAGMA table_info(images)")}:  # older databases
            self.db.execute("ALTER TABLE images ADD COLUMN sha256 TEXT")
        self._open = False

    def close(self) -> None:
        self.commit()
        self.db.close()

    # --- cases and units -------------------------------------------------------------------
    def add_case(self, case_key: str, suite: str, integrand: str, technique: str,
                 definition: dict[str, Any]) -> None:
        self.db.execute("INSERT OR IGNORE INTO cases VALUES (?, ?, ?, ?, ?)",
                        (case_key, suite, integrand, technique, json.dumps(definition, sort_keys=True)))

    def stored_keys(self, case_keys: Iterable[str]) -> set[Unit]:
        """The stored units of these cases."""
        keys: set[Unit] = set()
        for ck in set(case_keys):
            rows = self.db.execute(f"SELECT {_UNIT_COLUMNS} FROM units WHERE case_key = ?", (ck,))
            keys.update(Unit(*r) for r in rows)
        return keys

    def put(self, unit: Unit, payload: dict[str, Any], seconds: float) -> None:
        """Adds a unit's row to the open transaction (``commit`` makes it durable)."""
        if not self._open:
            self.db.execute("BEGIN")
            self._open = True
        self.db.execute("INSERT OR IGNORE INTO units VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                        (unit.case_key, unit.stream, unit.budget, unit.replica, unit.chunk_begin,
                         unit.chunk_end, unit.kind, json.dumps(payload), seconds, time.time()))

    def commit(self) -> None:
        if self._open:
            self.db.execute("COMMIT")
            self._open = False

    def payloads(self, case_key: str) -> dict[Unit, dict[str, Any]]:
        """The payload of each of the case's stored units."""
        rows = self.db.execute(f"SELECT {_UNIT_COLUMNS}, payload FROM units WHERE case_key = ?", (case_key,))
        return {Unit(*r[:7]): json.loads(r[7]) for r in rows}

    def seconds(self, case_key: str) -> dict[Unit, float]:
        """Wall time (s) of each of the case's stored units."""
        rows = self.db.execute(f"SELECT {_UNIT_COLUMNS}, seconds FROM units WHERE case_key = ?", (case_key,))
        return {Unit(*r[:7]): r[7] for r in rows}

    # --- images ----------------------------------------------------------------------------
    @property
    def image_dir(self) -> Path:
        return image_dir(self.path)

    def put_image(self, name: str, image: np.ndarray) -> Path:
        """Stores a float image (height, width[, channels]) as EXR and records it; returns the file."""
        self.image_dir.mkdir(parents=True, exist_ok=True)
        file = re.sub(r"[^A-Za-z0-9._-]", "_", name) + ".exr"
        final = self.image_dir / file
        a = write_exr(final, image)
        self.commit()
        self.db.execute("INSERT OR REPLACE INTO images (name, file, height, width, channels, finished, "
                        "sha256) VALUES (?, ?, ?, ?, ?, ?, ?)",
                        (name, file, a.shape[0], a.shape[1], a.shape[2], time.time(), _sha256(final)))
        return final

    def image_problem(self, name: str) -> str | None:
        """Why a stored image cannot be used (its file missing, or not the bytes written), naming
        the file; None if it is intact or was never stored."""
        row = self.db.execute("SELECT file, sha256 FROM images WHERE name = ?", (name,)).fetchone()
        if row is None:
            return None
        path = self.image_dir / row[0]
        if not path.is_file():
            return f"{path}: image missing"
        if row[1] is not None and _sha256(path) != row[1]:
            return f"{path}: image damaged (not the bytes stored)"
        return None

    def image(self, name: str) -> np.ndarray | None:
        """The stored image (height, width, channels) as float32, or None if none was stored;
        a missing or damaged file raises OSError naming it."""
        row = self.db.execute("SELECT file FROM images WHERE name = ?", (name,)).fetchone()
        if row is None:
            return None
        problem = self.image_problem(name)
        if problem:
            raise OSError(f"{problem}; rerun the suite to compute it again")
        return read_exr(self.image_dir / row[0])

    def drop_units(self, units: Iterable[Unit]) -> None:
        """Removes stored units (a damaged render, say), so the next plan computes them again."""
        self.commit()
        for u in units:
            self.db.execute(f"DELETE FROM units WHERE ({_UNIT_COLUMNS}) = (?, ?, ?, ?, ?, ?, ?)",
                            (u.case_key, u.stream, u.budget, u.replica, u.chunk_begin, u.chunk_end, u.kind))

    # --- measurements ------------------------------------------------------------------------
    def put_measurements(self, rows: list[dict[str, Any]]) -> None:
        self.commit()
        self.db.execute("BEGIN")
        for r in rows:
            self.db.execute("INSERT OR REPLACE INTO measurements "
                            "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                            (r["case_key"], r["suite"], r["integrand"], r["technique"], r["measurement"],
                             r.get("value"), r.get("lo"), r.get("hi"), r.get("n"), r.get("pvalue"),
                             r.get("alpha"), r.get("verdict"),
                             json.dumps(r.get("detail", {}), sort_keys=True, default=str)))
        self.db.execute("COMMIT")


def write_exr(path: Path, image: np.ndarray) -> np.ndarray:
    """Writes a float image (height, width[, channels]) as float32 EXR: to a temporary name,
    then renamed, so ``path`` is always a complete file.  Returns the array written."""
    import OpenImageIO as oiio  # only runs that store images need it

    a = np.asarray(image, dtype=np.float32)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[2] < 1:
        raise ValueError(f"'image' must have shape (height, width) or (height, width, channels), "
                         f"got {a.shape}")
    tmp = path.with_name(path.name + ".partial.exr")
    out = oiio.ImageOutput.create(str(tmp))
    if out is None or not out.open(str(tmp), oiio.ImageSpec(a.shape[1], a.shape[0], a.shape[2], "float")):
        raise OSError(f"cannot write {tmp}: {oiio.geterror()}")
    ok = out.write_image(np.ascontiguousarray(a))
    out.close()
    if not ok:
        raise OSError(f"cannot write {tmp}: {oiio.geterror()}")
    os.replace(tmp, path)
    return a


def read_exr(path: Path) -> np.ndarray:
    """An EXR image as float32 (height, width, channels); OSError naming a damaged file."""
    return read_image(path)


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def image_dir(db: str | Path) -> Path:
    """The folder of a database's images (EXR), beside it."""
    path = Path(db)
    return path.with_name(path.name + ".images")


def connect_read_only(db: str | Path) -> sqlite3.Connection:
    """A connection that never changes the database: read-only (no schema, no WAL switch), and
    immutable where SQLite cannot open it read-only otherwise (a read-only results folder).
    Raises FileNotFoundError for a missing file, ValueError naming the file for one that is not
    a SQLite database."""
    path = Path(db)
    if not path.is_file():
        raise FileNotFoundError(f"no results database at {path}")
    uri = path.resolve().as_uri()
    for flags in ("mode=ro", "mode=ro&immutable=1"):
        con = sqlite3.connect(f"{uri}?{flags}", uri=True)
        try:
            con.execute("SELECT name FROM sqlite_master LIMIT 1").fetchall()
            return con
        except sqlite3.DatabaseError as e:
            con.close()
            if not isinstance(e, sqlite3.OperationalError):  # not a database at all
                raise ValueError(f"{path} is not a results database ({e})") from None
            error = e
    raise ValueError(f"cannot read {path}: {error}")


def load(db: str | Path, suite: str | None = None) -> pd.DataFrame:
    """The stored measurements as a DataFrame: one row per case and measurement with its
    value, interval (lo, hi), sample count n, p-value, alpha and verdict.  Opens the database
    read-only: it never changes it."""
    con = connect_read_only(db)
    try:
        tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        if "measurements" not in tables:
            raise ValueError(f"{db} is not a results database (no measurements table)")
        query = "SELECT * FROM measurements" + (" WHERE suite = ?" if suite else "") + " ORDER BY rowid"
        return pd.read_sql_query(query, con, params=(suite,) if suite else ())
    finally:
        con.close()
