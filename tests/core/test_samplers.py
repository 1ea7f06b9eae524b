"""The sampler catalogue: sample / pdf / invert triples, draw(), the rejection method, and
the argument checks of the Python API.

For every registry sampler (defaults and a few harder parameter sets) this checks that
sample() reports pdf(x), that points lie in the domain, that invert() undoes sample(), that
the pdf integrates to 1 (by quadrature, independently of the sampler's own code), that the
pdf is 0 and the inverse NaN outside the support, and, for the 1-D inversion samplers, that
draw() follows the exact CDF (Kolmogorov-Smirnov, CDFs written here from the formulas).

Statistical tests state their false-alarm rate alpha and use fixed seeds chosen before the
tests were written; a failure is a finding, not a reason to try another seed.
"""
from __future__ import annotations

import math
import re
import subprocess
import sys
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest
from scipy import integrate, special, stats

import reference_estimators as rest

CHUNK = rest.CHUNK_SIZE
REGISTRY = {s["name"]: s for s in rest.samplers()}
DIRECTION_DOMAINS = ("hemisphere", "sphere")


# --- the cases ---------------------------------------------------------------------------
PC1D_TABLE = (1.0, 1.0, 0.87, 0.25)
# Zero bins at both ends and inside, an odd bin count, and a domain other than [0, 1].
PC1D_ZERO_TABLE = (0.0, 1.0, 0.0, 2.0, 0.0, 0.0, 3.0, 0.5, 0.0)
PC2D_TABLE = tuple(tuple(1.0 + ((5 * r + c) % 7) for c in range(5)) for r in range(4))
PC2D_ZERO_ROW = 3
PC2D_ZERO_TABLE = tuple(
    tuple(0.0 if r == PC2D_ZERO_ROW else 0.25 + ((3 * r + 5 * c) % 11) / 4 for c in range(16))
    for r in range(8)
)


@dataclass(frozen=True)
class Case:
    id: str
    name: str
    params: dict[str, float] = field(default_factory=dict)
    table: Any = None

    def make(self) -> rest.Sampler:
        table = None if self.table is None else np.array(self.table, dtype=float)
        return rest.sampler(self.name, table=table, **self.params)

    @property
    def p(self) -> dict[str, float]:
        """All parameters: the registry defaults overridden by this case's."""
        return {**REGISTRY[self.name]["params"], **self.params}

    @property
    def domain(self) -> str:
        return REGISTRY[self.name]["domain"]

    @property
    def is_direction(self) -> bool:
        return self.domain in DIRECTION_DOMAINS

    @property
    def is_1d(self) -> bool:
        return self.domain in ("interval", "half_line")

    def __str__(self) -> str:
        return self.id


CASES = [
    # registry defaults
    Case("exponential", "exponential"),
    Case("linear", "linear"),
    Case("power", "power"),
    Case("lomax", "lomax"),
    Case("trimmed_logistic", "trimmed_logistic"),
    Case("piecewise_constant_1d", "piecewise_constant_1d", table=PC1D_TABLE),
    Case("piecewise_constant_2d", "piecewise_constant_2d", table=PC2D_TABLE),
    Case("uniform_hemisphere", "uniform_hemisphere"),
    Case("cosine_hemisphere", "cosine_hemisphere"),
    Case("uniform_sphere", "uniform_sphere"),
    Case("uniform_cone", "uniform_cone"),
    Case("ggx", "ggx"),
    # harder parameter sets
    Case("ggx-alpha0.01", "ggx", {"alpha": 0.01}),
    Case("ggx-alpha0.5", "ggx", {"alpha": 0.5}),
    Case("uniform_cone-cos_max-0.5", "uniform_cone", {"cos_max": -0.5}),
    Case("uniform_cone-cos_max0.99", "uniform_cone", {"cos_max": 0.99}),
    Case("power-k-0.9", "power", {"k": -0.9}),
    Case("power-k2", "power", {"k": 2.0}),
    Case("linear-a0-b1", "linear", {"a": 0.0, "b": 1.0}),
    Case("trimmed_logistic-narrow", "trimmed_logistic", {"s": 1e-3}),
    Case("piecewise_constant_1d-zero_bins", "piecewise_constant_1d", {"a": -1.0, "b": 2.0}, PC1D_ZERO_TABLE),
    Case("piecewise_constant_2d-8x16-zero_row", "piecewise_constant_2d", table=PC2D_ZERO_TABLE),
]
ONE_D = [c for c in CASES if c.is_1d]
DIRECTIONS = [c for c in CASES if c.is_direction]


def cases(selection=CASES):
    return pytest.mark.parametrize("case", selection, ids=str)


def test_case_list_covers_the_registry():
    missing = set(REGISTRY) - {c.name for c in CASES}
    assert not missing, f"registry samplers without test cases: {sorted(missing)}"


# --- helpers -------------------------------------------------------------------------------
def canonical(m) -> np.ndarray:
    """The canonical uniform with 52-bit index m: (m + 0.5) 2^-52, in the open (0, 1)."""
    return (np.asarray(m, dtype=np.float64) + 0.5) * 2.0**-52


def random_canonical(rng: np.random.Generator, shape) -> np.ndarray:
    return canonical(rng.integers(0, 2**52, size=shape, dtype=np.int64))


EDGE_U = canonical(np.array([0, 1, 2, 1000, 2**50, 2**51 - 1, 2**51, 2**52 - 1001, 2**52 - 2, 2**52 - 1],
                            dtype=np.float64))


def breakpoint_u(cdf_values) -> np.ndarray:
    """Canonical uniforms at and next to each given CDF value (where tables switch bins)."""
    m = np.floor(np.asarray(cdf_values, dtype=float) * 2.0**52)
    near = (m[:, None] + np.arange(-3, 4)[None, :]).ravel()
    return canonical(near[(near >= 0) & (near < 2**52)])


def table_cdf(values) -> np.ndarray:
    v = np.asarray(values, dtype=float)
    c = np.concatenate([[0.0], np.cumsum(v)])
    return c / c[-1]


def uniforms_for(case: Case, n_random: int = 20_000) -> np.ndarray:
    """Random canonical uniforms plus the extreme ones (and, for tables, the ones next to
    the bin switches); shape (N,) or (N, 2)."""
    rng = np.random.default_rng(20240601)
    s = case.make()
    if s.udim == 1:
        extra = [EDGE_U]
        if case.table is not None:
            extra.append(breakpoint_u(table_cdf(case.table)[1:-1]))
        return np.concatenate([random_canonical(rng, n_random), *extra])
    e0, e1 = np.meshgrid(EDGE_U, EDGE_U, indexing="ij")
    parts = [random_canonical(rng, (n_random, 2)), np.column_stack([e0.ravel(), e1.ravel()])]
    if case.table is not None:
        t = np.asarray(case.table, dtype=float)
        ub = breakpoint_u(table_cdf(t.sum(axis=1))[1:-1])  # marginal over rows: u[1]
        cb = np.concatenate([breakpoint_u(table_cdf(row)[1:-1]) for row in t if row.sum() > 0])
        mid = np.full(ub.size, 0.37)
        parts += [np.column_stack([mid, ub]), np.column_stack([cb, np.full(cb.size, 0.61)])]
    return np.concatenate(parts)


def fmt(*columns, limit: int = 5) -> str:
    """First few offending rows, for failure messages."""
    rows = list(zip(*[np.asarray(c)[:limit].tolist() for c in columns]))
    return "\n  ".join(str(r) for r in rows)


