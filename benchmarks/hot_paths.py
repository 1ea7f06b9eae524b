"""Importance sampling, MIS and Sobol' points: Msamples/s of the core's `integrate` against numpy
and drjit implementations of the same estimators, side by side in one run.

Rows (integrand, catalogue technique):
  gaussian2d  importance:piecewise_constant_2d              f/p, p the 16x16 table sampler
  gaussian2d  mis_balance:uniform_box+piecewise_constant_2d one draw from each, balance heuristic
  gaussian2d  uniform/sobol                                 f at scrambled Sobol' points
  ggx_lobe    importance:ggx                                f/p, p = GGX D cos (zero variance)
  ggx_lobe    importance:cosine_hemisphere                  f/p, p = cos / pi
  ggx_lobe    mis_balance:cosine_hemisphere+ggx             one draw from each, balance heuristic
gaussian2d = exp(-|x - (0.3, 0.6)|^2 / (2 0.08^2)) on [0,1]^2; ggx_lobe = GGX D(w) cos(theta),
alpha = 0.01, over the hemisphere.  A sample is one contribution Y (an MIS sample draws one
point from each of its two samplers and evaluates f at both).

All three implementations run the core's estimator math in float64: the same samplers (the
piecewise-constant 2D sampler inverts the marginal CDF over rows, then the row's conditional
CDF, on the table the core builds: f at the cell centres + 1e-3), the same pdfs and the same
sums (f/p; MIS: sum_i f(X_i) / sum_j p_j(X_i)).
The numpy and drjit versions share one implementation of that math (written against a small
array interface, `NumpyOps` / `DrjitOps`), checked against the core's own samplers and
integrands on the same uniforms before anything is timed.
  core   reference_estimators.integrate: PCG32 chunk streams, compensated sum, M2..M4 moments,
         point, pdf and NaN/Inf screening (what the harness runs); Sobol': Owen-scrambled
         (Burley's hash) Sobol' points
  numpy  Generator.random in batches of 2^21 samples; bins by np.searchsorted (the conditional
         CDFs as one array, row r shifted by r: one search for all rows); one thread.  Sobol':
         scipy.stats.qmc.Sobol(d=2, scramble=True), whose scrambling is a linear matrix scramble
         plus digital shift, not Owen's: a scrambled Sobol' estimator, not the core's bits
  drjit  drjit.llvm, one fused kernel per estimate: PCG32.next_float64, dr.gather for the
         tables, a branchless binary search over the CDFs, dr.sum (symbolic mode).  drjit has no
         Sobol' generator; its column runs the core's construction written in drjit's integer
         ops (the same Joe-Kuo direction numbers, Burley's Owen scrambling, the core's seeds):
         the same points as the core, bit for bit.
On ggx_lobe f and every pdf read a direction's cos theta alone: all three draw z alone (the
core's polar path, Integrand.polar and Sampler.polar; drjit's tracer would drop the rest
anyway), the same bits as the whole directions' z.  The core's polar path also generates only
the uniforms it reads (each sampler's u0, the even-numbered ones of its stream; for importance
sampling inside the sampler's loop, a generator row at a time, so that PCG32's
multiplications overlap the sampler's divisions as in drjit's fused loop) and computes
f once where it is a sampler's pdf (the GGX lobe and GGX's pdf: Sampler.polar_function), as
drjit's tracer leaves out what nothing reads and merges equal expressions.  An MIS pair whose
f is one sampler's pdf runs in one loop (polar_mis.cpp): both techniques' draws, pdfs, weights
and terms in registers, each generator row's cosines drawn a row ahead of its terms.  The
"core path" lines name the path each row took (Estimate.kernel) and the blocks that went back
to the general path (Estimate.redone_blocks: 0 for these samplers), and the table sampler's
path for whole vectors of points (Sampler.kernel: on AVX-512 the 16 x 16 table is counted in
vector lanes, small_table2d.h).
Not in the peers: the core's screening of points, pdfs and contributions and its higher
moments (these samplers never produce a point the core would exclude).

Before timing, each numpy and drjit estimator runs at n = 2^18 against the exact reference
(Sobol' rows: 8 independent scrambles, the error from their spread); one more than 6 standard
errors off prints a loud warning.

Columns of the throughput table, in Msamples/s (n / best wall time):
  core 1, core 2      reference_estimators.integrate with threads=1 and 2 (the runs alternate)
  numpy               the numpy estimator (numpy is one thread)
  drjit 1, drjit 2    the drjit LLVM float64 estimator with 1 and 2 threads (alternating)
  core2/numpy         core with 2 threads over numpy
  core2/drjit2        core with 2 threads over drjit with 2 threads
Columns of the estimates table: the core's mean and standard error (Sobol': the spread of 8
independently scrambled replicas of the core, its samples being dependent), then the numpy and
drjit means from their last timed run; they agree within a few standard errors.
Timings: best of `--repeat` runs after a warm-up (drjit's kernel compilation excluded).

Last, a stage profile of each row in ns per sample and thread, at 1 and 2 threads: the core's
stages are differences of its pipeline's prefixes (reference_estimators.profile_stages: the
uniforms; the samplers' points and pdfs; their screening; for MIS every technique's pdf at
every point; the integrand and the estimator's arithmetic; the contributions' screening and
accumulation), each prefix timed alone, so a stage near 0 can come out slightly negative on
a noisy machine (on the polar path, ggx_lobe's rows, the samplers screen z and the pdf in their
own pass: the screening stage is in the sampling one and reads 0; and importance sampling
draws its u0s in that pass too, so its sampling stage is what the pass adds to drawing them
alone, less than the two apart; the MIS pair's prefixes are its one loop stopped early, so
its stages are what each part adds to that loop); drjit's are its uniforms
(a kernel that draws and sums them) and the rest of its whole kernel.

    .venv/bin/python benchmarks/hot_paths.py [--samples 2e7] [--repeat 3] [--no-drjit]
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import warnings
from dataclasses import dataclass, replace
from functools import partial
from typing import Any, Callable

import numpy as np
from scipy.stats import qmc

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from uniform_mc import Drjit, add_core_arguments, alternating, best_of, cpu_line, load_core, numpy_simd  # noqa: E402

BATCH = 1 << 21             # numpy samples per batch
N_VALIDATE = 1 << 18        # samples of each validation run
SOBOL_REPLICAS = 8          # independent scrambles behind a Sobol' error
Z_FAIL = 6.0                # |estimate - reference| / stderr above this is a failure
CHECK_POINTS = 4096         # uniforms of the cross-check against the core's samplers
INV_PI = 0.31830988618379067154  # kInvPi of sampling.h
MASK64 = (1 << 64) - 1

# Gaussian2D(0.3, 0.6, 0.08) and GgxLobe(alpha = 0.01) of reference_estimators/src/integrands.cpp
MX, MY, SIGMA = 0.3, 0.6, 0.08
ALPHA = 0.01
TABLE_RES, TABLE_FLOOR = 16, 1e-3  # the catalogue's piecewise_constant_2d table for gaussian2d


# --- the array operations the estimators need, for numpy and for drjit ----------------------
class NumpyOps:
    """Array operations on numpy arrays (tables are numpy arrays too)."""

    sqrt, exp, maximum, select, clip = np.sqrt, np.exp, np.maximum, np.where, np.clip

    @staticmethod
    def sincos_2pi(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        phi = 2 * math.pi * u
        return np.sin(phi), np.cos(phi)

    @staticmethod
    def gather(table: np.ndarray, index: np.ndarray) -> np.ndarray:
        return table[index]

    @staticmethod
    def cell(v: np.ndarray, k: int) -> np.ndarray:
        """min(floor(v k), k - 1): the cell of v in [0, 1] among k."""
        return np.minimum((v * k).astype(np.intp), k - 1)

    @staticmethod
    def to_float(i: np.ndarray) -> np.ndarray:
        return i

    @staticmethod
    def search(cdf: np.ndarray, bins: int, u: np.ndarray, row: np.ndarray | None = None) -> np.ndarray:
        """Last bin o in [0, bins) with cdf[o] <= u (the core's upper_bound - 1); `cdf` holds
        one CDF of bins + 1 entries per row, `row` says whose (None: the only one).  The shifted
        search rounds u + r to 2^-49: a u that close to a bin edge (probability ~1e-13) may take
        the bin above, at its lower edge."""
        if row is None:
            o = np.searchsorted(cdf, u, side="right") - 1
        else:  # row r's CDF shifted by r: all rows in one increasing array, one search
            rows = cdf.reshape(-1, bins + 1)
            shifted = (rows[:, :bins] + np.arange(len(rows))[:, None]).ravel()
            o = np.searchsorted(shifted, u + row, side="right") - 1 - row * bins
        return np.clip(o, 0, bins - 1)

    @staticmethod
    def to_numpy(a: np.ndarray) -> np.ndarray:
        return np.asarray(a)

    @staticmethod
    def from_numpy(a: np.ndarray) -> np.ndarray:
        return a


class DrjitOps:
    """The same operations on drjit.llvm Float64 / UInt32 arrays (tables uploaded once)."""

    def __init__(self, dr: Any, float64: type, uint32: type):
        self.dr, self.Float64, self.UInt32 = dr, float64, uint32
        self.sqrt, self.exp, self.maximum = dr.sqrt, dr.exp, dr.maximum
        self.select, self.clip = dr.select, dr.clip
        self._tables: dict[int, tuple[np.ndarray, Any]] = {}

    def sincos_2pi(self, u: Any) -> tuple[Any, Any]:
        return self.dr.sincos(2 * math.pi * u)

    def gather(self, table: np.ndarray, index: Any) -> Any:
        if id(table) not in self._tables:  # keeps `table` alive, so its id stays its own
            self._tables[id(table)] = (table, self.Float64(table))
        return self.dr.gather(self.Float64, self._tables[id(table)][1], index)

    def cell(self, v: Any, k: int) -> Any:
        return self.dr.minimum(self.UInt32(v * k), k - 1)

    def to_float(self, i: Any) -> Any:
        return self.Float64(i)

    def search(self, cdf: np.ndarray, bins: int, u: Any, row: Any = None) -> Any:
        """NumpyOps.search as a branchless binary search (bins a power of 2; cdf[0] = 0)."""
        base = 0 if row is None else row * (bins + 1)
        o, step = self.UInt32(0), bins // 2
        while step:
            o = self.dr.select(self.gather(cdf, base + o + step) <= u, o + step, o)
            step //= 2
        return o

    def to_numpy(self, a: Any) -> np.ndarray:
        return np.array(a)

    def from_numpy(self, a: np.ndarray) -> Any:
        return self.Float64(np.ascontiguousarray(a))


# --- the estimators' math, written once for both ---------------------------------------------
def gaussian2d(ops: Any, x: Any, y: Any) -> Any:
    """Gaussian2D::eval: exp(h |x - m|^2), h = -1 / (2 sigma^2)."""
    dx, dy = x - MX, y - MY
    return ops.exp((-0.5 / (SIGMA * SIGMA)) * (dx * dx + dy * dy))


def ggx_d(ops: Any, z: Any) -> Any:
    """sampling.h's ggx_d: alpha^2 / (pi t^2), t = z^2 (alpha^2 - 1) + 1; 0 unless z > 0."""
    a2 = ALPHA * ALPHA
    t = z * z * (a2 - 1) + 1
    return ops.select(z > 0, a2 / (math.pi * t * t), 0.0)


# f and both pdfs read a direction's cos theta (z) alone, so the estimators draw z alone, as the
# core's polar path does and drjit's tracer would anyway; the whole directions (sample_*) are
# built for the cross-check against the core's samplers.
def ggx_lobe(ops: Any, z: Any) -> Any:
    """GgxLobe::eval at a direction of cosine z, D(w) cos(theta); equally GGX's pdf there."""
    return ggx_d(ops, z) * z


def cosine_pdf(ops: Any, z: Any) -> Any:
    return ops.select(z > 0, z * INV_PI, 0.0)


def cosine_cos(ops: Any, u0: Any) -> Any:
    """sampling.h's cosine_hemisphere_cos: z of the cosine lobe's direction from u0."""
    return ops.sqrt(ops.maximum(0.0, 1 - u0))


def ggx_tan2(u0: Any) -> Any:
    return ALPHA * ALPHA * u0 / (1 - u0)


def ggx_cos(ops: Any, u0: Any) -> Any:
    """sampling.h's ggx_cos: z of GGX's direction from u0 (tan^2 theta = alpha^2 u0 / (1 - u0))."""
    return 1 / ops.sqrt(1 + ggx_tan2(u0))


def sample_cosine(ops: Any, u0: Any, u1: Any) -> tuple[tuple[Any, Any, Any], Any]:
    """sample_cosine_hemisphere: the direction and its pdf."""
    r = ops.sqrt(u0)
    s, c = ops.sincos_2pi(u1)
    z = cosine_cos(ops, u0)
    return (r * c, r * s, z), cosine_pdf(ops, z)


def sample_ggx(ops: Any, u0: Any, u1: Any) -> tuple[tuple[Any, Any, Any], Any]:
    """sample_ggx: the direction and its pdf."""
    z = ggx_cos(ops, u0)
    r = ops.sqrt(ggx_tan2(u0)) * z
    s, c = ops.sincos_2pi(u1)
    return (r * c, r * s, z), ggx_lobe(ops, z)


def neumaier(values: np.ndarray) -> float:
    """accumulator.h's CompensatedSum over values, in order."""
    total = comp = 0.0
    for v in map(float, values):
        t = total + v
        comp += (total - t) + v if abs(total) >= abs(v) else (v - t) + total
        total = t
    return total + comp


def cdf_and_pdf(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """PiecewiseConstant1D on [0, 1]: its CDF (len + 1 entries) and the pdf of each bin."""
    cdf = np.array([0.0] + [neumaier(values[:i + 1]) for i in range(len(values))])
    total = cdf[-1]
    cdf /= total
    cdf[-1] = 1.0
    return cdf, values * (len(values) / total)


class PiecewiseConstant2D:
    """table_samplers.cpp's PiecewiseConstant2D on [0,1]^2 (pbrt-v4): a marginal over rows (y) from
    u[1], then the row's conditional over columns (x) from u[0]; pdf = p(y) p(x | row)."""

    def __init__(self, values: np.ndarray):
        self.rows, self.cols = values.shape
        if self.rows & (self.rows - 1) or self.cols & (self.cols - 1) or not (values > 0).all():
            raise ValueError("the table must be 2^k x 2^l and positive (no empty bin to step over)")
        row_means = np.array([neumaier(row) / self.cols for row in values])
        self.marginal, marginal_pdf = cdf_and_pdf(row_means)
        conditional = [cdf_and_pdf(row) for row in values]
        self.conditional = np.concatenate([cdf for cdf, _ in conditional])
        self.cell_pdf = np.concatenate([marginal_pdf[r] * pdf for r, (_, pdf) in enumerate(conditional)])
        # the last double of each bin: a point rounded onto the next bin's edge steps back
        self.last_y = np.append(np.nextafter(np.arange(1, self.rows) / self.rows, 0.0), 1.0)
        self.last_x = np.append(np.nextafter(np.arange(1, self.cols) / self.cols, 0.0), 1.0)

    def sample(self, ops: Any, ux: Any, uy: Any) -> tuple[Any, Any, Any]:
        """Points (x, y) and their pdf from uniforms (u[0], u[1])."""
        r = ops.search(self.marginal, self.rows, uy)
        y = self._within_bin(ops, self.marginal, r, r, uy, self.rows, self.last_y)
        k = ops.search(self.conditional, self.cols, ux, row=r)
        x = self._within_bin(ops, self.conditional, r * (self.cols + 1) + k, k, ux, self.cols, self.last_x)
        return x, y, ops.gather(self.cell_pdf, r * self.cols + k)

    @staticmethod
    def _within_bin(ops: Any, cdf: np.ndarray, at: Any, o: Any, u: Any, bins: int, last: np.ndarray) -> Any:
        """PiecewiseTables::point_in's point in bin o (its CDF entry at index `at`)."""
        lo, hi = ops.gather(cdf, at), ops.gather(cdf, at + 1)
        t = (ops.to_float(o) + (u - lo) / (hi - lo)) / bins
        return ops.clip(t, ops.to_float(o) / bins, ops.gather(last, o))

    def pdf(self, ops: Any, x: Any, y: Any) -> Any:
        """The density at points (x, y) of [0,1]^2."""
        return ops.gather(self.cell_pdf, ops.cell(y, self.rows) * self.cols + ops.cell(x, self.cols))


def gaussian2d_table(rest: Any) -> np.ndarray:
    """The catalogue's table (integrands.cpp): f at the cell centres + 1e-3, rows along y."""
    c = (np.arange(TABLE_RES) + 0.5) / TABLE_RES
    centres = np.stack(np.meshgrid(c, c), axis=-1).reshape(-1, 2)  # row-major, (x, y)
    return rest.integrand("gaussian2d").eval(centres).reshape(TABLE_RES, TABLE_RES) + TABLE_FLOOR


# Contributions Y from the rows of uniforms u (u[j]: uniform j of every sample).
def table_importance(ops: Any, table: PiecewiseConstant2D, u: Any) -> Any:
    x, y, p = table.sample(ops, u[0], u[1])
    return gaussian2d(ops, x, y) / p


def box_table_balance(ops: Any, table: PiecewiseConstant2D, u: Any) -> Any:
    """Uniform box (pdf 1) from u[0:2], the table from u[2:4]: sum_i f(X_i) / (1 + p_table(X_i))."""
    first = gaussian2d(ops, u[0], u[1]) / (1.0 + table.pdf(ops, u[0], u[1]))
    x, y, p = table.sample(ops, u[2], u[3])
    return first + gaussian2d(ops, x, y) / (1.0 + p)


def box_uniform(ops: Any, table: PiecewiseConstant2D, u: Any) -> Any:
    return gaussian2d(ops, u[0], u[1])


def ggx_importance(ops: Any, table: PiecewiseConstant2D, u: Any) -> Any:
    z = ggx_cos(ops, u[0])
    return ggx_lobe(ops, z) / ggx_lobe(ops, z)


def cosine_importance(ops: Any, table: PiecewiseConstant2D, u: Any) -> Any:
    z = cosine_cos(ops, u[0])
    return ggx_lobe(ops, z) / cosine_pdf(ops, z)


def cosine_ggx_balance(ops: Any, table: PiecewiseConstant2D, u: Any) -> Any:
    """Cosine from u[0:2], GGX from u[2:4]: sum_i f(X_i) / (p_cos(X_i) + p_ggx(X_i))."""
    z = cosine_cos(ops, u[0])
    first = ggx_lobe(ops, z) / (cosine_pdf(ops, z) + ggx_lobe(ops, z))
    z = ggx_cos(ops, u[2])
    return first + ggx_lobe(ops, z) / (cosine_pdf(ops, z) + ggx_lobe(ops, z))


@dataclass(frozen=True)
class Row:
    integrand: str
    technique: str
    udim: int                 # uniforms per sample
    contribution: Callable[[Any, PiecewiseConstant2D, Any], Any]
    sobol: bool = False       # Sobol' points instead of random ones


ROWS = (
    Row("gaussian2d", "importance:piecewise_constant_2d", 2, table_importance),
    Row("gaussian2d", "mis_balance:uniform_box+piecewise_constant_2d", 4, box_table_balance),
    Row("gaussian2d", "uniform/sobol", 2, box_uniform, sobol=True),
    Row("ggx_lobe", "importance:ggx", 2, ggx_importance),
    Row("ggx_lobe", "importance:cosine_hemisphere", 2, cosine_importance),
    Row("ggx_lobe", "mis_balance:cosine_hemisphere+ggx", 4, cosine_ggx_balance),
)


def mean_and_stderr(total: float, squares: float, n: int) -> tuple[float, float]:
    """Mean and standard error (as if independent) from the sum and the sum of squares."""
    mean = total / n
    variance = max(squares / n - mean * mean, 0.0) * n / max(n - 1, 1)
    return mean, math.sqrt(variance / n)


# --- the numpy peer --------------------------------------------------------------------------
def numpy_uniforms(row: Row, replica: int) -> Callable[[int], np.ndarray]:
    """Batches of uniforms, shape (udim, m): numpy's PCG64, or scipy's scrambled Sobol'."""
    if not row.sobol:
        rng = np.random.default_rng(replica)
        return lambda m: rng.random((row.udim, m))
    sobol = qmc.Sobol(d=row.udim, scramble=True, rng=replica)
    return lambda m: sobol.random(m).T


def numpy_estimate(row: Row, table: PiecewiseConstant2D, n: int, replica: int = 0) -> tuple[float, float]:
    """The row's estimate by numpy, in batches of BATCH samples: (mean, stderr)."""
    draw = numpy_uniforms(row, replica)
    total = squares = 0.0
    with warnings.catch_warnings():  # batch sums that are no power of 2 unbalance the net: wanted
        warnings.filterwarnings("ignore", message="The balance properties of Sobol")
        for start in range(0, n, BATCH):
            y = row.contribution(NumpyOps, table, draw(min(BATCH, n - start)))
            total += float(np.sum(y))
            squares += float(np.dot(y, y))
    return mean_and_stderr(total, squares, n)


# --- the drjit peer --------------------------------------------------------------------------
def splitmix64(x: int) -> int:
    x = (x + 0x9E3779B97F4A7C15) & MASK64
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & MASK64
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & MASK64
    return x ^ (x >> 31)


def sobol_seed(replica: int, dim: int, seed: int = 0, case_id: int = 0) -> int:
    """pointsets.h's scrambling seed of dimension `dim`: splitmix64 over (seed, case, replica,
    0x50b01 + dim), low 32 bits."""
    key = splitmix64(seed ^ splitmix64(case_id ^ splitmix64(replica ^ splitmix64(0x50B01 + dim))))
    return key & 0xFFFFFFFF


class DrjitPeer(Drjit):
    """drjit's LLVM backend (set up by uniform_mc.Drjit) running the rows' estimators."""

    def __init__(self, target: str | None, directions: np.ndarray):
        super().__init__(target)
        from drjit.llvm import Float64, UInt32

        self.UInt32 = UInt32
        self.ops = DrjitOps(self.dr, Float64, UInt32)
        self.directions = directions  # v[dim, bit], the core's Sobol' direction numbers

    def reverse_bits(self, x: Any) -> Any:
        for shift, mask in ((1, 0x55555555), (2, 0x33333333), (4, 0x0F0F0F0F), (8, 0x00FF00FF)):
            x = ((x >> shift) & mask) | ((x & mask) << shift)
        return (x >> 16) | (x << 16)

    def owen_scramble(self, x: Any, seed: Any) -> Any:
        """pointsets.h's owen_scramble (Burley 2020)."""
        x = self.reverse_bits(x) + seed
        for k in (0x6C50B47C, 0xB82F1E52, 0xC7AFE638, 0x8D22F6E6):
            x ^= x * k
        return self.reverse_bits(x)

    def sobol(self, n: int, dims: int, replica: int) -> list[Any]:
        """The core's Owen-scrambled Sobol' points 0..n-1 (fill_points), one array per dimension."""
        dr, index, points = self.dr, self.dr.arange(self.UInt32, n), []
        for d in range(dims):
            x = self.UInt32(0)
            for k in range(max(n - 1, 1).bit_length()):
                x ^= dr.select((index & (1 << k)) != 0, self.UInt32(int(self.directions[d, k])), 0)
            x = self.owen_scramble(x, dr.opaque(self.UInt32, sobol_seed(replica, d)))
            points.append((self.ops.Float64(x) + 0.5) * 2.0**-32)
        return points

    def estimate(self, row: Row, table: PiecewiseConstant2D, n: int, replica: int = 0,
                 threads: int | None = None) -> tuple[float, float]:
        """The row's estimate as one kernel: (mean, stderr); `replica` picks the scramble of
        Sobol' points (random points come from drjit's default PCG32 streams); `threads`, when
        given, sets drjit's thread count first."""
        if threads is not None:
            self.threads(threads)
        if row.sobol:
            u = self.sobol(n, row.udim, replica)
        else:
            rng = self.PCG32(size=n)
            u = [rng.next_float64() for _ in range(row.udim)]
        y = row.contribution(self.ops, table, u)
        total, squares = self.dr.sum(y, mode="symbolic"), self.dr.sum(y * y, mode="symbolic")
        self.dr.eval(total, squares)
        return mean_and_stderr(total[0], squares[0], n)


# --- checks before timing --------------------------------------------------------------------
def worst_difference(ours: list[np.ndarray], theirs: list[np.ndarray]) -> float:
    """Largest |a - b| / max(|b|, 1) over pairs of arrays."""
    return max(float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1.0))) for a, b in zip(ours, theirs))


