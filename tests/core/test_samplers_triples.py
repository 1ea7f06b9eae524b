"""Every catalogue case's sample / pdf / invert triple: pdfs agree, points in the domain, invert undoes
sample, the pdf integrates to 1 and is 0 outside its support."""
from __future__ import annotations

import math

import numpy as np
from scipy import integrate

from tests.core.sampler_cases import CASES, REGISTRY, Case, breakpoint_u, canonical, cases, fmt, table_cdf


def test_case_list_covers_the_registry():
    missing = set(REGISTRY) - {c.name for c in CASES}
    assert not missing, f"registry samplers without test cases: {sorted(missing)}"


def random_canonical(rng: np.random.Generator, shape) -> np.ndarray:
    return canonical(rng.integers(0, 2**52, size=shape, dtype=np.int64))


EDGE_U = canonical(np.array([0, 1, 2, 1000, 2**50, 2**51 - 1, 2**51, 2**52 - 1001, 2**52 - 2, 2**52 - 1],
                            dtype=np.float64))


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


def circular_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = np.mod(a - b, 1.0)
    return np.minimum(d, 1.0 - d)


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
