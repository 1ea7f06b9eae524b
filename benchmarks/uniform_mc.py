"""Uniform Monte Carlo of exp(-x^2) on [0, 1]: Msamples/s of the core against numpy and drjit,
and where each one's time goes.

All three draw float64 uniforms, evaluate exp(-x^2) in float64 and reduce:
  core   reference_estimators.integrate: PCG32 chunk streams, 52-bit uniforms, compensated
         sum, M2..M4 moments and NaN/Inf/negative screening (what the harness really runs)
  numpy  Generator.random + np.exp + np.sum over 4M-sample batches (numpy is one thread)
  drjit  drjit.llvm PCG32.next_float64 + dr.exp + dr.sum, one fused LLVM kernel, float64
Timings: best of `--repeat` runs after a warm-up (drjit's kernel compilation excluded); the 1-
and 2-thread runs alternate, so a drift in the machine's speed does not pose as scaling.

It prints the CPU, the ISA the core was built for and the one its kernels run (there is no
runtime dispatch: the build's), the chunk count and size, each thread's busy time, and a
stage profile in ns per sample and thread:
  core   points (PCG32 uniforms) | integrand (exp, the select) | screening and accumulation,
         from reference_estimators' profile_stages (each prefix of the pipeline timed alone)
  drjit  random numbers + sum | integrand (dr.sum(x) against dr.sum(exp(-x^2)))

    .venv/bin/python benchmarks/uniform_mc.py [--samples 1e8] [--repeat 5]
    .venv/bin/python benchmarks/uniform_mc.py --core build/isa-haswell/_core...so --drjit-target haswell

--core loads another build of the C++ core (benchmarks/isa_builds.py makes them);
--drjit-target haswell makes drjit's LLVM backend emit AVX2 code of width 4, for a comparison
with an AVX2 build on an AVX-512 machine.  numpy picks its kernels' ISA at import; the line
"numpy:" says which it runs (an AVX2-only machine's: NPY_DISABLE_CPU_FEATURES="X86_V4
AVX512_ICL AVX512_SPR", which benchmarks/isa_builds.py --throughput sets for an AVX2 build).
"""
from __future__ import annotations

import argparse
import ctypes
import importlib.util
import os
import platform
import sys
import time
from typing import Any, Callable

import numpy as np

# drjit LLVM targets for --drjit-target: (cpu, features, vector width)
DRJIT_TARGETS = {
    "haswell": ("haswell", "+avx,+avx2,+fma,+f16c,+bmi,+bmi2,+popcnt,+sse4.2,+lzcnt,+movbe,"
                           "-avx512f,-avx512vl,-avx512bw,-avx512dq,-avx512cd", 8),
}