def cross_check(rest: Any, table: PiecewiseConstant2D, ops: Any) -> dict[str, float]:
    """Worst relative difference to the core's samplers (points and pdf from the same uniforms,
    pdf at the core's points) and integrands, for the table, GGX and cosine samplers."""
    u = np.random.default_rng(7).random((CHECK_POINTS, 2))
    uu = [ops.from_numpy(u[:, 0]), ops.from_numpy(u[:, 1])]
    out = {}
    core = rest.technique("gaussian2d", "importance:piecewise_constant_2d").sampler
    x, p = core.sample(u)
    cx = [ops.from_numpy(x[:, 0]), ops.from_numpy(x[:, 1])]
    ours = [*table.sample(ops, *uu), table.pdf(ops, *cx), gaussian2d(ops, *cx)]
    truth = [x[:, 0], x[:, 1], p, core.pdf(x), rest.integrand("gaussian2d").eval(x)]
    out["piecewise_constant_2d"] = worst_difference([ops.to_numpy(a) for a in ours], truth)
    directions = (("ggx", sample_ggx, ggx_lobe), ("cosine_hemisphere", sample_cosine, cosine_pdf))
    for name, sample, pdf in directions:
        core = rest.technique("ggx_lobe", f"importance:{name}").sampler
        w, p = core.sample(u)
        cw = tuple(ops.from_numpy(w[:, j]) for j in range(3))
        ws, ps = sample(ops, *uu)
        ours = [*ws, ps, pdf(ops, cw[2]), ggx_lobe(ops, cw[2])]
        truth = [w[:, 0], w[:, 1], w[:, 2], p, core.pdf(w), rest.integrand("ggx_lobe").eval(w)]
        out[name] = worst_difference([ops.to_numpy(a) for a in ours], truth)
    return out