def direction_grid(theta_breaks, n_theta: int = 48, n_phi: int = 64):
    """Gauss-Legendre product rule over (theta, phi) on the sphere, theta panels split at
    the given break points; returns unit vectors (N, 3) and weights including sin(theta)."""
    xg, wg = np.polynomial.legendre.leggauss(n_theta)
    thetas, wts = [], []
    for lo, hi in zip(theta_breaks[:-1], theta_breaks[1:]):
        thetas.append(0.5 * (hi - lo) * xg + 0.5 * (hi + lo))
        wts.append(0.5 * (hi - lo) * wg)
    theta, wt = np.concatenate(thetas), np.concatenate(wts)
    xp, wp = np.polynomial.legendre.leggauss(n_phi)
    phi, wphi = math.pi * (xp + 1), math.pi * wp
    T, P = np.meshgrid(theta, phi, indexing="ij")
    W = np.outer(wt * np.sin(theta), wphi)
    w = np.column_stack([(np.sin(T) * np.cos(P)).ravel(), (np.sin(T) * np.sin(P)).ravel(), np.cos(T).ravel()])
    return w, W.ravel()


def theta_breaks(case: Case) -> list[float]:
    br = {0.0, math.pi / 2, math.pi}
    if case.name == "uniform_cone":
        br.add(math.acos(case.p["cos_max"]))
    if case.name == "ggx":
        alpha = case.p["alpha"]
        br |= {alpha * 10.0**k for k in range(-3, 3) if alpha * 10.0**k < math.pi / 2}
    return sorted(br)


def azimuth_fraction(w: np.ndarray) -> np.ndarray:
    return np.mod(np.arctan2(w[:, 1], w[:, 0]) / (2 * math.pi), 1.0)


def circular_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = np.mod(a - b, 1.0)
    return np.minimum(d, 1.0 - d)


# --- exact CDFs, from the formulas ----------------------------------------------------------
def cdf_1d(case: Case):
    p = case.p
    if case.name == "exponential":
        return lambda x: -np.expm1(-p["rate"] * np.maximum(x, 0.0))
    if case.name == "linear":
        a, b = p["a"], p["b"]
        return lambda x: (lambda t: t * (a * (2 - t) + b * t) / (a + b))(np.clip(x, 0.0, 1.0))
    if case.name == "power":
        return lambda x: np.clip(x, 0.0, 1.0) ** (p["k"] + 1)
    if case.name == "lomax":
        return lambda x: -np.expm1(-p["shape"] * np.log1p(np.maximum(x, 0.0)))
    if case.name == "trimmed_logistic":
        mu, s, a, b = p["mu"], p["s"], p["a"], p["b"]
        la, lb = special.expit((a - mu) / s), special.expit((b - mu) / s)
        return lambda x: (special.expit((np.clip(x, a, b) - mu) / s) - la) / (lb - la)
    if case.name == "piecewise_constant_1d":
        a, b = p["a"], p["b"]
        edges = np.linspace(a, b, len(case.table) + 1)
        cdf = table_cdf(case.table)
        return lambda x: np.interp(x, edges, cdf)
    raise AssertionError(f"no CDF for {case}")


def support_1d(case: Case) -> tuple[float, float]:
    p = case.p
    if case.domain == "half_line":
        return 0.0, math.inf
    if case.name in ("linear", "power"):
        return 0.0, 1.0
    return p["a"], p["b"]


def pdf_breakpoints_1d(case: Case) -> list[float]:
    p = case.p
    if case.name == "trimmed_logistic":
        mu, s = p["mu"], p["s"]
        return [v for v in (mu - 20 * s, mu - 5 * s, mu, mu + 5 * s, mu + 20 * s) if p["a"] < v < p["b"]]
    if case.name == "piecewise_constant_1d":
        return list(np.linspace(p["a"], p["b"], len(case.table) + 1)[1:-1])
    return []


# --- sample() and pdf() agree ------------------------------------------------------------
@cases()
def test_sample_returns_the_pdf_at_the_sampled_point(case):
    s = case.make()
    u = uniforms_for(case)
    x, p = s.sample(u)
    q = s.pdf(x)
    bad = ~np.isclose(p, q, rtol=1e-12, atol=0.0)
    assert not bad.any(), (f"{case}: sample() pdf differs from pdf(x) for {bad.sum()} points "
                           f"(u, x, sample pdf, pdf(x)):\n  {fmt(u[bad], x[bad], p[bad], q[bad])}")
    assert np.all(p > 0), f"{case}: sampled points with pdf 0: {fmt(u[p <= 0], x[p <= 0])}"


@cases()
def test_sample_output_shapes(case):
    s = case.make()
    u = uniforms_for(case)[:7]
    x, p = s.sample(u)
    assert p.shape == (7,)
    assert x.shape == ((7,) if s.dim == 1 else (7, s.dim)), f"{case}: x shape {x.shape}"
    v = s.invert(x)
    assert v.shape == ((7,) if s.udim == 1 else (7, s.udim)), f"{case}: invert shape {v.shape}"
    if s.dim == 1:
        # 1-D points and uniforms may come as (N,) or (N, 1).
        x2, p2 = s.sample(u.reshape(-1, 1))
        assert np.array_equal(x2, x) and np.array_equal(p2, p)
        assert np.array_equal(s.pdf(x.reshape(-1, 1)), s.pdf(x))
        assert np.array_equal(s.invert(x.reshape(-1, 1)), v, equal_nan=True)


# --- the domain --------------------------------------------------------------------------
@cases()
def test_samples_lie_in_the_domain(case):
    s = case.make()
    u = uniforms_for(case)
    x, _ = s.sample(u)
    assert np.all(np.isfinite(x)), (
        f"{case}: non-finite points: "
        f"{fmt(u[~np.isfinite(x).all(axis=-1) if x.ndim > 1 else ~np.isfinite(x)])}")
    if case.is_1d:
        lo, hi = support_1d(case)
        bad = ~((x >= lo) & (x <= hi))
        if case.name == "power":
            bad |= x <= 0  # the support is (0, 1]
        assert not bad.any(), f"{case}: points outside [{lo}, {hi}] (u, x):\n  {fmt(u[bad], x[bad])}"
    elif case.domain == "square":
        bad = ~np.all((x >= 0) & (x <= 1), axis=1)
        assert not bad.any(), f"{case}: points outside [0,1]^2 (u, x):\n  {fmt(u[bad], x[bad])}"
    else:
        norm_err = np.abs(np.linalg.norm(x, axis=1) - 1)
        bad = norm_err > 1e-12
        assert not bad.any(), f"{case}: |w| - 1 > 1e-12 (u, w, err):\n  {fmt(u[bad], x[bad], norm_err[bad])}"
        if case.domain == "hemisphere":
            bad = x[:, 2] < 0
            assert not bad.any(), f"{case}: directions below the horizon (u, w):\n  {fmt(u[bad], x[bad])}"
        if case.name == "uniform_cone":
            c = case.p["cos_max"]
            bad = x[:, 2] < c
            assert not bad.any(), (f"{case}: directions outside the cone z >= {c} (u, w):\n  "
                                   f"{fmt(u[bad], x[bad])}")


# --- invert() undoes sample() ----------------------------------------------------------------
@cases()
def test_invert_undoes_sample(case):
    s = case.make()
    u = uniforms_for(case)
    x, _ = s.sample(u)
    v = s.invert(x)
    if s.udim == 1:
        err = np.abs(v - u)
    else:
        err = np.abs(v[:, 0] - u[:, 0])
        if case.is_direction:
            # The azimuth is periodic, and undefined at the pole: the cone sampler maps
            # u0 < ~2^-54 / (1 - cos_max) to z = 1 - u0 (1 - cos_max), which rounds to exactly
            # 1 and leaves x = y = 0; there only u0 can be recovered.
            at_pole = (x[:, 0] == 0) & (x[:, 1] == 0)
            err = np.maximum(err, np.where(at_pole, 0.0, circular_distance(v[:, 1], u[:, 1])))
        else:
            err = np.maximum(err, np.abs(v[:, 1] - u[:, 1]))
    bad = ~(err <= 1e-9)
    assert not bad.any(), (f"{case}: invert(sample(u)) != u for {bad.sum()} points (u, x, invert, err):\n  "
                           f"{fmt(u[bad], x[bad], v[bad], err[bad])}")


