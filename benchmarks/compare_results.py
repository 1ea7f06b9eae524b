"""Compare the stored measurements of two results databases, e.g. before and after a refactor.

    .venv/bin/python benchmarks/compare_results.py BEFORE.sqlite AFTER.sqlite

Rows are matched on (suite, integrand, technique, measurement); value, lo, hi, n, p-value,
verdict and detail must be equal bit for bit.  Measurements that are wall times by definition
(efficiency, equal-time relMSE) and the timing fields of details are left out.  Exits 1 and
lists every difference when there is one.  Both databases are opened read-only.
"""
from __future__ import annotations

import argparse
import json
import math
import sys

from harness.suite.readers import connect_read_only

TIMED = {"log10_efficiency", "efficiency_ratio", "efficiency", "equal_time_relmse"}
TIMING_FIELDS = {"seconds", "seconds_se", "error_vs_time", "rows", "log10_value", "notes"}
COLUMNS = ("value", "lo", "hi", "n", "pvalue", "alpha", "verdict")


def _rows(db: str) -> dict[tuple, tuple]:
    con = connect_read_only(db)
    try:
        query = (f"SELECT suite, integrand, technique, measurement, {', '.join(COLUMNS)}, detail "
                 "FROM measurements")
        return {r[:4]: r[4:] for r in con.execute(query)}
    finally:
        con.close()


def _untimed(d):
    if isinstance(d, dict):
        return {k: _untimed(v) for k, v in d.items() if k not in TIMING_FIELDS}
    return [_untimed(v) for v in d] if isinstance(d, list) else d


def _same(a, b) -> bool:
    both_nan = isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)
    return both_nan or a == b


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("before")
    parser.add_argument("after")
    args = parser.parse_args()
    a, b = _rows(args.before), _rows(args.after)
    differences = 0
    for key in sorted(a.keys() | b.keys()):
        if key not in a or key not in b:
            print(f"only in {'before' if key in a else 'after'}: {key}")
            differences += 1
            continue
        if key[3] in TIMED:
            continue
        for name, x, y in zip(COLUMNS, a[key], b[key]):
            if not _same(x, y):
                print(f"{key}: {name} {x!r} -> {y!r}")
                differences += 1
        dx, dy = (_untimed(json.loads(r[-1] or "{}")) for r in (a[key], b[key]))
        if dx != dy:
            print(f"{key}: detail differs")
            differences += 1
    print(f"{len(a)} rows before, {len(b)} after, {differences} differences")
    return 1 if differences else 0


if __name__ == "__main__":
    sys.exit(main())