def z_score(rest: Any, row: Row, estimate: Callable[[int], tuple[float, float]]) -> float:
    """(estimate - reference) / stderr at n = N_VALIDATE; Sobol': over SOBOL_REPLICAS scrambles."""
    reference = rest.integrand(row.integrand).reference
    if row.sobol:
        means = [estimate(replica)[0] for replica in range(SOBOL_REPLICAS)]
        mean, stderr = float(np.mean(means)), float(np.std(means, ddof=1)) / math.sqrt(SOBOL_REPLICAS)
    else:
        mean, stderr = estimate(0)
    return (mean - reference) / (stderr + 1e-12 * abs(reference))  # zero-variance rows: rounding


def core_sobol_spread(rest: Any, row: Row, n: int) -> float:
    """Standard deviation of the core's estimate over SOBOL_REPLICAS independent scrambles."""
    means = [rest.integrate(row.integrand, row.technique, n, replica=r, threads=2).mean
             for r in range(SOBOL_REPLICAS)]
    return float(np.std(means, ddof=1))


# --- timing and printing ---------------------------------------------------------------------
def recorded(store: dict[str, Any], key: str, fn: Callable[[], Any]) -> Callable[[], Any]:
    """fn, keeping its last result in store[key]."""
    return lambda: store.__setitem__(key, fn())