# --- the pdf integrates to 1 --------------------------------------------------------------
@cases()
def test_pdf_integrates_to_one(case):
    s = case.make()
    if case.is_1d:
        lo, hi = support_1d(case)
        f = lambda t: float(s.pdf(np.array([t]))[0])  # noqa: E731
        if math.isinf(hi):
            total, est = integrate.quad(f, lo, hi, epsabs=1e-12, epsrel=1e-12, limit=400)
        else:
            total, est = integrate.quad(f, lo, hi, points=pdf_breakpoints_1d(case) or None,
                                        epsabs=1e-12, epsrel=1e-12, limit=400)
        assert abs(total - 1) < 1e-6, (f"{case}: integral of pdf over [{lo}, {hi}] = {total!r} "
                                       f"(quad error {est:.2g})")
    elif case.domain == "square":
        t = np.asarray(case.table, dtype=float)
        rows, cols = t.shape
        yc, xc = np.meshgrid((np.arange(rows) + 0.5) / rows, (np.arange(cols) + 0.5) / cols, indexing="ij")
        centres = np.column_stack([xc.ravel(), yc.ravel()])
        cell_pdf = s.pdf(centres).reshape(rows, cols)
        total = cell_pdf.sum() / (rows * cols)
        assert abs(total - 1) < 1e-12, f"{case}: sum of cell pdf x cell area = {total!r}"
        # The density is proportional to the table, cell by cell.
        expected = t * (rows * cols) / t.sum()
        assert np.allclose(cell_pdf, expected, rtol=1e-12, atol=0), \
            f"{case}: cell pdf not proportional to the table:\n{cell_pdf}\nexpected\n{expected}"
    else:
        w, wt = direction_grid(theta_breaks(case))
        total = float(np.dot(s.pdf(w), wt))
        assert abs(total - 1) < 1e-6, f"{case}: integral of pdf over the sphere = {total!r}"


# --- outside the support ------------------------------------------------------------------
def outside_points(case: Case) -> np.ndarray:
    if case.is_1d:
        lo, hi = support_1d(case)
        pts = [lo - 1e-9, lo - 1, -1e300, -math.inf, math.nan]
        if not math.isinf(hi):
            pts += [hi + 1e-9 * max(1, abs(hi)), hi + 1, 1e300, math.inf]
        if case.name == "power":
            pts.append(0.0)  # the support is (0, 1]
        return np.array(pts)
    if case.domain == "square":
        return np.array([[-1e-9, 0.5], [0.5, -1e-9], [1 + 1e-9, 0.5], [0.5, 1 + 1e-9], [-1, -1], [2, 2],
                         [math.nan, 0.5], [0.5, math.inf]])
    # directions: not unit length, or outside the support on the sphere
    pts = [[0, 0, 2.0], [0, 0, 0.5], [0.6, 0.8, 0.1], [0, 0, 0], [math.nan, 0, 1]]
    if case.domain == "hemisphere":
        for z in (-1.0, -0.5, -1e-6):
            pts.append([math.sqrt(1 - z * z), 0, z])
    if case.name == "ggx":
        pts.append([1.0, 0.0, 0.0])  # the horizon: D cos = 0
    if case.name == "uniform_cone":
        c = case.p["cos_max"]
        for z in (c - 1e-6, (c - 1) / 2, -1.0):
            pts.append([math.sqrt(1 - z * z) * 0.6, math.sqrt(1 - z * z) * 0.8, z])
    if case.name == "uniform_sphere":
        pts = [p for p in pts if abs(np.linalg.norm(p) - 1) > 1e-6 or not np.isfinite(p).all()]
    return np.array(pts, dtype=float)


@cases()
def test_pdf_is_zero_and_invert_nan_outside_the_support(case):
    s = case.make()
    x = outside_points(case)
    p = s.pdf(x)
    assert np.all(p == 0), f"{case}: pdf != 0 outside the support (x, pdf):\n  {fmt(x[p != 0], p[p != 0])}"
    v = s.invert(x)
    bad = ~np.isnan(v) if v.ndim == 1 else ~np.isnan(v).all(axis=1)
    assert not bad.any(), f"{case}: invert != NaN outside the support (x, invert):\n  {fmt(x[bad], v[bad])}"


@pytest.mark.parametrize("case", [c for c in CASES if c.name == "piecewise_constant_1d"], ids=str)
def test_points_near_table_breakpoints_stay_in_their_bin(case):
    """u within a few 2^-52 of a CDF value (and the largest canonical uniforms, 1 - 2^-53)
    used to round x onto the edge of the neighbouring bin, where pdf(x) is that bin's
    density, possibly 0; the sampler must keep x inside the bin u selected."""
    s = case.make()
    t = np.asarray(case.table, dtype=float)
    u = np.concatenate([breakpoint_u(table_cdf(t)[1:-1]), canonical(2**52 - 1 - np.arange(64))])
    x, p = s.sample(u)
    q = s.pdf(x)
    bad = (p != q) | (p <= 0)
    assert not bad.any(), f"{case}: (u, x, sample pdf, pdf(x)):\n  {fmt(u[bad], x[bad], p[bad], q[bad])}"
    np.testing.assert_allclose(s.invert(x), u, atol=1e-9)


def neumaier_cdf(values: np.ndarray) -> np.ndarray:
    """A table's CDF as the core builds it: running compensated (Neumaier) sums over the
    values in order, each divided by the total, the last entry set to 1."""
    sums, total, comp = [0.0], 0.0, 0.0
    for v in map(float, values):
        t = total + v
        comp += (total - t) + v if abs(total) >= abs(v) else (v - t) + total
        total = t
        sums.append(total + comp)
    cdf = np.array(sums) / sums[-1]
    cdf[-1] = 1.0
    return cdf


@pytest.mark.parametrize("bins", [1, 2, 3, 7, 8, 15, 16, 17, 31, 32, 33, 63, 64, 65, 80, 200, 512, 513,
                                  4096, 4097, 40_000])
def test_table_bins_are_the_last_with_cdf_at_or_below_u(bins):
    """The bin a table sampler picks for u is pbrt's, the last o with cdf[o] <= u moved down
    past empty bins, for tables counted in one level (up to 16, 32 or 64 bins by ISA) and in
    two to five, with empty bins and u at, just below and just above every CDF value."""
    rng = np.random.default_rng(bins)
    t = rng.random(bins) ** 4
    t[rng.random(bins) < 0.3] = 0.0
    t[rng.integers(bins)] = 1.0
    s = rest.sampler("piecewise_constant_1d", table=t, a=0.0, b=1.0)
    cdf = neumaier_cdf(t)
    u = np.concatenate([rng.random(20_000), cdf, np.nextafter(cdf, 0.0), np.nextafter(cdf, 1.0)])
    u = u[(u >= 0) & (u <= 1)]
    want = np.minimum(np.searchsorted(cdf, u, side="right") - 1, bins - 1)
    full = cdf[1:] > cdf[:-1]
    below = np.maximum.accumulate(np.where(full, np.arange(bins), 0))   # last non-empty bin <= o, or 0
    want = below[want]
    x, p = s.sample(u)
    got = np.minimum(np.floor(x * bins), bins - 1).astype(int)
    bad = got != want
    assert not bad.any(), f"(u, bin, pbrt's bin):\n  {fmt(u[bad], got[bad], want[bad])}"


