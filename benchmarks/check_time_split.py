"""Where a Mitsuba sampler check's time goes, beside Mitsuba's own ChiSquareTest on the same
plugin: the plugin's calls that the check makes, the check's own work, and a lower bound on
the plugin work its CDF tables need.  At 1e6 samples, seed 0, llvm_ad_rgb on the CPU; best of
--repeat runs, after an untimed run of each (drjit's JIT compilation in neither).

Columns (seconds unless stated):
  mitsuba   Mitsuba's ChiSquareTest (benchmarks/mitsuba_samplers.py's mitsuba_chi2)
  ours      check_mitsuba_sampler
  sample    the plugin's sample calls within ours
  pdf       the plugin's pdf calls within ours (every one, pdf and float32_pdf: the CDF
            tables', the chi-square cubature's, the drawn points', an area light's
            reported-pdf pass)
  tables    the Rosenblatt transform's tabulation (Transform.build), its pdf calls included
  points    the checks on the drawn points (SamplerTest.check_points), their pdf call included
  own       ours less sample and pdf: the check's own work (cubature bookkeeping included)
  floor     a lower bound on the plugin work that sampling and the CDF tables need: the 1e6
            sample calls timed alone plus the tables' pdf evaluations at the plugin's best
            rate (one float32_pdf call on the 1e6 directions it sampled, as float32 columns:
            no per-call overhead, no rounding pass).  Every
            check that tabulates the CDFs to the bound the transform tests carry pays it.
  table evals, other evals   the tables' pdf evaluations, and every other one of ours
Ours runs drjit's kernels on the sampler's ``check_threads`` workers (one for most plugins:
drjit's idle workers spin after each kernel, beside the check's own work); the floor and
Mitsuba's test run on drjit's own count (the plugin's best rate; Mitsuba's test as its users
run it).

    .venv/bin/python benchmarks/check_time_split.py [--only TEXT ...] [--all] [--repeat 3]
"""
from __future__ import annotations

import argparse
import contextlib
import functools
import os
import sys
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from mitsuba_samplers import mitsuba_chi2  # noqa: E402
from uniform_mc import best_of, cpu_line  # noqa: E402

import reference_estimators as rest  # noqa: E402

from harness.adapters.mitsuba.batch import UNIT_SLACK, float32_pdf_of  # noqa: E402
from harness.adapters.mitsuba.catalogue import catalogue  # noqa: E402
from harness.adapters.mitsuba.checks import check_mitsuba_sampler  # noqa: E402
from harness.adapters.mitsuba.runtime import use_libllvm  # noqa: E402
from harness.samplers.check import SamplerTest  # noqa: E402
from harness.samplers.transform import Transform  # noqa: E402

#: the entries measured by default: a spread of BSDFs, phase functions, an area light, an envmap
DEFAULT = ["diffuse θi=45°", "roughconductor ggx α=0.1 visible=True θi=45°",
           "roughconductor ggx α=0.5 visible=False θi=0°", "hg g=0.3 θi=60°", "rayleigh θi=60°",
           "microfacet ggx α=0.1 visible θi=45°", "roughplastic ggx α=0.1 θi=45°", "principled θi=45°",
           "area rectangle constant from (0, 0, 0)", "envmap 256x128 sky, sun with a soft rim"]
N = 1_000_000


