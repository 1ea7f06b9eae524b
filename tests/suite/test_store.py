"""The results store (harness.suite.store): unit rows, images and measurements round trip
exactly, a row is visible only once committed, a key is written once, and a rerun reopens
the same file.

Images are drawn from numpy's default_rng(0) (seed fixed before writing the test)."""
from __future__ import annotations

import math
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from harness.suite.plan import Unit
from harness.suite.readers import load
from harness.suite.store import Store, read_exr, write_exr

A = Unit("case-a", 0, 4096, 3, 0, 1, "state")
B = Unit("case-a", 0, 4096, 0, 0, 0, "tail")
C = Unit("case-b", 2, 1024, 1, 0, 1, "state")
# doubles that a lossy encoding would change: 1/3, the smallest subnormal, the largest double, -0.0
PAYLOAD = {"mean": 1 / 3, "m2": 0.1 + 0.2, "tiny": 5e-324, "big": 1.7976931348623157e308, "neg_zero": -0.0,
           "count": 2**53 + 1, "inf": math.inf, "list": [0.1, -2.5e-300], "nested": {"x": [1, 2.0]}}


def same(a: object, b: object) -> bool:
    """Equal down to the bits of every float (-0.0 is not 0.0, NaN equals NaN)."""
    if isinstance(a, float) and isinstance(b, float):
        return a.hex() == b.hex() or (math.isnan(a) and math.isnan(b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    return type(a) is type(b) and a == b


# --- unit rows ---------------------------------------------------------------------------------
def test_payloads_and_seconds_round_trip_bitwise_through_a_reopen(tmp_path):
    store = Store(tmp_path / "r.sqlite")
    store.put(A, {**PAYLOAD, "nan": math.nan}, 1 / 3)
    store.put(B, {"tail": [3.0, 1e-12]}, 0.25)
    store.put(C, {"mean": 2.0}, 7.0)
    store.commit()
    for s in (store, Store(tmp_path / "r.sqlite")):
        payloads = s.payloads("case-a")
        assert set(payloads) == {A, B} and same(payloads[A], {**PAYLOAD, "nan": math.nan})
        assert payloads[B] == {"tail": [3.0, 1e-12]}
        assert s.seconds("case-a") == {A: 1 / 3, B: 0.25} and s.seconds("case-b") == {C: 7.0}
        assert s.stored_keys(["case-a"]) == {A, B}
        assert s.stored_keys(["case-a", "case-b", "none"]) == {A, B, C}
        assert s.payloads("none") == {} and s.stored_keys([]) == set()
        s.close()


def test_rows_are_visible_to_another_reader_only_once_committed(tmp_path):
    writer, reader = Store(tmp_path / "r.sqlite"), Store(tmp_path / "r.sqlite")
    writer.put(A, {"mean": 1.0}, 1.0)
    assert reader.stored_keys(["case-a"]) == set()
    writer.commit()
    assert reader.stored_keys(["case-a"]) == {A}
    writer.close()
    reader.close()


def test_payloads_kept_as_units_are_put_and_read_again_where_another_store_added_rows(tmp_path):
    one, other = Store(tmp_path / "r.sqlite"), Store(tmp_path / "r.sqlite")
    one.put(A, {"mean": 1.0}, 1.0)
    assert one.payloads("case-a") == {A: {"mean": 1.0}}
    first = one.payloads("case-a")
    one.put(A, {"mean": 9.0}, 1.0)                        # a unit is written once: the first stays
    assert one.payloads("case-a") is first and first == {A: {"mean": 1.0}}
    one.commit()
    other.put(B, {"tail": [2.0]}, 1.0)                     # another process's row
    other.commit()
    assert one.payloads("case-a") == {A: {"mean": 1.0}, B: {"tail": [2.0]}}
    one.drop_units([B])
    assert one.payloads("case-a") == {A: {"mean": 1.0}}
    one.close()
    other.close()


def test_close_commits_the_open_transaction(tmp_path):
    store = Store(tmp_path / "r.sqlite")
    store.put(A, {"mean": 1.0}, 1.0)
    store.close()
    again = Store(tmp_path / "r.sqlite")
    assert again.stored_keys(["case-a"]) == {A}
    again.close()


def test_a_process_that_dies_before_commit_leaves_only_its_committed_rows(tmp_path):
    db = tmp_path / "r.sqlite"
    code = ("import os, sys\nfrom harness.suite.plan import Unit\nfrom harness.suite.store import Store\n"
            "s = Store(sys.argv[1])\ns.put(Unit('case-a', 0, 1, 0, 0, 1, 'state'), {'mean': 1.0}, 1.0)\n"
            "s.commit()\ns.put(Unit('case-a', 0, 1, 1, 0, 1, 'state'), {'mean': 2.0}, 1.0)\nos._exit(0)\n")
    r = subprocess.run([sys.executable, "-c", code, str(db)], capture_output=True, text=True, timeout=120,
                       check=False)
    assert r.returncode == 0, r.stderr
    store = Store(db)
    assert store.payloads("case-a") == {Unit("case-a", 0, 1, 0, 0, 1, "state"): {"mean": 1.0}}
    store.close()


def test_a_unit_is_stored_once_and_the_first_row_wins(tmp_path):
    store = Store(tmp_path / "r.sqlite")
    store.put(A, {"mean": 1.0}, 1.0)
    store.put(A, {"mean": 2.0}, 2.0)      # same transaction
    store.commit()
    store.put(A, {"mean": 3.0}, 3.0)      # a later one
    store.put(replace(A, kind="tail"), {"mean": 4.0}, 4.0)   # another kind: another unit
    store.close()
    again = Store(tmp_path / "r.sqlite")
    assert again.payloads("case-a") == {A: {"mean": 1.0}, replace(A, kind="tail"): {"mean": 4.0}}
    assert again.seconds("case-a")[A] == 1.0
    again.close()


def test_a_store_makes_its_folder_and_reopens_after_close(tmp_path):
    path = tmp_path / "deep" / "er" / "r.sqlite"
    store = Store(path)
    store.put(C, {"mean": 2.0}, 1.0)
    store.close()
    for _ in range(2):   # opening again re-runs the schema without touching the rows
        again = Store(path)
        assert again.payloads("case-b") == {C: {"mean": 2.0}}
        again.close()


# --- images ----------------------------------------------------------------------------------
def test_exr_round_trips_float32_exactly_including_faults(tmp_path):
    a = np.random.default_rng(0).random((5, 7, 3)).astype(np.float32)
    a[0, 0], a[4, 6, 2] = [np.inf, np.nan, -1.0], np.float32(1e-42)   # a fault, a subnormal
    path = tmp_path / "x.exr"
    written = write_exr(path, a)
    b = read_exr(path)
    assert b.dtype == np.float32 and b.shape == (5, 7, 3) and np.array_equal(a, b, equal_nan=True)
    assert np.array_equal(written, a, equal_nan=True) and [p.name for p in tmp_path.iterdir()] == ["x.exr"]


def test_exr_stores_doubles_as_float32_and_gray_as_one_channel(tmp_path):
    x = np.random.default_rng(0).random((4, 6))   # float64, (h, w)
    write_exr(tmp_path / "g.exr", x)
    b = read_exr(tmp_path / "g.exr")
    assert b.shape == (4, 6, 1) and np.array_equal(b[:, :, 0], x.astype(np.float32))
    with pytest.raises(ValueError, match=r"'image' must have shape \(height, width\) or \(height, width, "
                                         r"channels\), got \(2, 3, 4, 5\)"):
        write_exr(tmp_path / "bad.exr", np.zeros((2, 3, 4, 5)))
    assert not (tmp_path / "bad.exr").exists()


def test_a_stored_image_is_replaced_under_its_name(tmp_path):
    rng = np.random.default_rng(0)
    first, second = rng.random((2, 3, 4, 3)).astype(np.float32)
    store = Store(tmp_path / "r.sqlite")
    store.put_image("case/replica 1", first)
    store.put_image("case/replica 1", second)
    store.close()
    again = Store(tmp_path / "r.sqlite")
    assert np.array_equal(again.image("case/replica 1"), second) and again.image("case/replica 2") is None
    again.close()


def test_images_are_stored_losslessly_in_their_precision_with_size_and_checksum(tmp_path):
    store = Store(tmp_path / "r.sqlite")
    mean = np.random.default_rng(1).random((3, 5, 3))             # a float64 mean: kept as float64
    rendered = mean.astype(np.float32).astype(np.float64)        # float32 values in a float64 array
    rendered[0, 0, 0] = np.nan
    files = [store.put_image(n, a) for n, a in (("k/mean", mean), ("k/render", rendered))]
    assert [f.suffix for f in files] == [".npy", ".exr"]
    assert store.image("k/mean").dtype == np.float64 and np.array_equal(store.image("k/mean"), mean)
    assert np.array_equal(store.image("k/render"), rendered, equal_nan=True)
    files[0].write_bytes(files[0].read_bytes()[:-8])
    assert store.image_problem("k/mean") == f"{files[0]}: image damaged ({files[0].stat().st_size} bytes, " \
                                            f"{files[0].stat().st_size + 8} stored)"
    with pytest.raises(OSError, match="image damaged"):
        store.image("k/mean")
    store.close()


# --- measurements ------------------------------------------------------------------------------
def row(measurement: str, value: float, suite: str = "s", key: str = "case-a", **extra) -> dict:
    return {"case_key": key, "suite": suite, "integrand": "gaussian", "technique": "uniform",
            "measurement": measurement, "value": value, **extra}


def finished_run(store: Store, rows: list[dict], suite: str = "s") -> int:
    """Stores rows as one finished run of ``suite``; returns its number."""
    run = store.start_run(suite, f"{suite}.toml", "revision")
    store.finish_run(run, rows, 0, 0)
    return run


def test_measurements_are_replaced_per_case_and_measurement(tmp_path):
    store = Store(tmp_path / "r.sqlite")
    run = store.start_run("s", "s.toml", "revision")
    store.put_measurements([row("bias", 0.1, lo=-0.2, hi=0.4, n=1000, pvalue=0.5, alpha=0.01,
                                verdict="unbiased", detail={"z": 1, "a": [2]}), row("variance", 2.0)],
                           run=run)
    store.finish_run(run, [row("bias", 1 / 3, verdict="biased")], 0, 0)
    finished_run(store, [row("bias", 5.0, suite="t", key="case-b")], suite="t")
    store.close()
    df = load(tmp_path / "r.sqlite", "s")
    assert list(df["measurement"]) == ["variance", "bias"]   # the replaced row is a new one
    bias = df[df["measurement"] == "bias"].iloc[0]
    assert bias["value"] == 1 / 3 and bias["verdict"] == "biased" and bias["detail"] == "{}"
    assert pd.isna(bias["lo"]) and pd.isna(bias["pvalue"])   # absent fields are NULL, not kept
    assert len(load(tmp_path / "r.sqlite")) == 3 and list(load(tmp_path / "r.sqlite", "t")["value"]) == [5.0]


def test_measurement_details_are_stored_as_sorted_json(tmp_path):
    store = Store(tmp_path / "r.sqlite")
    finished_run(store, [row("bias", 0.0, detail={"z": 1, "a": [2], "p": Path("x")})])
    store.close()
    assert load(tmp_path / "r.sqlite")["detail"].tolist() == ['{"a": [2], "p": "x", "z": 1}']


def test_load_of_a_missing_database_raises_and_creates_nothing(tmp_path):
    path = tmp_path / "none.sqlite"
    with pytest.raises(FileNotFoundError, match=re.escape(f"no results database at {path}")):
        load(path)
    assert not path.exists()


def test_load_and_show_never_change_a_database(tmp_path):
    """`harness.load` and `harness show` open read-only: an unrelated SQLite file keeps its bytes,
    tables and journal mode, and is refused with a one-line error naming it; so is a garbage file."""
    import sqlite3
    import subprocess
    import sys

    other = tmp_path / "other.sqlite"
    con = sqlite3.connect(other)
    con.execute("CREATE TABLE notes (text TEXT)")
    con.execute("INSERT INTO notes VALUES ('kept')")
    con.commit()
    con.close()
    before = other.read_bytes()
    with pytest.raises(ValueError,
                       match=r"other\.sqlite is not a results database \(no measurements table\)"):
        load(other)
    harness_cli = Path(sys.executable).with_name("harness")
    r = subprocess.run([str(harness_cli), "show", "--db", str(other)], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 2 and "is not a results database" in r.stderr and "Traceback" not in r.stderr
    assert other.read_bytes() == before
    con = sqlite3.connect(other)
    assert con.execute("PRAGMA journal_mode").fetchone()[0] == "delete"
    assert [t for (t,) in con.execute("SELECT name FROM sqlite_master")] == ["notes"]
    con.close()

    garbage = tmp_path / "garbage.sqlite"
    garbage.write_bytes(b"not a database at all, just bytes" * 100)
    with pytest.raises(ValueError, match=r"garbage\.sqlite is not a results database"):
        load(garbage)
    assert garbage.read_bytes() == b"not a database at all, just bytes" * 100


def test_load_reads_a_results_database_without_writing_it(tmp_path):
    db = tmp_path / "r.sqlite"
    store = Store(db)
    finished_run(store, [{"case_key": "k", "suite": "s", "integrand": "gaussian", "technique": "uniform",
                          "measurement": "bias", "value": 0.5, "n": 10}])
    store.close()
    for extra in tmp_path.glob("r.sqlite-*"):  # checkpointed and closed: only the main file matters
        extra.unlink()
    before = db.read_bytes()
    df = load(db)
    assert list(df["value"]) == [0.5] and db.read_bytes() == before