@pytest.mark.parametrize("shape", [(1, 1), (3, 5), (16, 16), (8, 64), (64, 8), (128, 256)])
def test_table_2d_pdf_in_batches_equals_pdf_point_by_point(shape):
    """pdf of many points (vector lanes) and of one point at a time (the scalar path) agree
    bit for bit, on cell edges, the square's boundary, just outside it and inside empty rows."""
    rng = np.random.default_rng(shape[0] * 1000 + shape[1])
    t = rng.random(shape)
    t[rng.random(shape) < 0.2] = 0.0
    t[rng.integers(shape[0])] = 0.0
    t[0, 0] = 1.0
    s = rest.sampler("piecewise_constant_2d", table=t)
    edges = np.stack([rng.integers(0, shape[1] + 1, 3000) / shape[1],
                      rng.integers(0, shape[0] + 1, 3000) / shape[0]], axis=1)
    x = np.concatenate([rng.random((3000, 2)) * 1.2 - 0.1, edges,
                        np.nextafter(edges, rng.choice([-1.0, 2.0], edges.shape))])
    batch = s.pdf(x)
    one = np.array([s.pdf(x[i:i + 1])[0] for i in range(len(x))])
    bad = batch.view(np.uint64) != one.view(np.uint64)
    assert not bad.any(), f"(x, batch pdf, one point's pdf):\n  {fmt(x[bad], batch[bad], one[bad])}"
    assert (batch[(x < 0).any(axis=1) | (x > 1).any(axis=1)] == 0).all()


