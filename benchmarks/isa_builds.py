"""The C++ core built for other ISAs, side by side with this machine's build: the same bits,
and how fast each one runs.

Builds reference_estimators/_core with CMake into build/isa-<march>/ for each --march
(default: haswell, the AVX2 + FMA baseline, and x86-64, plain SSE2), then
  --identity    compares, bit for bit, every catalogue estimate (all techniques, random,
                stratified and Sobol' points, 1 and 2 threads), the elementary functions'
                values and the sampler check's vectorised kernels' (dithering, float32
                detection, domain maps with given and streamed uniforms, cubature maps, the
                CDF tables' interpolation bound, the adapter's weight check)
                between the installed build and each variant; exit status 1 on any
                difference (tests/core/test_isa_builds.py runs this)
  --throughput  runs benchmarks/uniform_mc.py on each variant, drjit targeting the same ISA
                where it can (haswell) and numpy's kernels held to it (NUMPY_ABOVE), so an
                AVX2 build is compared with AVX2 drjit and numpy code

    .venv/bin/python benchmarks/isa_builds.py --identity [--march haswell x86-64]
    .venv/bin/python benchmarks/isa_builds.py --throughput --march haswell

Needs cmake, ninja and nanobind (setup.sh installs them).
"""
from __future__ import annotations

