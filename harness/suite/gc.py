"""``harness gc``: prune what no suite's latest run needs, and repair a damaged database.

What a database keeps: the units each suite's latest run planned (the ``planned`` table),
the images those units and that run's measurements point at, the cached references its
render cases read (``run_keys``), every run's measurements (the history ``harness show
--all`` lists) and the cases they name.  Everything else (units of removed cases, of earlier
sample counts or spp, images no row points at, files left half-written by a kill, cached
references only this database's removed cases used) is removed, and the file is vacuumed.
A cached reference another database in the same folder may use is never touched: only
keys this database knows are candidates.

``repair`` is for a database SQLite cannot read (truncated, overwritten, "malformed"): the
damaged file is moved aside, a new one is written, and every row that can still be read is
copied into it.  Units lost this way are computed again by the next run.
"""
from __future__ import annotations

import json
import shutil
import sqlite3
import time
from dataclasses import dataclass
from pathlib import Path

from harness.suite.store import Store, StoreError, same_unit

__all__ = ["Collected", "Repaired", "collect_garbage", "repair"]

_UNPLANNED = f"FROM units WHERE NOT EXISTS (SELECT 1 FROM planned p WHERE {same_unit('p', 'units')})"


@dataclass(frozen=True)
class Collected:
    """What ``collect_garbage`` removed (or would remove, with ``dry_run``)."""

    db: Path
    units: int
    images: int
    files: int
    references: int
    cases: int
    bytes_before: int
    bytes_after: int
    dry_run: bool = False

    def __str__(self) -> str:
        verb = "would remove" if self.dry_run else "removed"
        freed = "" if self.dry_run else (f"; {self.db}: {self.bytes_before / 1e6:.2f} MB -> "
                                         f"{self.bytes_after / 1e6:.2f} MB")
        return (f"{verb} {self.units} units, {self.images} image rows, {self.files} files, "
                f"{self.references} cached references and {self.cases} cases no suite's latest run "
                f"needs{freed}")


def _size(db: Path) -> int:
    """Bytes of a database with its images, its WAL and shared-memory files."""
    files = [db, db.with_name(db.name + "-wal"), db.with_name(db.name + "-shm")]
    images = db.with_name(db.name + ".images")
    files += list(images.iterdir()) if images.is_dir() else []
    return sum(f.stat().st_size for f in files if f.is_file())


def collect_garbage(db: str | Path, *, dry_run: bool = False) -> Collected:
    """Removes units, images, files, cached references and cases no suite's latest run needs
    (see the module's docstring); ``dry_run`` counts them and changes nothing.  StoreError
    (one line naming the file) if the database cannot be used."""
    path = Path(db)
    if not path.is_file():
        raise StoreError(f"no results database at {path}")
    before = _size(path)
    store = Store(path)
    try:
        with store.translated():
            removed = _collect(store, dry_run)
        if not dry_run:
            store.db.execute("VACUUM")
            store.db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    finally:
        store.close()
    return Collected(path, *removed, before, _size(path), dry_run)