def test_a_bin_edge_near_zero_ends_the_move_into_the_bin():
    """Over [-0.3, 1.1] in 14 bins, u = 3/14 puts x at -2.8e-17 + rounding, just above bin 3's
    edge near 0 in x but in bin 2 by bin_of_x; the sampler moves x into bin 3.  Stepping one ulp
    at a time, it took ~10^15 steps there (the ulps near 0 are tiny): sample() never returned.
    Run in a subprocess so that a regression fails in a minute instead of hanging the suite."""
    code = ("import numpy as np, reference_estimators as rest\n"
            "a = -3 * 0.1\n"
            "s = rest.sampler('piecewise_constant_1d', table=np.ones(14), a=a, b=a + 14 * 0.1)\n"
            "x, p = s.sample(np.array([3 / 14]))\n"
            "print(repr(float(x[0])))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    x = float(r.stdout)
    a, b = -3 * 0.1, -3 * 0.1 + 14 * 0.1

    def bin_of_x(v):   # the sampler's bin_of_x, the same double operations
        return min(int((v - a) / (b - a) * 14), 13)

    # the first double of bin 3: the nearest to where rounding left x
    assert bin_of_x(x) == 3 and bin_of_x(np.nextafter(x, -1.0)) == 2, x
    assert abs(x) < 1e-15


@pytest.mark.parametrize("u", [np.nan, -0.25, 1.5, np.inf])
@pytest.mark.parametrize("name", ["piecewise_constant_1d", "piecewise_constant_2d", "ggx", "linear"])
def test_sample_refuses_uniforms_outside_the_unit_interval(name, u):
    """Canonical uniforms outside [0, 1] (or NaN) are refused with the count and an example
    (a table sampler's search has no bin for them: it used to hang)."""
    s = rest.sampler(name, table=np.ones((3, 4)) if name.endswith("2d") else np.ones(4)) \
        if name.startswith("piecewise") else rest.sampler(name)
    us = np.full((5, s.udim), 0.5)
    us[3, -1] = u
    refusal = r"canonical uniforms in \[0, 1\]; 1 of \d+ values are not \(u\[3\] = "
    with pytest.raises(ValueError, match=refusal):
        s.sample(us if s.udim > 1 else us[:, 0])
    x, p = s.sample(np.zeros((2, s.udim)) if s.udim > 1 else np.array([0.0, 1.0]))   # the ends are valid
    assert np.all(np.isfinite(p))


@pytest.mark.parametrize("case", [c for c in CASES if c.table is not None and 0 in np.ravel(c.table)],
                         ids=str)
def test_pdf_is_zero_inside_empty_table_bins(case):
    s = case.make()
    t = np.asarray(case.table, dtype=float)
    if t.ndim == 1:
        a, b = case.p["a"], case.p["b"]
        centres = a + (b - a) * (np.flatnonzero(t == 0) + 0.5) / t.size
        x = centres
    else:
        rows, cols = t.shape
        r = np.flatnonzero(t.sum(axis=1) == 0)
        yy, xx = np.meshgrid((r + 0.5) / rows, (np.arange(cols) + 0.5) / cols, indexing="ij")
        x = np.column_stack([xx.ravel(), yy.ravel()])
    p = s.pdf(x)
    assert np.all(p == 0), f"{case}: pdf != 0 inside empty bins (x, pdf):\n  {fmt(x[p != 0], p[p != 0])}"


# --- distribution of draw(): Kolmogorov-Smirnov --------------------------------------------
KS_N = 100_000
KS_SEED = 1
KS_ALPHA = 1e-3


@cases(ONE_D)
def test_draw_follows_the_exact_cdf_ks(case):
    """KS test of draw(100_000, seed=1) against the exact CDF (written here from the
    formula).  Family-wise alpha = 1e-3 over the 1-D samplers, Bonferroni: each test at
    1e-3 / len(ONE_D)."""
    s = case.make()
    x, p, diag = s.draw(KS_N, seed=KS_SEED)
    assert x.shape == (KS_N,) and diag["drawn"] == KS_N and diag["candidates"] == KS_N
    res = stats.kstest(x, cdf_1d(case))
    alpha = KS_ALPHA / len(ONE_D)
    assert res.pvalue > alpha, f"{case}: KS D = {res.statistic:.5g}, p = {res.pvalue:.3g} < {alpha:.3g}"


def direction_marginals():
    out = []
    for c in DIRECTIONS:
        out += [(c, "z"), (c, "azimuth")]
    out += [(c, axis) for c in CASES if c.domain == "square" for axis in ("x", "y")]
    return out


MARGINALS = direction_marginals()


def marginal_cdf(case: Case, which: str):
    p = case.p
    if which == "azimuth":
        return lambda t: np.clip(t, 0, 1)
    if case.domain == "square":
        t = np.asarray(case.table, dtype=float)
        rows, cols = t.shape
        if which == "y":
            edges, cdf = np.linspace(0, 1, rows + 1), table_cdf(t.sum(axis=1))
            return lambda y: np.interp(y, edges, cdf)
        edges, cdf = np.linspace(0, 1, cols + 1), table_cdf(t.sum(axis=0))
        return lambda x: np.interp(x, edges, cdf)
    if case.name == "uniform_hemisphere":
        return lambda z: np.clip(z, 0, 1)
    if case.name == "uniform_sphere":
        return lambda z: np.clip((z + 1) / 2, 0, 1)
    if case.name == "cosine_hemisphere":
        return lambda z: np.clip(z, 0, 1) ** 2
    if case.name == "uniform_cone":
        c = p["cos_max"]
        return lambda z: np.clip((z - c) / (1 - c), 0, 1)
    if case.name == "ggx":
        # P(Z <= z) = P(tan^2 theta >= t2(z)) = alpha^2 / (alpha^2 + tan^2 theta(z))
        a2 = p["alpha"] ** 2

        def f(z):
            z = np.clip(z, 0, 1)
            t2 = (1 - z * z) / np.maximum(z * z, 1e-300)
            return a2 / (a2 + t2)
        return f
    raise AssertionError(f"no marginal for {case}")


@pytest.mark.parametrize("case,which", MARGINALS, ids=[f"{c}-{w}" for c, w in MARGINALS])
def test_draw_marginals_follow_the_exact_cdf_ks(case, which):
    """KS test of one marginal of draw(100_000, seed=1) (cos theta and the azimuth fraction
    for directions; x and y for the 2-D table) against its exact CDF.  Family-wise alpha =
    1e-3 over these marginals, Bonferroni."""
    s = case.make()
    w, _, _ = s.draw(KS_N, seed=KS_SEED)
    data = {"z": lambda: w[:, 2], "azimuth": lambda: azimuth_fraction(w),
            "x": lambda: w[:, 0], "y": lambda: w[:, 1]}[which]()
    res = stats.kstest(data, marginal_cdf(case, which))
    alpha = KS_ALPHA / len(MARGINALS)
    assert res.pvalue > alpha, (f"{case} {which}: KS D = {res.statistic:.5g}, "
                                f"p = {res.pvalue:.3g} < {alpha:.3g}")


# --- draw() is independent of the thread count ---------------------------------------------
THREAD_N = 3 * CHUNK + 4321  # not a multiple of the chunk size


@cases()
def test_draw_is_identical_for_any_thread_count(case):
    s = case.make()
    x1, p1, d1 = s.draw(THREAD_N, seed=7, threads=1)
    for t in (2, 3):
        xt, pt, dt = s.draw(THREAD_N, seed=7, threads=t)
        assert np.array_equal(x1, xt), f"{case}: points differ between threads=1 and threads={t}"
        assert np.array_equal(p1, pt), f"{case}: pdfs differ between threads=1 and threads={t}"
        assert dt["candidates"] == d1["candidates"] and dt["drawn"] == d1["drawn"] == THREAD_N


def test_draw_seeds_give_different_streams():
    s = rest.sampler("linear")
    a, _, _ = s.draw(1000, seed=1)
    b, _, _ = s.draw(1000, seed=2)
    assert not np.array_equal(a, b)


# --- the rejection method -------------------------------------------------------------------
GAUSS_REF = 0.5 * math.sqrt(math.pi) * math.erf(1.0)


def proposal() -> rest.Sampler:
    return rest.sampler("linear", a=1, b=0.37)


def valid_bound() -> float:
    """1.01 x max of f/p over a fine grid: a valid c for exp(-x^2) under linear(1, 0.37)."""
    x = np.linspace(0, 1, 200_001)
    return 1.01 * float(np.max(np.exp(-x * x) / proposal().pdf(x)))


def test_gaussian_reference_matches_catalogue():
    assert rest.integrand("gaussian").reference == pytest.approx(GAUSS_REF, rel=1e-15)


def test_rejection_sampler_with_valid_bound():
    """Valid c: no bound violations; acceptance rate = reference / c within 5 sigma
    (binomial over the candidates); KS against erf(x) / erf(1) at alpha = 1e-3, seed 1."""
    c = valid_bound()
    s = rest.rejection_sampler("gaussian", proposal(), c)
    assert s.method == "rejection" and not s.invertible
    n = 200_000
    x, p, diag = s.draw(n, seed=1)
    assert diag["counts"]["bound_violation"] == 0, f"violations with valid c = {c}: {diag['examples']}"
    assert not any(e["issue"] == "bound_violation" for e in diag["examples"])
    assert diag["drawn"] == n and x.shape == (n,)
    k = diag["candidates"]
    assert k > n, f"candidates {k} <= drawn {n}"
    rate, expected = n / k, GAUSS_REF / c
    sigma = math.sqrt(expected * (1 - expected) / k)
    assert abs(rate - expected) < 5 * sigma, f"acceptance {rate:.6f}, expected {expected:.6f} +- {sigma:.2g}"
    assert np.all((x >= 0) & (x <= 1))
    assert np.allclose(p, np.exp(-x * x) / GAUSS_REF, rtol=1e-12), "draw() pdf is not target / reference"
    assert np.allclose(s.pdf(x), p, rtol=1e-12)
    res = stats.kstest(x, lambda t: special.erf(np.clip(t, 0, 1)) / special.erf(1.0))
    assert res.pvalue > 1e-3, f"KS D = {res.statistic:.5g}, p = {res.pvalue:.3g}"


def test_rejection_sampler_reports_bound_violations_when_c_is_too_small():
    c = 0.5 * valid_bound()
    s = rest.rejection_sampler("gaussian", proposal(), c)
    x, p, diag = s.draw(50_000, seed=1)
    assert diag["counts"]["bound_violation"] > 0, f"no violation reported with c = {c}: {diag['counts']}"
    ex = [e for e in diag["examples"] if e["issue"] == "bound_violation"]
    assert ex, f"no bound_violation examples: {diag['examples']}"
    for e in ex:
        (pt,) = e["point"]
        assert 0 <= pt <= 1, e
        assert e["value"] > 1, e
        expect = math.exp(-pt * pt) / (c * float(proposal().pdf(np.array([pt]))[0]))
        assert e["value"] == pytest.approx(expect, rel=1e-12), e


def test_rejection_sampler_draw_identical_for_any_thread_count():
    s = rest.rejection_sampler("gaussian", proposal(), 0.5 * valid_bound())
    x1, p1, d1 = s.draw(THREAD_N, seed=3, threads=1)
    for t in (2, 3):
        xt, pt, dt = s.draw(THREAD_N, seed=3, threads=t)
        assert np.array_equal(x1, xt) and np.array_equal(p1, pt), f"threads={t} differs"
        assert dt["counts"] == d1["counts"] and dt["candidates"] == d1["candidates"]


def test_rejection_sampler_sample_raises_and_names_draw():
    s = rest.rejection_sampler("gaussian", proposal(), valid_bound())
    with pytest.raises(ValueError, match=r"draw"):
        s.sample(np.full((4, s.udim), 0.5))


def test_rejection_sampler_invert_raises():
    s = rest.rejection_sampler("gaussian", proposal(), valid_bound())
    with pytest.raises(ValueError, match="no inverse"):
        s.invert(np.array([0.5]))


@pytest.mark.parametrize("c", [0.0, -1.0, math.inf, math.nan])
def test_rejection_sampler_rejects_bad_bound(c):
    with pytest.raises(ValueError, match=r"'c' must be finite and > 0"):
        rest.rejection_sampler("gaussian", proposal(), c)


def test_rejection_sampler_rejects_dimension_mismatch():
    with pytest.raises(ValueError, match="proposal"):
        rest.rejection_sampler("gaussian", rest.sampler("uniform_hemisphere"), 1.0)


def test_hit_or_miss_reports_bound_violations_when_c_is_too_small():
    est = rest.integrate("gaussian", rest.rejection(proposal(), 0.5 * valid_bound()), 100_000, seed=0)
    assert est.counts["bound_violation"] > 0, est.counts
    assert not est.ok
    assert "bound_violation" in est.issues
    ex = [e for e in est.examples if e["issue"] == "bound_violation"]
    assert ex and all(0 <= e["point"][0] <= 1 and e["value"] > 1 for e in ex), ex


def test_hit_or_miss_with_valid_bound_is_clean_and_unbiased():
    est = rest.integrate("gaussian", rest.rejection(proposal(), valid_bound()), 200_000, seed=0)
    assert est.counts["bound_violation"] == 0, est.examples
    assert est.ok, est.issues
    assert abs(est.z_score()) < 5, f"mean {est.mean} +- {est.stderr}, reference {GAUSS_REF}"


# --- argument errors ----------------------------------------------------------------------
def test_unknown_sampler_lists_known_samplers():
    with pytest.raises(ValueError, match=r"unknown sampler 'nope'; known samplers: .*ggx") as e:
        rest.sampler("nope")
    for name in REGISTRY:
        assert name in str(e.value)


def test_unknown_parameter_is_named():
    with pytest.raises(ValueError, match=r"sampler 'ggx' has no parameter 'beta'; its parameters: alpha"):
        rest.sampler("ggx", beta=0.3)
    with pytest.raises(ValueError, match=r"has no parameter 'k'; its parameters: \(none\)"):
        rest.sampler("uniform_sphere", k=1)


@pytest.mark.parametrize("name,params,message", [
    ("ggx", {"alpha": 0}, "'alpha' must be > 0"),
    ("ggx", {"alpha": -0.1}, "'alpha' must be > 0"),
    ("exponential", {"rate": -1}, "'rate' must be > 0"),
    ("exponential", {"rate": 0}, "'rate' must be > 0"),
    ("power", {"k": -1}, "'k' must be > -1"),
    ("uniform_cone", {"cos_max": 1}, "'cos_max' must be in (-1, 1)"),
    ("uniform_cone", {"cos_max": -1}, "'cos_max' must be in (-1, 1)"),
    ("lomax", {"shape": 0}, "'shape' must be > 0"),
    ("linear", {"a": -1}, "'a' must be >= 0"),
    ("linear", {"a": 0, "b": 0}, "'a + b' must be > 0"),
    ("trimmed_logistic", {"s": 0}, "'s' must be > 0"),
    ("trimmed_logistic", {"a": 1, "b": 0}, "'b' must be > a"),
    ("ggx", {"alpha": math.inf}, "'alpha' must be finite"),
    ("ggx", {"alpha": math.nan}, "'alpha' must be finite"),
])
def test_invalid_parameter_names_argument_and_rule(name, params, message):
    with pytest.raises(ValueError, match=re.escape(f"sampler '{name}': parameter {message}")):
        rest.sampler(name, **params)


def test_non_numeric_parameter_is_a_type_error():
    with pytest.raises(TypeError, match=r"parameter 'alpha' must be a number"):
        rest.sampler("ggx", alpha="0.1")


@pytest.mark.parametrize("name,table,message", [
    ("piecewise_constant_1d", [1.0, 2.0, -1.0], r"table values must be finite and >= 0, got -1 at index 2"),
    ("piecewise_constant_1d", [1.0, math.nan], r"table values must be finite and >= 0, got nan at index 1"),
    ("piecewise_constant_1d", [1.0, math.inf], r"table values must be finite and >= 0, got inf at index 1"),
    ("piecewise_constant_1d", [0.0, 0.0, 0.0], r"table values must not all be 0"),
    ("piecewise_constant_2d", [[1.0, 2.0], [-0.5, 1.0]],
     r"table values must be finite and >= 0, got -0.5 at index 2"),
    ("piecewise_constant_2d", [[1.0, math.nan], [0.5, 1.0]],
     r"table values must be finite and >= 0, got nan at index 1"),
    ("piecewise_constant_2d", np.zeros((3, 4)), r"table values must not all be 0"),
    ("piecewise_constant_2d", [1.0, 2.0, 3.0], r"table must be 2-dimensional"),
])
def test_bad_tables_are_rejected(name, table, message):
    with pytest.raises(ValueError, match=rf"sampler '{name}': {message}"):
        rest.sampler(name, table=np.array(table, dtype=float))


def test_table_required_and_refused():
    with pytest.raises(ValueError, match=r"sampler 'piecewise_constant_1d' needs a table"):
        rest.sampler("piecewise_constant_1d")
    with pytest.raises(ValueError, match=r"sampler 'ggx' takes no table"):
        rest.sampler("ggx", table=[1.0, 2.0])


@pytest.mark.parametrize("case,shape,want", [
    (Case("ggx", "ggx"), (5, 3), r"'u' must have shape (N, 2), got (5, 3)"),
    (Case("ggx", "ggx"), (5,), r"'u' must have shape (N, 2), got (5,)"),
    (Case("pc2d", "piecewise_constant_2d", table=PC2D_TABLE), (5, 1),
     r"'u' must have shape (N, 2), got (5, 1)"),
    (Case("linear", "linear"), (5, 2), r"'u' must have shape (N, 1) or (N,), got (5, 2)"),
    (Case("linear", "linear"), (5, 1, 1), r"'u' must have shape (N, 1) or (N,), got (5, 1, 1)"),
])
def test_sample_rejects_u_of_the_wrong_shape(case, shape, want):
    with pytest.raises(ValueError, match=re.escape(want)):
        case.make().sample(np.full(shape, 0.5))


@pytest.mark.parametrize("case,shape,want", [
    (Case("ggx", "ggx"), (5, 2), r"'x' must have shape (N, 3), got (5, 2)"),
    (Case("uniform_sphere", "uniform_sphere"), (3,), r"'x' must have shape (N, 3), got (3,)"),
    (Case("pc2d", "piecewise_constant_2d", table=PC2D_TABLE), (5, 3),
     r"'x' must have shape (N, 2), got (5, 3)"),
    (Case("exponential", "exponential"), (5, 2), r"'x' must have shape (N, 1) or (N,), got (5, 2)"),
])
def test_pdf_and_invert_reject_x_of_the_wrong_shape(case, shape, want):
    s = case.make()
    with pytest.raises(ValueError, match=re.escape(want)):
        s.pdf(np.full(shape, 0.5))
    with pytest.raises(ValueError, match=re.escape(want)):
        s.invert(np.full(shape, 0.5))


@pytest.mark.parametrize("n,exc", [(0, ValueError), (-5, ValueError), (2.5, TypeError), (True, TypeError)])
def test_draw_rejects_bad_counts(n, exc):
    with pytest.raises(exc, match="'n'"):
        rest.sampler("linear").draw(n)


# --- estimate_from_samples -----------------------------------------------------------------
def test_estimate_from_samples_clean_call_is_ok_and_unbiased():
    s = proposal()
    x, p, _ = s.draw(200_000, seed=11)
    est = rest.estimate_from_samples("gaussian", x, p)
    assert est.ok, est.issues
    assert est.n == est.drawn == x.size
    assert abs(est.z_score()) < 5, f"mean {est.mean} +- {est.stderr}, reference {GAUSS_REF}"


def test_estimate_from_samples_excludes_and_reports_bad_samples():
    s = proposal()
    x, p, _ = s.draw(10_000, seed=12)
    x, p = x.copy(), p.copy()
    outside = {17: -0.25, 1234: 1.5, 5000: math.inf}
    zero = [3, 4000]
    bad = {99: -1.0, 7777: math.nan, 8888: math.inf}
    for i, v in outside.items():
        x[i] = v
    p[zero] = 0.0
    for i, v in bad.items():
        p[i] = v
    est = rest.estimate_from_samples("gaussian", x, p)
    assert est.counts["outside_domain"] == len(outside), est.counts
    assert est.counts["zero_pdf"] == len(zero), est.counts
    assert est.counts["bad_pdf"] == len(bad), est.counts
    n_bad = len(outside) + len(zero) + len(bad)
    assert est.drawn == x.size and est.n == x.size - n_bad, (est.n, est.drawn)
    assert not est.ok
    by_issue: dict[str, dict[int, tuple]] = {}
    for e in est.examples:
        by_issue.setdefault(e["issue"], {})[e["index"]] = e["point"]
    assert set(by_issue["outside_domain"]) == set(outside), est.examples
    for i, v in outside.items():
        assert by_issue["outside_domain"][i] == (v,), (i, by_issue["outside_domain"][i])
    assert set(by_issue["zero_pdf"]) == set(zero), est.examples
    assert set(by_issue["bad_pdf"]) == set(bad), est.examples
    for i in zero + list(bad):
        assert by_issue["zero_pdf" if i in zero else "bad_pdf"][i] == (x[i],)
    # The remaining samples give the same estimate as if the bad ones were never there.
    keep = np.ones(x.size, dtype=bool)
    keep[list(outside) + zero + list(bad)] = False
    clean = rest.estimate_from_samples("gaussian", x[keep], p[keep])
    assert clean.ok and clean.n == est.n
    assert est.mean == pytest.approx(clean.mean, rel=1e-13)


def test_estimate_from_samples_rejects_mismatched_pdf():
    with pytest.raises(ValueError, match=r"'pdf' must have shape \(3,\)"):
        rest.estimate_from_samples("gaussian", np.array([0.1, 0.2, 0.3]), np.array([1.0, 1.0]))
    with pytest.raises(ValueError, match=re.escape("'points' must have shape (N, 1) or (N,), got (3, 2)")):
        rest.estimate_from_samples("gaussian", np.zeros((3, 2)), np.ones(3))


# --- pbrt-style names ----------------------------------------------------------------------
def test_every_analytic_sampler_has_a_complete_triple_by_name():
    from reference_estimators import sampling

    rng = np.random.default_rng(3)
    for info in rest.samplers():
        if info["needs_table"]:
            continue
        name = info["name"]
        fns = [getattr(sampling, f) for f in (f"sample_{name}", f"{name}_pdf", f"invert_{name}")]
        s = rest.sampler(name)
        u = rng.random((100, s.udim))
        x = fns[0](u)
        np.testing.assert_array_equal(x, s.sample(u)[0], err_msg=name)
        np.testing.assert_array_equal(fns[1](x), s.pdf(x), err_msg=name)
        np.testing.assert_array_equal(fns[2](x), s.invert(x), err_msg=name)
    assert (sampling.sample_ggx(np.full((1, 2), 0.5), alpha=0.3)[0, 2]
            == pytest.approx(1 / math.sqrt(1 + 0.09)))


@pytest.mark.parametrize("integrand, hemisphere", [("ggx_lobe", True), ("spherical_cap", False)])
def test_directions_off_the_sphere_are_counted_in_vector_bodies_and_tails(integrand, hemisphere):
    """Membership (|w|^2 within 1e-5 of 1, z >= 0 on the hemisphere) is counted kWidth directions
    at a time: planted points in every lane position and in the tail, against numpy's count."""
    s = rest.sampler("cosine_hemisphere" if hemisphere else "uniform_sphere")
    w, p = s.sample(np.random.default_rng(5).random((1003, 2)))
    w = w.copy()
    w[[0, 5, 10, 15, 1001]] *= 1.0001                    # off by 2e-4 in |w|^2
    w[[1, 6, 11, 1002], 2] = np.nan
    w[[2, 7], :] *= 1 + 4e-6                              # within the tolerance: on the sphere
    w[[3, 8, 13], 2] = -np.abs(w[[3, 8, 13], 2]) - 1e-3   # below the horizon (renormalised)
    w[[3, 8, 13]] /= np.linalg.norm(w[[3, 8, 13]], axis=1)[:, None]
    r2 = np.sum(w * w, axis=1)
    with np.errstate(invalid="ignore"):
        on = (np.abs(r2 - 1) <= 1e-5) & ((w[:, 2] >= 0) | (not hemisphere))
    est = rest.estimate_from_samples(integrand, w, p)
    assert est.counts["outside_domain"] == int((~on).sum()) == (12 if hemisphere else 9)


@pytest.mark.parametrize("threads", [1, 2])
def test_direction_samplers_screen_their_points_in_their_own_pass(threads):
    """The direction samplers count bad pdfs and points off their domain in the vector lanes
    that draw them (Sampler::sample_valid); what they find is reported exactly as the separate
    screening of given points reports it: the same counts, the same examples."""
    s = rest.sampler("ggx", alpha=1e-155)   # alpha^2 is subnormal: D's pdf overflows at every z = 1
    n = 3 * 2048 + 5                         # whole vectors and a scalar tail
    est = rest.integrate("ggx_lobe", rest.importance(s), n, threads=threads)
    x, p = s.sample(rest.points(n, 2))
    ref = rest.estimate_from_samples("ggx_lobe", x, p, sampler=s)
    assert est.issues == ref.issues == {"bad_pdf": n}
    assert est.examples == ref.examples and est.n == 0


@pytest.mark.parametrize("a, b", [(0.0, 1.0), (-0.3, 1.1), (2.0, 6.0), (1.0, 1.0 + 6 * 2.0**-52)])
@pytest.mark.parametrize("table", [np.arange(1.0, 17.0), np.array([0, 3, 0, 0, 1, 5, 0, 2, 2, 0, 1, 4, 0.0])],
                         ids=["16 bins", "13 bins, empty ones"])
def test_table_samplers_agree_in_vector_lanes_and_one_at_a_time(table, a, b):
    """The table samplers check in vector lanes that a block's points landed in their bins and
    send the rest through the scalar step into the bin: a batch against the same uniforms
    passed one at a time (the scalar path alone) gives the same points, pdfs and bins bit for
    bit, on intervals whose width is a power of two or not and on one whose bins hold no double
    ([1, 1 + 6 ulp] in 16 or 13 bins), u at every CDF value and its neighbours included."""
    s = rest.sampler("piecewise_constant_1d", table=table, a=a, b=b)
    cdf = neumaier_cdf(table)
    u = np.concatenate([[0.0, np.nextafter(1.0, 0.0), 1.0], cdf, np.nextafter(cdf, 0.0),
                        np.nextafter(cdf, 1.0), np.random.default_rng(5).random(1000)])
    u = u[(u >= 0) & (u <= 1)]
    x, p = s.sample(u)
    one = [s.sample(u[i:i + 1]) for i in range(u.size)]
    np.testing.assert_array_equal(x.view(np.uint64), np.concatenate([o[0] for o in one]).view(np.uint64))
    np.testing.assert_array_equal(p, np.concatenate([o[1] for o in one]))
    assert np.all((x >= a) & (x <= b))


def test_the_2d_table_sampler_agrees_in_vector_lanes_and_one_at_a_time():
    """The 2-D table sampler reads each point's density off its cells for the row and column
    the point landed in: a batch equals the same uniforms one at a time bit for bit, and each
    density is the marginal's times the row's conditional's, as the tables give them."""
    t = np.random.default_rng(6).gamma(0.7, 1.0, (7, 13))
    t[2] = 0.0
    t[4, 3:6] = 0.0
    s = rest.sampler("piecewise_constant_2d", table=t)
    u = np.random.default_rng(7).random((2003, 2))
    u[:3] = [[0.0, 0.0], [np.nextafter(1.0, 0.0), np.nextafter(1.0, 0.0)], [1.0, 1.0]]
    x, p = s.sample(u)
    one = [s.sample(u[i:i + 1]) for i in range(u.shape[0])]
    np.testing.assert_array_equal(x, np.concatenate([o[0] for o in one]))
    np.testing.assert_array_equal(p, np.concatenate([o[1] for o in one]))
    rows = np.minimum(np.floor(x[:, 1] * 7), 6).astype(int)
    cols = np.minimum(np.floor(x[:, 0] * 13), 12).astype(int)
    marginal = t.mean(axis=1) / t.mean()                     # the rows' densities in y
    with np.errstate(invalid="ignore"):                      # the empty row: never drawn
        conditional = t / t.mean(axis=1, keepdims=True)      # each row's density in x
    np.testing.assert_allclose(p, marginal[rows] * conditional[rows, cols], rtol=1e-13)
    assert np.all(t[rows, cols] > 0)


SMALL_TABLES = [((1, 1), ""), ((2, 1), ""), ((3, 5), ""), ((16, 16), ""), ((16, 64), ""), ((5, 33), ""),
                ((16, 16), "first row empty"), ((9, 12), "first column empty"), ((17, 4), ""), ((16, 65), ""),
                ((6, 6), "an empty cell inside")]


@pytest.mark.parametrize("shape, zeros", SMALL_TABLES)
def test_small_2d_tables_sample_the_same_in_vector_lanes_and_one_at_a_time(shape, zeros):
    """Tables of at most 16 rows and 64 columns whose CDFs have no empty bin after the first
    take the vector kernel of small_table2d.h on AVX-512 builds (Sampler.kernel; whole vectors
    of a batch, while one point alone takes sample_many's path; 17 rows, 65 columns or an empty
    cell inside a row never do): the same points and densities bit for bit, on uniforms that
    are exactly the tables' CDF entries (inverted from the cells' corners), an ulp either side
    of them, 0 and 1."""
    rng = np.random.default_rng(shape[0] * 100 + shape[1])
    t = rng.gamma(0.5, 1.0, shape) + 1e-9
    if zeros == "first row empty":
        t[0] = 0.0
    elif zeros == "first column empty":
        t[:, 0] = 0.0
    elif zeros:
        t[2, 3] = 0.0
    s = rest.sampler("piecewise_constant_2d", table=t)
    fits = shape[0] <= 16 and shape[1] <= 64 and zeros != "an empty cell inside"
    avx512 = rest.build_info()["isa"] == "AVX-512"
    assert s.kernel == ("small table in vector lanes" if fits and avx512 else "batch loop")
    corners = np.stack(np.meshgrid(np.arange(shape[1] + 1) / shape[1], np.arange(shape[0] + 1) / shape[0]),
                       axis=-1).reshape(-1, 2)
    entries = s.invert(np.minimum(corners, np.nextafter(1.0, 0.0)))
    entries = entries[np.all(np.isfinite(entries), axis=1)]
    u = np.concatenate([entries, np.nextafter(entries, 0.0), np.nextafter(entries, 2.0),
                        [[0.0, 0.0], [1.0, 1.0], [0.0, 1.0], [1.0, 0.0], [np.nextafter(1.0, 0.0)] * 2],
                        rng.random((4001, 2))])
    u = np.clip(u, 0.0, 1.0)
    x, p = s.sample(u)
    one = [s.sample(u[i:i + 1]) for i in range(u.shape[0])]
    np.testing.assert_array_equal(x.view(np.uint64), np.concatenate([o[0] for o in one]).view(np.uint64))
    np.testing.assert_array_equal(p.view(np.uint64), np.concatenate([o[1] for o in one]).view(np.uint64))
    rows = np.minimum(np.floor(x[:, 1] * shape[0]), shape[0] - 1).astype(int)
    cols = np.minimum(np.floor(x[:, 0] * shape[1]), shape[1] - 1).astype(int)
    assert np.all(t[rows, cols] > 0)
    np.testing.assert_allclose(p, t[rows, cols] / t.mean(), rtol=1e-12)


@pytest.mark.parametrize("kind", ["random", "sobol", "stratified"])
@pytest.mark.parametrize("n", [1, 7, 2048, 65545, 70001])
def test_an_mis_pair_of_square_samplers_is_its_samplers_and_the_balance_heuristic(n, kind):
    """The general path's MIS of the uniform square and the 2-D table sampler (which screen
    their points in the lanes that draw them; their uniforms, from random points, drawn
    straight into each one's columns, whole generator rows and one value at a time after
    them, and from Sobol' or stratified points taken out of the block's rows by shuffles):
    each contribution is f / (p_0 + p_1) at each technique's point, recomputed from the
    samplers' own batches on the point set's uniforms, bit for bit, at chunk, block, row and
    vector tails."""
    name = "mis_balance:uniform_box+piecewise_constant_2d"
    technique = rest.techniques("gaussian2d")[name]
    box, table = technique.mis
    f = rest.integrand("gaussian2d")
    u = rest.points(n, 4, kind, seed=3)
    x0, p0 = box.sample(u[:, :2])
    x1, p1 = table.sample(u[:, 2:])
    np.testing.assert_array_equal(x0, u[:, :2])   # 0 + 1 u on the unit square
    np.testing.assert_array_equal(p0, np.ones(n))
    f0, f1 = f.eval(x0), f.eval(x1)
    assert np.all(f0 > 0) and np.all(f1 > 0)
    y = (0.0 + f0 / ((0.0 + p0) + table.pdf(x0))) + f1 / ((0.0 + box.pdf(x1)) + p1)
    points = technique if kind == "random" else rest.with_points(technique, kind)
    c = rest.contributions("gaussian2d", points, n, seed=3)
    np.testing.assert_array_equal(c.view(np.uint64), y.view(np.uint64))


@pytest.mark.parametrize("shape", [(16, 16), (4, 128)], ids=["small table in vector lanes", "batch loop"])
@pytest.mark.parametrize("n", [1003, 70001])
def test_a_table_samplers_bad_densities_are_screened_where_they_are_drawn(shape, n):
    """A table of subnormal values has every cell's density overflow to +inf: importance
    sampling and MIS with the uniform square report every sample as a bad pdf (none averaged),
    whether the small-table kernel screens its lanes or the batch loop's points are screened
    after, at vector and block tails."""
    s = rest.sampler("piecewise_constant_2d", table=np.full(shape, 1e-320))
    avx512 = rest.build_info()["isa"] == "AVX-512"
    assert s.kernel == ("small table in vector lanes" if shape == (16, 16) and avx512 else "batch loop")
    assert np.all(s.sample(np.full((9, 2), 0.3))[1] == np.inf)
    box = rest.techniques("gaussian2d")["mis_balance:uniform_box+piecewise_constant_2d"].mis[0]
    for technique in (rest.importance(s), rest.mis([box, s])):
        e = rest.integrate("gaussian2d", technique, n, seed=1)
        assert e.issues == {"bad_pdf": n} and e.n == 0


def test_the_uniform_square_samples_and_rates_its_points_in_vector_lanes():
    """The uniform square's batches (vector lanes, a scalar tail): lo + (hi - lo) u and pdf 1
    inside, 0 outside, at the edges, just past them, and at NaN, in any lane."""
    box = rest.techniques("gaussian2d")["mis_balance:uniform_box+piecewise_constant_2d"].mis[0]
    u = np.random.default_rng(8).random((1003, 2))
    u[:4] = [[0.0, 0.0], [1.0, 1.0], [0.0, 1.0], [np.nextafter(1.0, 0.0), 0.5]]
    x, p = box.sample(u)
    np.testing.assert_array_equal(x, u)
    np.testing.assert_array_equal(p, np.ones(len(u)))
    edges = [0.0, -0.0, 1.0, np.nextafter(0.0, -1.0), np.nextafter(1.0, 2.0), np.nan, -np.inf, np.inf, 0.5]
    pts = np.array([(a, b) for a in edges for b in edges])
    pts = np.concatenate([pts, pts[::-1][:13]])           # 94 points: whole vectors and a tail
    inside = (pts >= 0.0).all(axis=1) & (pts <= 1.0).all(axis=1)
    np.testing.assert_array_equal(box.pdf(pts), np.where(inside, 1.0, 0.0))


@pytest.mark.parametrize("name, params", [
    ("exponential", {}), ("exponential", {"rate": 7.5}), ("linear", {}), ("linear", {"a": 0.0, "b": 1.0}),
    ("power", {}), ("power", {"k": -0.9}), ("power", {"k": 3.0}), ("lomax", {}),
    ("trimmed_logistic", {}), ("trimmed_logistic", {"mu": 0.3, "s": 0.001}),
])
def test_one_dimensional_samplers_agree_in_vector_lanes_and_one_at_a_time(name, params):
    """The 1-D inversion samplers run whole vectors of points and a scalar tail (the same
    templates): a batch against the same uniforms passed one at a time (all tail) gives the
    same points and pdfs bit for bit, u = 0 and points outside the support included."""
    s = rest.sampler(name, **params)
    u = np.concatenate([[0.0, 0.5, np.nextafter(1.0, 0.0)], np.random.default_rng(4).random(2045)])
    x, p = s.sample(u[:, None])
    one = [s.sample(u[i:i + 1, None]) for i in range(u.size)]
    np.testing.assert_array_equal(x, np.concatenate([o[0] for o in one]))
    np.testing.assert_array_equal(p, np.concatenate([o[1] for o in one]))
    probe = np.concatenate([x.ravel(), [-1.0, -0.0, 0.0, 1.0, 1.5, np.inf, np.nan]])
    one_pdf = np.concatenate([s.pdf(probe[i:i + 1, None]) for i in range(probe.size)])
    np.testing.assert_array_equal(s.pdf(probe[:, None]), one_pdf)