def time_row(rest: Any, row: Row, table: PiecewiseConstant2D, n: int, repeat: int,
             drjit: DrjitPeer | None) -> tuple[dict[str, float], dict[str, Any]]:
    """Best seconds and last result of each implementation on one row."""
    results: dict[str, Any] = {}

    def core(k: int) -> Callable[[], Any]:
        run = partial(rest.integrate, row.integrand, row.technique, n, threads=k)
        return recorded(results, f"core {k}", run)

    seconds = {f"core {k}": s for k, s in alternating(repeat, {1: core(1), 2: core(2)}).items()}
    seconds["numpy"] = best_of(repeat, recorded(results, "numpy", lambda: numpy_estimate(row, table, n)))
    if drjit is not None:
        def dj(k: int) -> Callable[[], Any]:
            return recorded(results, f"drjit {k}", partial(drjit.estimate, row, table, n, threads=k))

        seconds.update({f"drjit {k}": s for k, s in alternating(repeat, {1: dj(1), 2: dj(2)}).items()})
    return seconds, results


def column(value: float | None, fmt: str, width: int, unit: str = "") -> str:
    """value right-aligned in `width` characters with `unit` after it, or n/a."""
    text = "n/a" if value is None else f"{value:{fmt}}{unit}"
    return f"{text:>{width}s}"


