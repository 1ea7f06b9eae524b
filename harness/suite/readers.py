"""Reading a results database without changing it: the connection (read-only, immutable where
the folder is read-only), the choice of runs (each suite's latest finished run, one run, or all),
the measurements and runs as DataFrames, and how far an interrupted run's plan got.
"""
from __future__ import annotations

import sqlite3
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from harness.suite.store import explain, same_unit

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["connect_read_only", "run_filter", "plan_progress", "reading", "load", "runs"]


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
            if not isinstance(e, sqlite3.OperationalError):  # not a database at all, or damaged
                raise ValueError(explain(e, path)) from None
            error = e
    raise ValueError(f"cannot read {path}: {error}")


def run_filter(con: sqlite3.Connection, db: str | Path, *, suite: str | None = None, run: int | None = None,
               all_runs: bool = False) -> tuple[str, tuple[Any, ...]]:
    """A WHERE clause (and its parameters) choosing measurement rows ``m``: of each suite's
    latest finished run by default, of run ``run``, or of every run (``all_runs``); of one
    suite if ``suite`` is given.  ValueError naming the runs (suites) there are for an unknown
    run (suite)."""
    tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    if "measurements" not in tables:
        raise ValueError(f"{db} is not a results database (no measurements table)")
    where: list[str] = []
    params: list[Any] = []
    if suite:
        # a suite is known by its measurements, or by a run (one still running or interrupted)
        named = "SELECT suite FROM measurements" + (" UNION SELECT suite FROM runs" if "runs" in tables
                                                    else "")
        known = [s for (s,) in con.execute(f"SELECT DISTINCT suite FROM ({named}) ORDER BY suite")]
        if suite not in known:
            raise ValueError(f"{db} has no suite {suite!r}; its suites: {', '.join(known) or 'none'}")
        where.append("m.suite = ?")
        params.append(suite)
    if "runs" in tables and run is not None:
        if con.execute("SELECT 1 FROM runs WHERE run = ?", (run,)).fetchone() is None:
            known = [r for (r,) in con.execute("SELECT run FROM runs ORDER BY run")]
            raise ValueError(f"{db} has no run {run}; its runs: {', '.join(map(str, known)) or 'none'}")
        where.append("m.run = ?")
        params.append(run)
    elif "runs" in tables and not all_runs:
        where.append("m.run IN (SELECT MAX(run) FROM runs WHERE finished IS NOT NULL GROUP BY suite)")
    return (" WHERE " + " AND ".join(where) if where else ""), tuple(params)


def plan_progress(db: str | Path, suite: str) -> tuple[int, int]:
    """(units stored, units planned) of the current plan of ``suite`` in ``db``, counted in
    the database (what an interrupted run leaves); (0, 0) if nothing was planned yet."""
    try:
        with reading(db) as con:
            planned = con.execute("SELECT COUNT(*) FROM planned WHERE suite = ?", (suite,)).fetchone()[0]
            stored = con.execute("SELECT COUNT(*) FROM planned p WHERE p.suite = ? AND EXISTS (SELECT 1 FROM "
                                 f"units u WHERE {same_unit('u', 'p')})", (suite,)).fetchone()[0]
    except (FileNotFoundError, ValueError):
        return 0, 0
    return int(stored), int(planned)


@contextmanager
def reading(db: str | Path) -> Iterator[sqlite3.Connection]:
    """A read-only connection (:func:`connect_read_only`), closed after; an SQLite error while
    reading (a truncated or corrupt file) becomes a ValueError naming the file and the cause."""
    con = connect_read_only(db)
    try:
        yield con
    except sqlite3.Error as e:
        raise ValueError(explain(e, db)) from None
    finally:
        con.close()


def load(db: str | Path, suite: str | None = None, *, run: int | None = None,
         all_runs: bool = False) -> pd.DataFrame:
    """The stored measurements as a DataFrame: one row per case and measurement with its
    value, interval (lo, hi), sample count n, p-value, alpha, verdict and the run that
    measured it.  By default each suite's latest finished run only (what the suite file
    measures now); ``run=`` one run, ``all_runs=True`` the whole history.  Opens the database
    read-only: it never changes it."""
    import pandas as pd  # deferred, as in harness.suite.kind.Outcome.frame
    with reading(db) as con:
        where, params = run_filter(con, db, suite=suite, run=run, all_runs=all_runs)
        return pd.read_sql_query(f"SELECT * FROM measurements m{where} ORDER BY m.rowid", con, params=params)


def runs(db: str | Path) -> pd.DataFrame:
    """The runs a database has seen: number, suite, file, revision, harness, started and
    finished (UTC; finished empty for a run that was interrupted or still runs), units
    planned and computed, measurements stored.  Read-only."""
    import pandas as pd  # deferred, as in harness.suite.kind.Outcome.frame
    with reading(db) as con:
        if con.execute("SELECT 1 FROM sqlite_master WHERE name = 'runs'").fetchone() is None:
            return pd.DataFrame()
        df = pd.read_sql_query("SELECT r.*, (SELECT COUNT(*) FROM measurements m WHERE m.run = r.run) AS "
                               "measurements FROM runs r ORDER BY r.run", con)
    for col in ("started", "finished"):
        df[col] = pd.to_datetime(df[col], unit="s", utc=True).dt.strftime("%Y-%m-%d %H:%M:%S").fillna("")
    df["revision"] = df["revision"].str[:12]
    return df
