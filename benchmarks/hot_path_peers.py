"""The peers of benchmarks/hot_paths.py: numpy and drjit implementations of the core's
importance sampling, MIS and Sobol' estimators on gaussian2d and ggx_lobe, written once against
a small array interface (`NumpyOps`, `DrjitOps`), and the rows the benchmark times (see
hot_paths.py's docstring for what each row and peer computes).

Each estimate returns (mean, stderr) from sums of y - shift and its squares, the shift a value
near the mean (the benchmark passes the row's exact reference): the variance is then the
squares' mean less the square of the mean difference, which a shift near the mean keeps from
cancelling (raw sums of y and y^2 lose every digit of a variance far below the mean's square).
"""
from __future__ import annotations

import math
import os
import sys
import warnings
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
from scipy.stats import qmc

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from uniform_mc import Drjit  # noqa: E402

BATCH = 1 << 21             # numpy samples per batch
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


def mean_and_stderr(total: float, squares: float, n: int, shift: float) -> tuple[float, float]:
    """Mean and standard error (as if independent) of n values y from the sums of d = y - shift
    and of d^2 (the module's docstring says why shifted)."""
    mean_d = total / n
    variance = max(squares - total * mean_d, 0.0) / max(n - 1, 1)
    return shift + mean_d, math.sqrt(variance / n)


# --- the numpy peer --------------------------------------------------------------------------
def numpy_uniforms(row: Row, replica: int) -> Callable[[int], np.ndarray]:
    """Batches of uniforms, shape (udim, m): numpy's PCG64, or scipy's scrambled Sobol'."""
    if not row.sobol:
        rng = np.random.default_rng(replica)
        return lambda m: rng.random((row.udim, m))
    sobol = qmc.Sobol(d=row.udim, scramble=True, rng=replica)
    return lambda m: sobol.random(m).T


def numpy_estimate(row: Row, table: PiecewiseConstant2D, n: int, shift: float,
                   replica: int = 0) -> tuple[float, float]:
    """The row's estimate by numpy, in batches of BATCH samples: (mean, stderr), from sums
    of y - shift."""
    draw = numpy_uniforms(row, replica)
    total = squares = 0.0
    with warnings.catch_warnings():  # batch sums that are no power of 2 unbalance the net: wanted
        warnings.filterwarnings("ignore", message="The balance properties of Sobol")
        for start in range(0, n, BATCH):
            d = row.contribution(NumpyOps, table, draw(min(BATCH, n - start))) - shift
            total += float(np.sum(d))
            squares += float(np.dot(d, d))
    return mean_and_stderr(total, squares, n, shift)


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

    def estimate(self, row: Row, table: PiecewiseConstant2D, n: int, shift: float, replica: int = 0,
                 threads: int | None = None) -> tuple[float, float]:
        """The row's estimate as one kernel: (mean, stderr) from sums of y - shift; `replica`
        picks the scramble of Sobol' points (random points come from drjit's default PCG32
        streams); `threads`, when given, sets drjit's thread count first."""
        if threads is not None:
            self.threads(threads)
        if row.sobol:
            u = self.sobol(n, row.udim, replica)
        else:
            rng = self.PCG32(size=n)
            u = [rng.next_float64() for _ in range(row.udim)]
        d = row.contribution(self.ops, table, u) - shift
        total, squares = self.dr.sum(d, mode="symbolic"), self.dr.sum(d * d, mode="symbolic")
        self.dr.eval(total, squares)
        return mean_and_stderr(total[0], squares[0], n, shift)