def print_throughput(n: int, seconds: dict[Row, dict[str, float]]) -> None:
    names = ("core 1", "core 2", "numpy", "drjit 1", "drjit 2")
    print(f"\nMsamples/s{'':38s}" + "".join(f"{c:>9s}" for c in names)
          + f"{'core2/numpy':>13s}{'core2/drjit2':>14s}")
    for row, s in seconds.items():
        rate = {c: n / s[c] / 1e6 if c in s else None for c in names}
        ratio = [rate["core 2"] / rate[c] if rate[c] else None for c in ("numpy", "drjit 2")]
        print(f"{row.integrand:10s} {row.technique:46s}" + "".join(column(rate[c], ".1f", 9) for c in names)
              + column(ratio[0], ".2f", 13, "x") + column(ratio[1], ".2f", 14, "x"))


def print_kernels(rest: Any, results: dict[Row, dict[str, Any]]) -> None:
    """The path each row's estimate took through the core (Estimate.kernel) and how many of
    its blocks went back to the general path, and the path the table sampler takes for whole
    vectors of points (Sampler.kernel) (a core without these fields: '?')."""
    print("\ncore path (two threads; blocks redone on the general path):")
    for row, r in results.items():
        e = r["core 2"]
        print(f"  {row.integrand:10s} {row.technique:46s} {getattr(e, 'kernel', '?') or '?':34s} "
              f"{getattr(e, 'redone_blocks', '?')}")
    table = rest.technique("gaussian2d", "importance:piecewise_constant_2d").sampler
    print(f"  the {TABLE_RES}x{TABLE_RES} table sampler: {getattr(table, 'kernel', '?')}")


