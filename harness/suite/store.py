"""Results storage: SQLite in WAL mode, one row per finished work unit.

A unit's row holds its complete accumulator state (JSON; Python's float repr round-trips
every double exactly) and is written inside a transaction under a UNIQUE key, so a run killed
at any point leaves only whole rows, and a rerun skips exactly the units already stored.
Each run of a suite is a row of ``runs`` (the suite file's revision, the harness that ran it,
when it started and finished); the measurements it computed are stored under its number, so
the readers (``load``, ``harness show``, ``harness report``) show each suite's latest finished
run, and older runs stay as history (``run=``, ``all_runs=``).  ``planned`` holds the units
the latest run of each suite needs: ``harness gc`` removes every other unit and image.
Images (renders, references) are files in a folder beside the database, lossless in the
precision they were computed in (EXR via OpenImageIO for float32, .npy otherwise), each written
to a temporary name and renamed before its row is committed, so a row always points at a
complete file; the row holds the file's size and SHA-256, so a damaged file is detected.
"""
from __future__ import annotations

import errno
import hashlib
import io
import json
import os
import re
import sqlite3
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from harness.adapters.base import read_image
from harness.fingerprint import harness_fingerprint
from harness.suite.plan import Unit

__all__ = ["Store", "StoreError", "RECORDED", "explain", "image_dir", "write_exr", "read_exr", "write_npy",
           "read_stored", "same_unit"]

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
    sha256   TEXT,                 -- of the file's bytes: a damaged or replaced file is detected
    bytes    INTEGER               -- the file's size
);
CREATE TABLE IF NOT EXISTS runs (
    run      INTEGER PRIMARY KEY,  -- 1, 2, ... in the order the runs started
    suite    TEXT NOT NULL,
    file     TEXT NOT NULL,        -- the suite file as given (or how the results were recorded)
    revision TEXT NOT NULL,        -- SHA-256 of the suite file's text: which edit of it was measured
    harness  TEXT NOT NULL,        -- the harness version and code fingerprint that ran it
    started  REAL NOT NULL,
    finished REAL,                 -- NULL while it runs, or if it was interrupted
    units_planned INTEGER,
    units_run     INTEGER,
    alpha    REAL,                 -- the false-alarm rate of the whole run ...
    families TEXT                  -- ... split evenly over these families of tests (JSON list)
);
CREATE TABLE IF NOT EXISTS planned (  -- the units the latest run of each suite needs
    suite       TEXT NOT NULL,
    case_key    TEXT NOT NULL,
    stream      INTEGER NOT NULL,
    budget      INTEGER NOT NULL,
    replica     INTEGER NOT NULL,
    chunk_begin INTEGER NOT NULL,
    chunk_end   INTEGER NOT NULL,
    kind        TEXT NOT NULL,
    UNIQUE (suite, case_key, stream, budget, replica, chunk_begin, chunk_end, kind)
);
CREATE TABLE IF NOT EXISTS run_keys (  -- the case keys each run registered (references included)
    run      INTEGER NOT NULL,
    case_key TEXT NOT NULL,
    UNIQUE (run, case_key)
);
CREATE TABLE IF NOT EXISTS measurements (
    run         INTEGER NOT NULL,  -- the run that computed it (runs.run)
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
    UNIQUE (run, case_key, measurement)
);
"""

RECORDED = "harness.record"   # the runs table's file of results recorded from Python
_UNIT_COLUMNS = "case_key, stream, budget, replica, chunk_begin, chunk_end, kind"


def same_unit(a: str, b: str) -> str:
    """SQL: the rows aliased ``a`` and ``b`` (of ``units`` or ``planned``) name the same unit."""
    return " AND ".join(f"{a}.{c} = {b}.{c}" for c in _UNIT_COLUMNS.split(", "))


class StoreError(RuntimeError):
    """A results database or image folder that cannot be used: one line naming the file and
    the cause (locked, disk full, corrupt, not writable)."""


def explain(error: BaseException, path: str | Path, timeout: float = 60) -> str:
    """One line naming ``path`` and what went wrong with it, from an SQLite or OS error."""
    msg = str(error)
    if isinstance(error, sqlite3.OperationalError) and ("locked" in msg or "busy" in msg):
        return (f"{path}: locked by another process for {timeout:g} s (another harness run on it?); "
                "wait for it to end or use another --db")
    if "disk is full" in msg or getattr(error, "errno", None) == errno.ENOSPC:
        return f"{path}: disk full ({msg}); free some space and rerun to resume"
    if isinstance(error, sqlite3.DatabaseError) and "not a database" in msg:
        return (f"{path} is not a results database, or it is damaged ({msg}): check the path, or run "
                f"`harness gc --repair --db {path}` (or delete it)")
    if isinstance(error, sqlite3.DatabaseError) and "malformed" in msg:
        return (f"{path}: corrupt results database ({msg}); run `harness gc --repair --db {path}` "
                "or delete it")
    if "readonly" in msg or isinstance(error, PermissionError):
        return f"{path}: not writable ({msg}); store the results elsewhere with --db"
    if isinstance(error, OSError) and error.filename:
        return f"{error.filename}: {error.strerror or msg}"
    return f"{path}: {msg}"


class Store:
    """One SQLite database file; safe to reopen after a crash.  Every SQLite or file-system
    error of opening it is a :class:`StoreError` naming the file; use :meth:`translated`
    around work on it for the same."""

    def __init__(self, path: str | Path, *, timeout: float = 60):
        self.path = Path(path)
        self.timeout = timeout
        self._open = False
        self.run: int | None = None   # the run in progress (start_run), if any
        self._decoded: dict[str, dict[Unit, dict[str, Any]]] = {}   # payloads() per case key
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:  # a parent that is a file, a read-only folder
            what = "a file, not a folder" if e.errno in (errno.EEXIST, errno.ENOTDIR) else e.strerror or e
            raise StoreError(f"{self.path}: cannot make its folder {self.path.parent}: {what}") from None
        with self.translated():
            self.db = sqlite3.connect(self.path, isolation_level=None, timeout=timeout)
            try:
                self.db.execute("PRAGMA journal_mode=WAL")
                # WAL: a crash loses at most the last commits, never corrupts
                self.db.execute("PRAGMA synchronous=NORMAL")
                _migrate(self.db)
                self.db.executescript(_SCHEMA)
            except BaseException:
                self.db.close()
                raise

    @contextmanager
    def translated(self) -> Iterator[None]:
        """SQLite and file-system errors inside become one-line :class:`StoreError`s."""
        try:
            yield
        except (sqlite3.Error, OSError) as e:  # the database, its images folder, the disk
            raise StoreError(explain(e, self.path, self.timeout)) from None

    def close(self, *, quiet: bool = False) -> None:
        """Commits what is open and closes; ``quiet``: after another error, never raise (an
        SQLite error that rolled the transaction back must not hide the first one)."""
        try:
            with self.translated():
                self.commit()
        except StoreError:
            if not quiet:
                raise
        finally:
            self.db.close()

    # --- runs ------------------------------------------------------------------------------
    def start_run(self, suite: str, file: str, revision: str, alpha: float | None = None,
                  families: tuple[str, ...] = ()) -> int:
        """Records a run of ``suite`` starting now (``alpha``: its false-alarm rate, split over
        ``families``); its planned units replace the suite's previous plan.  Returns its number."""
        self.commit()
        self.db.execute("BEGIN")
        self.db.execute("DELETE FROM planned WHERE suite = ?", (suite,))
        cur = self.db.execute("INSERT INTO runs (suite, file, revision, harness, started, alpha, families) "
                              "VALUES (?, ?, ?, ?, ?, ?, ?)",
                              (suite, file, revision, harness_fingerprint(), time.time(), alpha,
                               json.dumps(list(families))))
        self.db.execute("COMMIT")
        self.run = int(cur.lastrowid)
        return self.run

    def record_run(self, suite: str) -> int:
        """The run that results recorded from Python (harness.record) go to: the suite's latest
        run if it is a recording, else a new one.  ValueError for the name of a suite that a
        suite file ran here: a recording would replace its plan (harness gc then removes its
        units) and hide its results."""
        ran = self.db.execute("SELECT file FROM runs WHERE suite = ? AND file != ? LIMIT 1",
                              (suite, RECORDED)).fetchone()
        if ran is not None:
            raise ValueError(f"'suite': {suite!r} names the suite of {ran[0]} in {self.path}; record under "
                             "another name (a recording would replace that suite's plan and hide its "
                             "results)")
        row = self.db.execute("SELECT run, file FROM runs WHERE suite = ? ORDER BY run DESC LIMIT 1",
                              (suite,)).fetchone()
        if row is not None and row[1] == RECORDED:
            self.db.execute("UPDATE runs SET finished = ? WHERE run = ?", (time.time(), row[0]))
            return int(row[0])
        run = self.start_run(suite, RECORDED, "")
        self.db.execute("UPDATE runs SET finished = ? WHERE run = ?", (time.time(), run))
        return run

    def plan_units(self, suite: str, units: Iterable[Unit]) -> None:
        """Adds units to the suite's current plan (kept by ``harness gc``)."""
        self.commit()
        self.db.execute("BEGIN")
        self.db.executemany("INSERT OR IGNORE INTO planned VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                            [(suite, *u.row()) for u in units])
        self.db.execute("COMMIT")

    def finish_run(self, run: int, rows: list[dict[str, Any]], planned: int, ran: int) -> None:
        """Stores the run's measurements under its number and marks it finished, in one
        transaction, so its rows are shown only once all are stored."""
        self.commit()
        self.db.execute("BEGIN")
        self.db.execute("UPDATE runs SET finished = ?, units_planned = ?, units_run = ? WHERE run = ?",
                        (time.time(), planned, ran, run))
        self._write_measurements(rows, run)
        self.db.execute("COMMIT")

    # --- cases and units -------------------------------------------------------------------
    def add_case(self, case_key: str, suite: str, integrand: str, technique: str,
                 definition: dict[str, Any]) -> None:
        self.db.execute("INSERT OR IGNORE INTO cases VALUES (?, ?, ?, ?, ?)",
                        (case_key, suite, integrand, technique, json.dumps(definition, sort_keys=True)))
        self.use_key(case_key)

    def use_key(self, case_key: str) -> None:
        """Records that the current run reads units, images or cached data under ``case_key``."""
        if self.run is not None:
            self.db.execute("INSERT OR IGNORE INTO run_keys VALUES (?, ?)", (self.run, case_key))

    def stored_keys(self, case_keys: Iterable[str]) -> set[Unit]:
        """The stored units of these cases (another process may have stored some since)."""
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
        cached = self.payloads(unit.case_key)   # the rows stored so far, decoded while workers run
        text = json.dumps(payload)
        cur = self.db.execute("INSERT OR IGNORE INTO units VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                              (*unit.row(), text, seconds, time.time()))
        if cur.rowcount == 1:
            cached[unit] = json.loads(text)

    def commit(self) -> None:
        if self._open:
            self._open = False
            if self.db.in_transaction:  # SQLite rolls back by itself on some errors (disk full)
                self.db.execute("COMMIT")

    def payloads(self, case_key: str) -> dict[Unit, dict[str, Any]]:
        """The payload of each of the case's stored units: the same dicts, to read, not change.
        Decoded once and kept as units are put (``put`` runs in the runner's main thread while
        its workers compute, so the analysis after them finds its payloads decoded), read
        again where the store holds rows this connection did not put (another process's)."""
        cached = self._decoded.get(case_key)
        if cached is not None and self.db.execute("SELECT COUNT(*) FROM units WHERE case_key = ?",
                                                  (case_key,)).fetchone()[0] == len(cached):
            return cached
        rows = self.db.execute(f"SELECT {_UNIT_COLUMNS}, payload FROM units WHERE case_key = ?", (case_key,))
        self._decoded[case_key] = decoded = {Unit(*r[:7]): json.loads(r[7]) for r in rows}
        return decoded

    def seconds(self, case_key: str) -> dict[Unit, float]:
        """Wall time (s) of each of the case's stored units."""
        rows = self.db.execute(f"SELECT {_UNIT_COLUMNS}, seconds FROM units WHERE case_key = ?", (case_key,))
        return {Unit(*r[:7]): r[7] for r in rows}

    # --- images ----------------------------------------------------------------------------
    @property
    def image_dir(self) -> Path:
        return image_dir(self.path)

    def put_image(self, name: str, image: np.ndarray) -> Path:
        """Stores a float image (height, width[, channels]) losslessly and records it with its
        size and checksum; returns the file.  Float32 values (what renderers produce, float64
        arrays of float32 values included) go to EXR; others, a float64 mean say, to .npy."""
        self.image_dir.mkdir(parents=True, exist_ok=True)
        a = np.asarray(image)
        a = a[:, :, None] if a.ndim == 2 else a
        exact32 = np.array_equal(a.astype(np.float32).astype(a.dtype), a, equal_nan=True)
        file = re.sub(r"[^A-Za-z0-9._-]", "_", name) + (".exr" if exact32 else ".npy")
        final = self.image_dir / file
        a = write_exr(final, a) if exact32 else write_npy(final, a)
        self.commit()
        self.db.execute("INSERT OR REPLACE INTO images (name, file, height, width, channels, finished, "
                        "sha256, bytes) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                        (name, file, a.shape[0], a.shape[1], a.shape[2], time.time(), _sha256(final),
                         final.stat().st_size))
        return final

    def image_problem(self, name: str) -> str | None:
        """Why a stored image cannot be used (its file missing, truncated, or not the bytes
        written), naming the file; None if it is intact or was never stored."""
        row = self.db.execute("SELECT file, sha256, bytes FROM images WHERE name = ?", (name,)).fetchone()
        if row is None:
            return None
        path = self.image_dir / row[0]
        if not path.is_file():
            return f"{path}: image missing"
        if row[2] is not None and path.stat().st_size != row[2]:
            return f"{path}: image damaged ({path.stat().st_size} bytes, {row[2]} stored)"
        if row[1] is not None and _sha256(path) != row[1]:
            return f"{path}: image damaged (not the bytes stored)"
        return None

    def image(self, name: str) -> np.ndarray | None:
        """The stored image (height, width, channels) in the precision it was stored in, or
        None if none was stored; a missing or damaged file raises OSError naming it."""
        row = self.db.execute("SELECT file FROM images WHERE name = ?", (name,)).fetchone()
        if row is None:
            return None
        problem = self.image_problem(name)
        if problem:
            raise OSError(f"{problem}; rerun the suite to compute it again")
        return read_stored(self.image_dir / row[0])

    def drop_units(self, units: Iterable[Unit]) -> None:
        """Removes stored units (a damaged render, say), so the next plan computes them again."""
        self.commit()
        for u in units:
            self.db.execute(f"DELETE FROM units WHERE ({_UNIT_COLUMNS}) = (?, ?, ?, ?, ?, ?, ?)", u.row())
            self._decoded.pop(u.case_key, None)

    # --- measurements ------------------------------------------------------------------------
    def put_measurements(self, rows: list[dict[str, Any]], *, run: int) -> None:
        """Stores measurement rows under run ``run`` (a row of a case and measurement already
        stored in that run is replaced)."""
        self.commit()
        self.db.execute("BEGIN")
        self._write_measurements(rows, run)
        self.db.execute("COMMIT")

    def _write_measurements(self, rows: list[dict[str, Any]], run: int) -> None:
        for r in rows:
            self.db.execute("INSERT OR REPLACE INTO measurements "
                            "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                            (run, r["case_key"], r["suite"], r["integrand"], r["technique"], r["measurement"],
                             r.get("value"), r.get("lo"), r.get("hi"), r.get("n"), r.get("pvalue"),
                             r.get("alpha"), r.get("verdict"),
                             json.dumps(r.get("detail", {}), sort_keys=True, default=str)))