class Split:
    """Seconds and pdf evaluations accumulated per key by the wrappers of :meth:`timing`; pdf
    evaluations made inside the tabulation count as "table evals", the others as "other evals"."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self.evals = {"table evals": 0, "other evals": 0}
        self.in_tables = False

    def wrap(self, key: str, fn: Callable[..., Any], columns: bool = False) -> Callable[..., Any]:
        """fn timed under ``key``; a pdf's evaluations counted from its last argument's rows
        (``columns``: its columns, float32_pdf's (3, N))."""
        @functools.wraps(fn)
        def timed(*args: Any, **kwargs: Any) -> Any:
            start = time.perf_counter()
            if key == "tables":
                self.in_tables = True
            try:
                return fn(*args, **kwargs)
            finally:
                if key == "tables":
                    self.in_tables = False
                self.seconds[key] = self.seconds.get(key, 0.0) + time.perf_counter() - start
                if key == "pdf":   # pdf(self, x): x (N, 3); float32_pdf(self, c): c (3, N)
                    n = args[-1].shape[1] if columns else len(args[-1])
                    self.evals["table evals" if self.in_tables else "other evals"] += n
        return timed

    @contextlib.contextmanager
    def timing(self, sampler: Any) -> Iterator[None]:
        """The sampler's sample and pdf calls, the tabulation and the point checks timed while
        inside (the class attributes restored after; the sampler's own class gets wrappers of
        what it inherits, removed after)."""
        cls = type(sampler)
        build = Transform.__dict__["build"].__func__
        patches = [(cls, "pdf", self.wrap("pdf", cls.pdf)),
                   (cls, "sample_batch", self.wrap("sample", cls.sample_batch)),   # under sample()
                   (Transform, "build", classmethod(self.wrap("tables", build))),
                   (SamplerTest, "check_points", self.wrap("points", SamplerTest.check_points))]
        # float32_pdf wrapped only where the check calls it (else pdf alone), and where it is a
        # method (a Mutant's is a property: its calls then count as the check's own work)
        if float32_pdf_of(sampler) is not None and callable(getattr(cls, "float32_pdf", None)):
            patches.append((cls, "float32_pdf", self.wrap("pdf", cls.float32_pdf, columns=True)))
        done = []
        try:
            for owner, name, value in patches:
                done.append((owner, name, owner.__dict__.get(name)))
                setattr(owner, name, value)
            yield
        finally:
            for owner, name, value in reversed(done):
                if value is None:
                    delattr(owner, name)   # inherited: the subclass's wrapper goes
                else:
                    setattr(owner, name, value)


def measure(entry: Any, repeat: int) -> dict[str, float]:
    sampler = entry.make()
    check_mitsuba_sampler(sampler, seed=0, sample_count=16384)   # compiles the plugin's kernels
    mitsuba_chi2(sampler, 16384, 0)
    splits = []
    for _ in range(repeat):
        split = Split()
        with split.timing(sampler):
            start = time.perf_counter()
            check_mitsuba_sampler(sampler, seed=0)
            split.seconds["ours"] = time.perf_counter() - start
        splits.append(split)
    split = min(splits, key=lambda s: s.seconds["ours"])
    row: dict[str, float] = {**split.seconds, **split.evals}
    row["mitsuba"] = min(mitsuba_chi2(sampler, N, 0)[1] for _ in range(repeat))
    row["own"] = row["ours"] - row.get("sample", 0.0) - row.get("pdf", 0.0)
    # the floor: the plugin's own time for the sample calls, and its best pdf rate (on all of
    # drjit's workers: the bound holds whatever the check's thread count)
    u = np.random.default_rng(0).random((N, sampler.udim))
    sample_alone = best_of(repeat, lambda: sampler.sample_batch(u))
    x = sampler.sample(u)
    x = x[np.all(np.isfinite(x), axis=1)]
    fast = float32_pdf_of(sampler)
    if fast is not None:   # as the tables' nodes reach the plugin
        columns, _ = rest.float32_unit_rows(x, UNIT_SLACK)
        rate = best_of(repeat, lambda: fast(columns)) / max(len(x), 1)
    else:
        rate = best_of(repeat, lambda: sampler.pdf(x)) / max(len(x), 1)
    row["floor"] = sample_alone + rate * row["table evals"]
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", nargs="*", default=None, help="entries whose label contains one of these")
    parser.add_argument("--all", action="store_true", help="every real plugin of the catalogue")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    use_libllvm()  # before drjit is imported
    entries = catalogue()
    if not args.all:
        wanted = args.only or DEFAULT
        missing = [w for w in wanted if not any(w in e.label for e in entries)]
        if missing:
            parser.error(f"no catalogue entry's label contains {missing}")
        entries = [e for e in entries if any(w in e.label for w in wanted)]
    print(f"CPU: {cpu_line()}")
    print(f"{N:.0e} samples, seed 0, llvm_ad_rgb, best of {args.repeat}; seconds")
    cols = ["mitsuba", "ours", "sample", "pdf", "tables", "points", "own", "floor"]
    print(f"{'entry':50s}" + "".join(f"{c:>9s}" for c in cols) + f"{'table evals':>13s}{'other evals':>13s}")
    rows = []
    for e in entries:
        row = measure(e, args.repeat)
        rows.append(row)
        print(f"{e.label[:50]:50s}" + "".join(f"{row.get(c, 0.0):9.3f}" for c in cols)
              + f"{row['table evals']:13d}{row['other evals']:13d}", flush=True)
    print(summary(rows))


def summary(rows: list[dict[str, float]]) -> str:
    """The issue's targets over the plugins measured: each column's median and sum, and how
    many plugins' own work is within 50 ms and whole check within 1x and 2x Mitsuba's test."""
    def col(c: str) -> np.ndarray:
        return np.array([r.get(c, 0.0) for r in rows])
    mitsuba, ours, own = col("mitsuba"), col("ours"), col("own")
    lines = [f"{len(rows)} plugins; median / sum (s):"]
    lines += [f"  {c:8s} {np.median(col(c)):.3f} / {col(c).sum():.2f}"
              for c in ("mitsuba", "ours", "own", "tables")]
    lines.append(f"  own work <= 50 ms: {int((own <= 0.05).sum())}; whole check <= Mitsuba's test: "
                 f"{int((ours <= mitsuba).sum())}, <= 2x: {int((ours <= 2 * mitsuba).sum())}")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
