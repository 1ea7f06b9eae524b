"""Where a Mitsuba sampler check's time goes, beside Mitsuba's own ChiSquareTest on the same
plugin: the plugin's calls that the check makes, the check's own work, and the floor those
calls set.  At 1e6 samples, seed 0, llvm_ad_rgb on the CPU; best of --repeat runs, after an
untimed run of each (drjit's JIT compilation in neither).

Columns (seconds unless stated):
  mitsuba   Mitsuba's ChiSquareTest (benchmarks/mitsuba_samplers.py's mitsuba_chi2)
  ours      check_mitsuba_sampler
  sample    the plugin's sample calls within ours
  pdf       the plugin's pdf calls within ours; 'evals' their points
  tables    the Rosenblatt transform's tabulation (Transform.build), its pdf calls included
  points    the checks on the drawn points (SamplerTest.check_points), their pdf call included
  own       ours less sample and pdf: the check's own work (cubature bookkeeping included)
  floor     what the plugin's calls cost at the rate its pdf reaches alone (batches of 65536
            directions it sampled): the sample calls, the pdf at the drawn points and the
            tabulation's evaluations.  Where the floor exceeds Mitsuba's whole test, no check
            that tabulates the CDFs to the bound the transform tests carry can match it.
The calls' own times within ours run beside drjit's worker threads, which spin after each
kernel (nanothread), so they exceed the floor's rate.

    .venv/bin/python benchmarks/check_time_split.py [--only TEXT ...] [--all] [--repeat 3]
"""
from __future__ import annotations

import argparse
import contextlib
import os
import sys
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from mitsuba_samplers import mitsuba_chi2  # noqa: E402

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
    """Seconds and calls accumulated per key by the wrappers of :meth:`timing`."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self.points: dict[str, int] = {}

    def wrap(self, key: str, fn: Callable[..., Any], count: bool = False) -> Callable[..., Any]:
        def timed(*args: Any, **kwargs: Any) -> Any:
            start = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self.seconds[key] = self.seconds.get(key, 0.0) + time.perf_counter() - start
                if count:
                    self.points[key] = self.points.get(key, 0) + len(args[-1])
        return timed

    @contextlib.contextmanager
    def timing(self, sampler: Any) -> Iterator[None]:
        """The sampler's sample and pdf calls, the tabulation and the point checks timed while
        inside (the class attributes restored after)."""
        cls = type(sampler)
        saved = [(cls, name, cls.__dict__.get(name)) for name in ("pdf", "sample_batch")]
        saved += [(Transform, "build", Transform.__dict__["build"]),
                  (SamplerTest, "check_points", SamplerTest.__dict__["check_points"])]
        try:
            cls.pdf = self.wrap("pdf", cls.pdf, count=True)
            cls.sample_batch = self.wrap("sample", cls.sample_batch)   # under sample and sample_with_pdf
            build = Transform.build
            Transform.build = classmethod(lambda _, *a, **k: self.wrap("tables", build)(*a, **k))
            SamplerTest.check_points = self.wrap("points", SamplerTest.check_points)
            yield
        finally:
            for owner, name, value in saved:
                if value is None:
                    delattr(owner, name)   # inherited: the subclass's wrapper goes
                else:
                    setattr(owner, name, value)


def best(repeat: int, fn: Callable[[], Any]) -> float:
    seconds = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        seconds.append(time.perf_counter() - start)
    return min(seconds)


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
    row = dict(split.seconds)
    row["evals"] = split.points.get("pdf", 0)
    row["mitsuba"] = min(mitsuba_chi2(sampler, N, 0)[1] for _ in range(repeat))
    row["own"] = row["ours"] - row.get("sample", 0.0) - row.get("pdf", 0.0)
    # the floor: the plugin's own rates, measured alone
    u = np.random.default_rng(0).random((N, sampler.udim))
    row["floor sample"] = best(repeat, lambda: sampler.sample_with_pdf(u))
    x = sampler.sample(u)
    x = x[np.all(np.isfinite(x), axis=1)]
    batch = x[:65536]
    rate = best(repeat, lambda: sampler.pdf(batch)) / max(len(batch), 1)
    row["floor"] = row["floor sample"] + rate * row["evals"]
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
        entries = [e for e in entries if any(w in e.label for w in wanted)]
    print(f"{N:.0e} samples, seed 0, llvm_ad_rgb, best of {args.repeat}; seconds")
    cols = ["mitsuba", "ours", "sample", "pdf", "tables", "points", "own", "floor"]
    print(f"{'entry':50s}" + "".join(f"{c:>9s}" for c in cols) + f"{'evals':>12s}")
    for e in entries:
        row = measure(e, args.repeat)
        print(f"{e.label[:50]:50s}" + "".join(f"{row.get(c, 0.0):9.3f}" for c in cols)
              + f"{row['evals']:12d}", flush=True)


if __name__ == "__main__":
    main()