def print_estimates(rest: Any, n: int, results: dict[Row, dict[str, Any]]) -> None:
    print(f"\nestimates (n = {n:.3g}){'':25s}{'core':>19s}{'stderr':>11s}{'numpy':>19s}{'drjit':>19s}")
    for integrand in dict.fromkeys(row.integrand for row in results):
        print(f"{integrand}: reference {rest.integrand(integrand).reference!r}")
        for row in (r for r in results if r.integrand == integrand):
            r = results[row]
            stderr = core_sobol_spread(rest, row, n) if row.sobol else r["core 2"].stderr
            peers = [r[k][0] if k in r else None for k in ("numpy", "drjit 2")]
            print(f"  {row.technique:46s}{r['core 2'].mean:19.15f}{stderr:10.2e}{'*' if row.sobol else ' '}"
                  + "".join(column(v, ".15f", 19) for v in peers))
    print(f"  * the spread of {SOBOL_REPLICAS} independently scrambled replicas "
          "(Sobol' samples are dependent)")


def print_checks(rest: Any, table: PiecewiseConstant2D, peers: dict[str, tuple[Any, Callable]]) -> None:
    """The cross-check against the core's samplers and the validation against the references."""
    print(f"\ncross-check on {CHECK_POINTS} uniforms, worst relative difference to the core's samplers "
          "(points, pdfs) and integrands:")
    for name, (ops, _) in peers.items():
        worst = cross_check(rest, table, ops)
        print(f"  {name:6s} " + "  ".join(f"{k} {v:.1e}" for k, v in worst.items()))
        for k, v in worst.items():
            if v > 1e-9:
                print(f"!!! WARNING: {name}'s {k} differs from the core's by {v:.2e}: "
                      "not the same sampler !!!")
    print(f"\nvalidation at n = {N_VALIDATE} (z = (estimate - reference) / stderr; Sobol': "
          f"{SOBOL_REPLICAS} scrambles):")
    for row in ROWS:
        zs = {name: z_score(rest, row, lambda rep, est=est: est(row, table, N_VALIDATE, rep))
              for name, (_, est) in peers.items()}
        print(f"  {row.integrand:10s} {row.technique:46s}"
              + "".join(f"  {k} z = {z:+6.2f}" for k, z in zs.items()))
        for name, z in zs.items():
            if not abs(z) <= Z_FAIL:
                print(f"!!! WARNING: {name} {row.integrand} {row.technique} is {z:+.1f} standard errors "
                      "off the reference: its timing below is of a wrong estimator !!!")