def load_core(path: str | None) -> Any:
    """reference_estimators, with its C++ core loaded from `path` when given."""
    if path:
        spec = importlib.util.spec_from_file_location("reference_estimators._core", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        sys.modules["reference_estimators._core"] = module
    import reference_estimators

    return reference_estimators


def best_of(repeat: int, fn: Callable[[], Any]) -> float:
    """Best time of `repeat` runs of fn after one warm-up."""
    return alternating(repeat, {None: fn})[None]


def add_core_arguments(parser: argparse.ArgumentParser) -> None:
    """--core, --drjit-target and --no-drjit: which core build and which drjit to compare."""
    parser.add_argument("--core", help="path of another build of reference_estimators/_core")
    parser.add_argument("--drjit-target", choices=sorted(DRJIT_TARGETS),
                        help="make drjit's LLVM backend target this CPU (AVX2: haswell)")
    parser.add_argument("--no-drjit", action="store_true", help="leave drjit out")


def alternating(repeat: int, runs: dict[Any, Callable[[], Any]]) -> dict[Any, float]:
    """Best time of each run, the runs taking turns (after one warm-up each)."""
    for fn in runs.values():
        fn()
    best = {k: float("inf") for k in runs}
    for _ in range(repeat):
        for k, fn in runs.items():
            t = time.perf_counter()
            fn()
            best[k] = min(best[k], time.perf_counter() - t)
    return best


#: numpy's x86 dispatch targets (numpy >= 2.4), widest first: the ISA each stands for
NUMPY_TARGETS = (("AVX512_SPR", "AVX-512 (Sapphire Rapids)"), ("AVX512_ICL", "AVX-512 (Ice Lake)"),
                 ("X86_V4", "AVX-512"), ("X86_V3", "AVX2"))


def numpy_simd() -> str:
    """The widest x86 target numpy's kernels dispatch to in this process (lowered by
    NPY_DISABLE_CPU_FEATURES), from numpy's runtime feature table."""
    try:
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:   # a numpy whose table lives elsewhere: say so rather than guess
        return "unknown"
    if not any(key in features for key, _ in NUMPY_TARGETS):
        return "unknown (no x86 dispatch targets in numpy's table)"
    level = next((name for key, name in NUMPY_TARGETS if features.get(key)), "the SSE4.2 baseline")
    off = os.environ.get("NPY_DISABLE_CPU_FEATURES")
    return level + (f" (NPY_DISABLE_CPU_FEATURES={off!r})" if off else "")


def cpu_line() -> str:
    model, flags = platform.machine(), set()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                if key.strip() == "model name":
                    model = value.strip()
                elif key.strip() == "flags":
                    flags = set(value.split())
                if model != platform.machine() and flags:
                    break
    except OSError:
        pass
    named = (("AVX-512F", "avx512f"), ("AVX-512BW", "avx512bw"), ("AVX-512VL", "avx512vl"),
             ("AVX-512FP16", "avx512_fp16"), ("AVX2", "avx2"), ("FMA", "fma"))
    isa = [name for name, flag in named if flag in flags]
    return f"{model}, {os.cpu_count()} logical CPUs, {' '.join(isa) or 'no AVX'}"


class Drjit:
    """drjit's LLVM backend: its kernels, and what it targets (via drjit-core's C API)."""

    def __init__(self, target: str | None):
        from harness.adapters.mitsuba.runtime import use_libllvm

        use_libllvm()  # before drjit is imported
        import drjit as dr
        from drjit.llvm import PCG32

        self.dr, self.PCG32 = dr, PCG32
        self.PCG32(size=8).next_float64()  # initialises the LLVM backend
        dr.eval(self.PCG32(size=8).next_float64())
        self.lib = ctypes.CDLL(os.path.join(dr.__path__[0], "libdrjit-core.so"))
        if target:
            cpu, features, width = DRJIT_TARGETS[target]
            self._call("_Z19jit_llvm_set_targetPKcS0_j", None, cpu.encode(), features.encode(),
                       ctypes.c_uint(width))

    def _call(self, symbol: str, restype: Any, *args: Any) -> Any:
        try:
            fn = getattr(self.lib, symbol)  # drjit-core's C++ API (mangled names, drjit 1.x)
        except AttributeError:
            return None
        fn.restype = restype
        return fn(*args)

    def describe(self) -> str:
        cpu = self._call("_Z19jit_llvm_target_cpuv", ctypes.c_char_p)
        width = self._call("_Z21jit_llvm_vector_widthv", ctypes.c_uint)
        cpu = cpu.decode() if cpu else "?"
        llvm = ".".join(map(str, self.dr.detail.llvm_version()))
        return f"drjit {self.dr.__version__}, LLVM {llvm}: target {cpu}, vector width {width}"

    def integrand(self, n: int) -> float:
        x = self.PCG32(size=n).next_float64()
        return float(self.dr.sum(self.dr.exp(-x * x))[0]) / n

    def random_numbers(self, n: int) -> float:
        return float(self.dr.sum(self.PCG32(size=n).next_float64())[0]) / n

    def threads(self, k: int) -> None:
        self.dr.set_thread_count(k)


def numpy_mc(n: int) -> float:
    rng = np.random.default_rng(0)
    batch = 1 << 22
    total = 0.0
    for start in range(0, n, batch):
        x = rng.random(min(batch, n - start))
        total += float(np.sum(np.exp(-x * x)))
    return total / n


def core_stages(rest: Any, n: int, threads: int, repeat: int) -> dict[str, float]:
    """Best seconds of each prefix of the core's pipeline (points; contributions; everything)."""
    best = {"points": np.inf, "contributions": np.inf, "full": np.inf}
    for _ in range(repeat + 1):
        d = rest.profile_stages("gaussian", "uniform", n, threads=threads)
        best = {k: min(v, d[k]) for k, v in best.items()}
    return best


def main() -> None:
    rest = load_core(ARGS.core)
    n, repeat = int(float(ARGS.samples)), ARGS.repeat
    info = rest.build_info()
    print(f"uniform MC of exp(-x^2) on [0,1], n = {n:.0e} float64 samples, best of {repeat}")
    print(f"CPU: {cpu_line()}")
    print(f"core: built for {info['isa']} (-march={info['march'] or '(none)'}, GCC {info['compiler']}), "
          f"{info['vector_doubles']} doubles a vector, {info['rng_lanes']} PCG32 lanes; kernels run: "
          f"{info['isa']} (no runtime dispatch; this CPU's best: {info['cpu_isa']})")
    print(f"numpy {np.__version__}: kernels run {numpy_simd()}")
    chunks = -(-n // info["chunk_size"])
    print(f"chunks: {chunks} of {info['chunk_size']} samples (each its own PCG32 stream, merged in order)")
    drjit = None
    if not ARGS.no_drjit:
        try:
            drjit = Drjit(ARGS.drjit_target)
            print(drjit.describe())
        except Exception as e:  # noqa: BLE001 - report why the column is missing, keep the rest
            print(f"drjit unavailable: {e}")

    def core_run(k: int) -> Callable[[], Any]:
        return lambda: rest.integrate("gaussian", "uniform", n, threads=k)

    seconds = {f"core, {k} thread{'s' * (k > 1)}": s for k, s in alternating(repeat, {1: core_run(1),
                                                                                    2: core_run(2)}).items()}
    seconds["numpy, 1 thread"] = best_of(repeat, lambda: numpy_mc(n))
    if drjit is not None:
        def drjit_run(k: int) -> Callable[[], Any]:
            return lambda: (drjit.threads(k), drjit.integrand(n))

        for k, s in alternating(repeat, {1: drjit_run(1), 2: drjit_run(2)}).items():
            seconds[f"drjit LLVM float64, {k} thread{'s' * (k > 1)}"] = s
    rate = {name: n / s / 1e6 for name, s in seconds.items()}
    core2 = rate["core, 2 threads"]
    print(f"\n{'':36s} {'Msamples/s':>11s} {'core(2 threads) /':>18s}")
    for name, r in rate.items():
        print(f"{name:36s} {r:11.0f} {core2 / r:17.2f}x")
    print(f"\ncore scaling 1 -> 2 threads: {rate['core, 2 threads'] / rate['core, 1 thread']:.2f}x")
    if "drjit LLVM float64, 2 threads" in rate:
        d = rate["drjit LLVM float64, 2 threads"] / rate["drjit LLVM float64, 1 thread"]
        print(f"drjit scaling 1 -> 2 threads: {d:.2f}x")

    est = rest.integrate("gaussian", "uniform", n, threads=2)
    busy = ", ".join(f"{b:.4f} s ({b / est.seconds:.0%})" for b in est.busy)
    print(f"core busy per thread (2 threads, one run of {est.seconds:.4f} s): {busy}")

    print("\nstage profile, ns per sample and thread (best of the repeats)")
    print(f"{'':34s} {'1 thread':>9s} {'2 threads':>10s}")
    profile = {k: core_stages(rest, n, k, repeat) for k in (1, 2)}

    def ns(seconds_: float, k: int) -> float:
        return seconds_ * 1e9 * k / n

    rows = [("core: points (PCG32 uniforms)", lambda p: p["points"]),
            ("core: integrand exp(-x^2)", lambda p: p["contributions"] - p["points"]),
            ("core: screening + accumulation", lambda p: p["full"] - p["contributions"]),
            ("core: all", lambda p: p["full"])]
    for label, stage in rows:
        print(f"{label:34s} {ns(stage(profile[1]), 1):9.3f} {ns(stage(profile[2]), 2):10.3f}")
    if drjit is not None:
        dj = {}
        for k in (1, 2):
            drjit.threads(k)
            rng = best_of(repeat, lambda: drjit.random_numbers(n))
            full = best_of(repeat, lambda: drjit.integrand(n))
            dj[k] = (rng, full)
        print(f"{'drjit: random numbers + sum':34s} {ns(dj[1][0], 1):9.3f} {ns(dj[2][0], 2):10.3f}")
        print(f"{'drjit: integrand exp(-x^2)':34s} {ns(dj[1][1] - dj[1][0], 1):9.3f} "
              f"{ns(dj[2][1] - dj[2][0], 2):10.3f}")
        print(f"{'drjit: all':34s} {ns(dj[1][1], 1):9.3f} {ns(dj[2][1], 2):10.3f}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", default="1e8")
    parser.add_argument("--repeat", type=int, default=5)
    add_core_arguments(parser)
    ARGS = parser.parse_args()
    main()