def _table(name: str) -> str:
    """The CREATE TABLE statement of one table of the schema."""
    return re.search(rf"CREATE TABLE IF NOT EXISTS {name} \(.*?\n\);", _SCHEMA, re.S).group(0)


def _migrate(db: sqlite3.Connection) -> None:
    """Brings a database written before runs were recorded up to the current schema: its
    measurements become one run per suite (file "(before runs were recorded)"); images get
    their checksum column."""
    columns = {t: {r[1] for r in db.execute(f"PRAGMA table_info({t})")} for t in ("measurements", "images")}
    columns["runs"] = {r[1] for r in db.execute("PRAGMA table_info(runs)")}
    for table, column, kind in (("images", "sha256", "TEXT"), ("images", "bytes", "INTEGER"),
                                ("runs", "alpha", "REAL"), ("runs", "families", "TEXT")):
        if columns[table] and column not in columns[table]:
            db.execute(f"ALTER TABLE {table} ADD COLUMN {column} {kind}")
    if not columns["measurements"] or "run" in columns["measurements"]:
        return
    db.execute("BEGIN")
    db.execute("ALTER TABLE measurements RENAME TO measurements_before_runs")
    db.execute(_table("measurements"))
    db.execute(_table("runs"))
    for (suite,) in db.execute("SELECT DISTINCT suite FROM measurements_before_runs").fetchall():
        run = db.execute("INSERT INTO runs (suite, file, revision, harness, started, finished) "
                         "VALUES (?, '(before runs were recorded)', '', '', 0, 0)", (suite,)).lastrowid
        db.execute("INSERT INTO measurements SELECT ?, * FROM measurements_before_runs WHERE suite = ? "
                   "ORDER BY rowid", (run, suite))
    db.execute("DROP TABLE measurements_before_runs")
    db.execute("COMMIT")


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


def write_npy(path: Path, a: np.ndarray) -> np.ndarray:
    """Writes an array as .npy: serialised in memory, written to a temporary name, then
    renamed.  (np.save on a file turns a Ctrl-C inside its write into a TypeError.)  Returns it."""
    buffer = io.BytesIO()
    np.save(buffer, a, allow_pickle=False)
    tmp = path.with_name(path.name + ".partial.npy")
    tmp.write_bytes(buffer.getvalue())
    os.replace(tmp, path)
    return a


def read_stored(path: Path) -> np.ndarray:
    """A stored image (EXR as float32, .npy in its own precision), (height, width, channels);
    OSError naming a missing or damaged file."""
    if path.suffix != ".npy":
        return read_exr(path)
    try:
        return np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as e:
        raise OSError(f"cannot read image {path}: {e}") from None


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def image_dir(db: str | Path) -> Path:
    """The folder of a database's images (EXR), beside it."""
    path = Path(db)
    return path.with_name(path.name + ".images")