# The core's pipeline prefixes (reference_estimators.profile_stages) and the stage each adds.
STAGES = (("points", "points"), ("sampled", "sampling"), ("screened", "screening"),
          ("weighted", "MIS weights"), ("contributions", "integrand"), ("full", "accumulation"))


def core_stages(rest: Any, row: Row, n: int, threads: int, repeat: int) -> dict[str, float | None]:
    """Best seconds of each prefix of the core's pipeline on one row (None: no such stage)."""
    best: dict[str, float | None] = {}
    for _ in range(repeat + 1):   # the first run is the warm-up, as in best_of
        d = rest.profile_stages(row.integrand, row.technique, n, threads=threads)
        best = {k: None if d[k] is None else min(d[k], best.get(k) or math.inf) for k, _ in STAGES}
    return best


def uniforms_only(ops: Any, table: PiecewiseConstant2D, u: Any) -> Any:
    """The sum of a sample's uniforms: a kernel that draws them and nothing else."""
    total = u[0]
    for v in u[1:]:
        total = total + v
    return total


def print_stages(rest: Any, n: int, repeat: int, drjit: DrjitPeer | None, table: PiecewiseConstant2D) -> None:
    """Where each row's time goes, in ns per sample and thread: the core's stages (differences of
    its pipeline's prefixes, each timed alone) and drjit's uniforms (a kernel summing them)
    against its whole kernel."""
    print(f"\nstage profile, ns per sample and thread (best of {repeat}; a stage = the difference of two "
          "prefixes of the pipeline, each timed alone):")
    print("  core: points = the uniforms (PCG32 or Sobol'; the polar path's u0s alone); sampling = the "
          "samplers' points and pdfs;\n  screening = the points' "
          "domain and pdf checks; MIS weights = every technique's pdf at every "
          "point; integrand = f and the\n  estimator's arithmetic; accumulation = the contributions' "
          "screening, compensated sum and M2..M4")
    print("  drjit: uniforms = PCG32.next_float64 (or the Sobol' points) summed; rest = its whole kernel "
          "less that")
    print(f"{'':58s}" + "".join(f"{label:>13s}" for _, label in STAGES) + f"{'core all':>10s}"
          + f"{'drjit unif.':>12s}{'drjit rest':>11s}{'drjit all':>10s}")
    for row in ROWS:
        uniforms = replace(row, contribution=uniforms_only)
        for k in (1, 2):
            ns = {key: None if v is None else v * 1e9 * k / n
                  for key, v in core_stages(rest, row, n, k, repeat).items()}
            cells, last = [ns["points"]], ns["points"]
            for key, _ in STAGES[1:]:
                cells.append(None if ns[key] is None else ns[key] - last)
                last = last if ns[key] is None else ns[key]
            dj: list[float | None] = [None, None, None]
            if drjit is not None:
                drjit.threads(k)
                unif = best_of(repeat, lambda: drjit.estimate(uniforms, table, n))
                full = best_of(repeat, lambda: drjit.estimate(row, table, n))
                dj = [unif * 1e9 * k / n, (full - unif) * 1e9 * k / n, full * 1e9 * k / n]
            print(f"{row.integrand:10s} {row.technique:44s} {k}t"
                  + "".join(column(c, ".2f", 13) for c in cells) + column(ns["full"], ".2f", 10)
                  + column(dj[0], ".2f", 12) + column(dj[1], ".2f", 11) + column(dj[2], ".2f", 10))