def _collect(store: Store, dry_run: bool) -> tuple[int, int, int, int, int]:
    db = store.db
    db.execute("BEGIN")
    latest = [r for (r,) in db.execute("SELECT MAX(run) FROM runs GROUP BY suite")]
    marks = ",".join("?" * len(latest))
    kept_keys = {k for (k,) in db.execute(f"SELECT case_key FROM run_keys WHERE run IN ({marks})", latest)}
    kept_keys |= {k for (k,) in db.execute("SELECT DISTINCT case_key FROM planned")}
    known_keys = {k for (k,) in db.execute("SELECT case_key FROM run_keys UNION SELECT case_key FROM units")}

    units = db.execute(f"SELECT COUNT(*) {_UNPLANNED}").fetchone()[0]
    db.execute(f"DELETE {_UNPLANNED}")
    # images: those the remaining render units point at, and the kept cases' reference/estimate/|t| map
    wanted = {json.loads(p).get("image")
              for (p,) in db.execute("SELECT payload FROM units WHERE kind = 'render'")}
    images = []
    for name, file in db.execute("SELECT name, file FROM images").fetchall():
        key, _, what = name.rpartition("/")
        if name not in wanted and not (what in ("reference", "estimate", "tmap") and key in kept_keys):
            images.append((name, file))
    db.executemany("DELETE FROM images WHERE name = ?", [(n,) for n, _ in images])
    cases = db.execute("SELECT case_key FROM cases WHERE case_key NOT IN (SELECT case_key FROM measurements)"
                       ).fetchall()
    cases = [k for (k,) in cases if k not in kept_keys]
    db.executemany("DELETE FROM cases WHERE case_key = ?", [(k,) for k in cases])
    db.execute(f"DELETE FROM run_keys WHERE run NOT IN ({marks})", latest)
    kept_files = {f for (f,) in db.execute("SELECT file FROM images")}
    db.execute("ROLLBACK" if dry_run else "COMMIT")

    folder = store.image_dir
    files = [f for f in folder.iterdir() if f.name not in kept_files] if folder.is_dir() else []
    refs = store.path.parent / "references"
    references = sorted({f.name.split("-")[0] for f in refs.iterdir()} & (known_keys - kept_keys)
                        ) if refs.is_dir() else []
    if not dry_run:
        for f in files:
            f.unlink()
        for key in references:
            for f in refs.glob(f"{key}-*"):
                f.unlink()
    return units, len(images), len(files), len(references), len(cases)


@dataclass(frozen=True)
class Repaired:
    """What ``repair`` did: where the damaged file went and the rows copied per table."""

    db: Path
    damaged: Path | None              # None: the database was readable, nothing was done
    rows: dict[str, int]
    lost: dict[str, str]              # table -> why its copy stopped early

    def __str__(self) -> str:
        if self.damaged is None:
            return f"{self.db}: intact (integrity check ok); nothing to repair"
        copied = ", ".join(f"{n} {t}" for t, n in self.rows.items()) or "nothing"
        why = sorted(set(self.lost.values()))
        lost = f"; unreadable: {', '.join(self.lost)} ({'; '.join(why)})" if self.lost else ""
        return (f"{self.db}: damaged file moved to {self.damaged}; copied {copied} into a new database"
                f"{lost}; the next run computes what was lost")


def _intact(path: Path) -> bool:
    with path.open("rb") as f:
        header = f.read(16)
    if header and header != b"SQLite format 3\x00":
        return False
    try:
        con = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True)
        try:
            return con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        finally:
            con.close()
    except sqlite3.Error:
        return False


def repair(db: str | Path) -> Repaired:
    """Checks ``db`` (PRAGMA integrity_check); if it is damaged, moves it (and its WAL) to
    ``<db>.damaged-<time>`` and copies every readable row of its tables into a new database
    at ``db``.  Image files are kept: their rows carry checksums, so a damaged one is
    rendered again."""
    path = Path(db)
    if not path.is_file():
        raise StoreError(f"no results database at {path}")
    if _intact(path):
        return Repaired(path, None, {}, {})
    damaged = path.with_name(f"{path.name}.damaged-{time.strftime('%Y%m%d-%H%M%S')}")
    shutil.move(path, damaged)
    for suffix in ("-wal", "-shm"):
        side = path.with_name(path.name + suffix)
        if side.exists():
            shutil.move(side, damaged.with_name(damaged.name + suffix))
    store = Store(path)   # a new database with the current schema
    rows: dict[str, int] = {}
    lost: dict[str, str] = {}
    try:
        old = sqlite3.connect(f"{damaged.resolve().as_uri()}?mode=ro", uri=True)
        tables = [t for (t,) in store.db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")]
        for table in tables:
            rows[table] = 0
            store.db.execute("BEGIN")
            try:
                cur = old.execute(f"SELECT * FROM {table}")
                width = len(cur.description)
                for row in cur:  # row by row: everything before the damaged page is kept
                    store.db.execute(f"INSERT OR IGNORE INTO {table} VALUES ({','.join('?' * width)})", row)
                    rows[table] += 1
            except sqlite3.Error as e:
                lost[table] = str(e)
            store.db.execute("COMMIT")
        old.close()
    finally:
        store.close()
    return Repaired(path, damaged, {t: n for t, n in rows.items() if n}, lost)