import argparse
import glob
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# Runs in a subprocess with one build of the core loaded: digests of everything it computes.
DIGEST = r"""
import json, sys
import numpy as np
sys.path.insert(0, "benchmarks")
from uniform_mc import load_core
rest = load_core(sys.argv[1])
from reference_estimators import kernels

out = {"isa": rest.build_info()["isa"]}
for f in rest.catalogue():
    for name in rest.techniques(f):
        for threads in (1, 2):
            e = rest.integrate(f, name, 100_000, seed=3, threads=threads)
            fields = (e.mean, e.variance, e.skewness, e.kurtosis, e.min, e.max)
            out[f"{f.name}/{name}/{threads}"] = [float(v).hex() for v in fields] + [e.n]
rng = np.random.default_rng(0)
x = np.concatenate([rng.uniform(-746, 710, 20_000), rng.uniform(-745.2, -708, 2_000),
                    [np.nan, np.inf, -np.inf]])
out["exp"] = kernels.fast_exp(x).tobytes().hex()
u = rng.random(20_000)
out["log"] = kernels.fast_log(u * 10.0 ** rng.uniform(-300, 300, u.size)).tobytes().hex()
out["sincos"] = b"".join(a.tobytes() for a in kernels.fast_sincos_2pi(u * 6 - 3)).hex()
# the sampler check's vectorised kernels: any bits, float32 values, unit vectors, boxes
bits = rng.integers(0, 2**64, size=20_000, dtype=np.uint64).view(np.float64)
f32 = rng.normal(size=(20_000, 3)).astype(np.float32).astype(np.float64)
out["dither"] = rest.dither_float32(np.concatenate([bits, f32.ravel()]), rng.random(80_000)).tobytes().hex()
out["all_float32"] = [rest.all_float32(f32), rest.all_float32(bits), rest.all_float32(f32 + 1e-12)]
unit = f32 / np.linalg.norm(f32, axis=1)[:, None]
s, inside = rest.dithered_domain_params("sphere", unit, rng.random(unit.shape))
out["dithered_params"] = s.tobytes().hex() + inside.tobytes().hex()
# 80 000 points: the uniforms drawn inside the pass from two stream chunks
s, inside = rest.dithered_domain_params("sphere", np.repeat(unit, 4, axis=0), stream=(3, 0xD17E))
out["dithered_stream"] = s.tobytes().hex() + inside.tobytes().hex()
# the (hemi)sphere map's lanes and tail: the norm tolerance's and the horizon's edges, NaN,
# infinities, signed zeros
edge = unit[:1_003] * (1 + rng.uniform(-2e-5, 2e-5, (1_003, 1)))
edge[:8] = [[0, 0, -1e-12], [0, 0, -2e-12], [np.nan, 0, 1], [0, np.inf, 0], [-0.0, -0.0, 1],
            [0, 0, -1.0000001], [0, 0, 0], [0.6, -0.8, -0.0]]
out["direction_params"] = "".join(a.tobytes().hex() for kind in ("hemisphere", "sphere")
                                  for a in rest.domain_params(kind, edge))
# a float32 renderer's directions both ways: rows inside the slack, near it, far off it, not finite
rows = np.concatenate([unit[:2_003] * (1 + rng.uniform(-3e-6, 3e-6, (2_003, 1))), edge[:11], unit[:5] * 3])
out["float32_unit_rows"] = "".join(a.tobytes().hex() for a in rest.float32_unit_rows(rows, 1e-6))
columns = np.ascontiguousarray(f32[:2_011].T.astype(np.float32))
odd = columns.copy()
odd[:, :4] = np.array([[np.nan, np.inf, -np.inf, -0.0]] * 3, dtype=np.float32)
out["float64_rows"] = "".join(rest.float64_rows(c).tobytes().hex() for c in (columns, list(odd)))
# the CDF tables' interpolation bound: monotone, flat and mixed quarter masses, special values
qs = rng.random((4_001, 4)) * 10.0 ** rng.uniform(-300, 300, (4_001, 1))
qs[:1_000] = np.sort(qs[:1_000], axis=1)
qs[1_000:2_000] = np.sort(qs[1_000:2_000], axis=1)[:, ::-1]
qs[2_000:2_100] = qs[2_000:2_100, :1]
qs[rng.random(qs.shape) < 0.01] = np.nan
qs[:6] = [[0, 0, 0, 0], [-0.0, 0, 0, 0], [1, np.inf, 2, 3], [np.inf] * 4, [5e-324, 0, 1e308, 1e308],
          [1, 2, 2, 1]]
out["interpolation_bound"] = rest.interpolation_bound(qs).tobytes().hex()
# the Rosenblatt transform's table lookups (four passes a batch of points: crowded leaves, NaN,
# points outside [0, 1] and strips outside the table) and its statistics
def table(strips, leaves):
    parts = []
    for _ in range(strips):
        cuts = np.unique(np.r_[0.0, 1.0, rng.random(leaves - 1), 0.3 + 1e-9 * np.arange(40)])
        mass = rng.gamma(0.5, 1.0, cuts.size - 1)
        mass /= mass.sum()
        parts.append((cuts[:-1], cuts[1:], np.r_[0.0, np.cumsum(mass)[:-1]], mass))
    lo, hi, start, mass = (np.concatenate(v) for v in zip(*parts))
    return lo, hi, start, mass, np.r_[0, np.cumsum([q[0].size for q in parts])]
marginal, conditional = table(1, 3_000), table(32, 200)
edges = np.r_[0.0, np.sort(rng.random(31)), 1.0]
pts = rng.uniform(-0.05, 1.05, (70_001, 2))
pts[:4] = [[np.nan, 0.5], [0.5, np.nan], [0.3 + 5e-9, 0.3 + 2e-9], [edges[5], 0.0]]
out["rosenblatt"] = "".join(a.tobytes().hex() for a in rest.rosenblatt(marginal, conditional, edges, pts))
out["lookup"] = rest.piecewise_linear_lookup(*conditional, rng.integers(-1, 34, 20_000),
                                             rng.uniform(-0.1, 1.1, 20_000)).tobytes().hex()
out["transform_statistics"] = "".join(
    a.tobytes().hex() for a in rest.transform_statistics(marginal, conditional, edges, pts[4:], 64))
# the rectangle light's map both ways and its density (a tilted parallelogram seen from off its
# axis): rays that hit, miss and graze; points inside, on and off the square; NaN rows
# (its frame in Python floats, the same on every machine: numpy's and LAPACK's kernels are not)
e0, e1, corner = (2.0, 0.1, -0.3), (0.2, -1.8, 0.1), (-1.0, 1.0, 1.2)   # ref at the origin
cross = (e0[1] * e1[2] - e0[2] * e1[1], e0[2] * e1[0] - e0[0] * e1[2], e0[0] * e1[1] - e0[1] * e1[0])
area = sum(c * c for c in cross) ** 0.5
n = tuple(c / area for c in cross)
g00, g01, g11 = (sum(a * b for a, b in zip(x, y)) for x, y in ((e0, e0), (e0, e1), (e1, e1)))
det = g00 * g11 - g01 * g01
dual = [[(g11 * a - g01 * b) / det for a, b in zip(e0, e1)],
        [(g00 * b - g01 * a) / det for a, b in zip(e0, e1)]]
frame = (corner, e0, e1, n, dual, sum(a * b for a, b in zip(n, corner)), area)
sq = rng.uniform(-0.1, 1.1, (20_003, 2))
sq[:3] = [[np.nan, 0.5], [0.0, 1.0], [1 + 5e-7, 0.5]]
dirs = rest.rect_to_world(sq, frame)
dirs[3:6] = [[0.0, 0.0, -1.0], [np.nan, 0.0, 1.0], [1.0, 0.0, 0.0]]
out["rect"] = "".join(a.tobytes().hex() for a in (
    dirs, rest.rect_to_square(dirs, frame, 1e-6),
    rest.rect_density(sq, rng.random(20_003) * 10.0 ** rng.uniform(-30, 30, 20_003), frame)))
# the weight check: weights near, at and off eval / pdf; bad weights (NaN, infinite, negative,
# -0.0 is not); zero, NaN and negative pdfs (apart: a NaN ratio makes the largest difference
# inf); one constant weight
e, p = rng.random((70_001, 3)), rng.uniform(0.01, 5.0, 70_001)
w = e / p[:, None] * (1 + rng.choice([0.0, 5e-5, 2e-4], e.shape))
odd = rng.random(e.shape) < 0.01
w[odd] = rng.choice([np.nan, np.inf, -np.inf, -1.0, -0.0], int(odd.sum()))
special = np.array([0.0, np.nan, -1.0, 1e-300])
out["weight_agreement"] = "".join(
    a.tobytes().hex() if isinstance(a, np.ndarray) else float(a).hex()
    for args in ((w, e, p), (w[:4], e[:4], special), (np.broadcast_to(w[7], e.shape), e, p))
    for a in rest.weight_agreement(*args, 1e-6, 1e-4))
lo = rng.random((3_001, 2)) * 0.9
out["cubature_points"] = rest.cubature_points("sphere", lo, lo + 0.05, np.linspace(0.1, 0.9, 4),
                                              columns=[0, 2, 1]).tobytes().hex()
print(json.dumps(out))
"""