def main() -> None:
    rest = load_core(ARGS.core)

    n, repeat = int(float(ARGS.samples)), ARGS.repeat
    print(f"core integrate against numpy and drjit: importance sampling, MIS, Sobol'; n = {n:.3g} "
          f"samples a row, best of {repeat}")
    print(f"CPU: {cpu_line()}")
    print(f"core build_info: {rest.build_info()}")
    print(f"numpy {np.__version__}: kernels run {numpy_simd()}")
    table = PiecewiseConstant2D(gaussian2d_table(rest))
    peers: dict[str, tuple[Any, Callable]] = {"numpy": (NumpyOps, numpy_estimate)}
    drjit = None
    if not ARGS.no_drjit:
        try:
            drjit = DrjitPeer(ARGS.drjit_target, rest.sobol.direction_numbers(2))
            print(drjit.describe())
            peers["drjit"] = (drjit.ops, drjit.estimate)
        except Exception as e:  # noqa: BLE001 - report why the columns are missing, keep the rest
            print(f"drjit unavailable: {e}")
    print_checks(rest, table, peers)
    seconds, results = {}, {}
    for row in ROWS:
        seconds[row], results[row] = time_row(rest, row, table, n, repeat, drjit)
    print_throughput(n, seconds)
    print_kernels(rest, results)
    print_estimates(rest, n, results)
    print_stages(rest, n, repeat, drjit, table)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", default="2e7", help="samples (contributions) a row")
    parser.add_argument("--repeat", type=int, default=3)
    add_core_arguments(parser)
    ARGS = parser.parse_args()
    main()