def build(march: str) -> str:
    """Configures and builds the core for -march=<march>; returns the module's path."""
    out = os.path.join(ROOT, "build", f"isa-{march}")
    configure = ["cmake", "-S", os.path.join(ROOT, "reference_estimators"), "-B", out, "-G", "Ninja",
                 f"-DRE_MARCH={march}", f"-DPython_EXECUTABLE={sys.executable}", "-DCMAKE_BUILD_TYPE=Release"]
    for cmd in (configure, ["cmake", "--build", out]):
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode:
            raise SystemExit(f"building the core for -march={march} failed:\n"
                             f"{r.stdout[-3000:]}{r.stderr[-3000:]}")
    (module,) = glob.glob(os.path.join(out, "_core*.so"))
    return module


def digest(core: str) -> dict:
    r = subprocess.run([sys.executable, "-c", DIGEST, core], capture_output=True, text=True, cwd=ROOT)
    if r.returncode:
        raise SystemExit(f"computing with {core or 'the installed core'} failed:\n{r.stderr[-3000:]}")
    return json.loads(r.stdout)


def identity(marches: list[str]) -> int:
    base = digest("")
    estimates = sum("/" in k for k in base)        # keys integrand/technique/threads
    print(f"installed build: {base['isa']}, {estimates} estimates, 3 elementary functions and "
          f"{len(base) - estimates - 4} check kernels")
    status = 0
    for march in marches:
        other = digest(build(march))
        differ = [k for k in base if k != "isa" and base[k] != other.get(k)]
        print(f"-march={march} ({other['isa']}): "
              + ("bitwise identical" if not differ else f"{len(differ)} differ, e.g. {differ[:5]}"))
        status |= bool(differ)
    return status


#: numpy's dispatch targets above each variant's ISA: turned off (NPY_DISABLE_CPU_FEATURES)
#: so that numpy runs the kernels it would run on a machine of that ISA (numpy cannot go
#: below its SSE4.2 baseline)
NUMPY_ABOVE = {"haswell": ("X86_V4", "AVX512_ICL", "AVX512_SPR"),
               "x86-64": ("X86_V3", "X86_V4", "AVX512_ICL", "AVX512_SPR")}


def numpy_env(march: str) -> dict[str, str]:
    """The environment for a variant's run: numpy's targets above its ISA off, those this CPU
    has (the variable then names only what it changes; uniform_mc prints it)."""
    try:
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:   # a numpy whose table lives elsewhere: its own choice, as uniform_mc says
        return dict(os.environ)
    off = [t for t in NUMPY_ABOVE.get(march, ()) if features.get(t)]
    return {**os.environ, "NPY_DISABLE_CPU_FEATURES": " ".join(off)} if off else dict(os.environ)


def throughput(marches: list[str], extra: list[str]) -> None:
    for march in marches:
        script = os.path.join(ROOT, "benchmarks", "uniform_mc.py")
        cmd = [sys.executable, script, "--core", build(march), *extra]
        if march == "haswell":
            cmd += ["--drjit-target", "haswell"]
        print(f"\n=== -march={march} ===", flush=True)
        subprocess.run(cmd, check=True, env=numpy_env(march))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--march", nargs="+", default=["haswell", "x86-64"])
    parser.add_argument("--identity", action="store_true")
    parser.add_argument("--throughput", action="store_true")
    parser.add_argument("--samples", default="1e8", help="for --throughput")
    args = parser.parse_args()
    if not (args.identity or args.throughput):
        parser.error("say --identity, --throughput or both")
    code = identity(args.march) if args.identity else 0
    if args.throughput:
        throughput(args.march, ["--samples", args.samples])
    sys.exit(code)
