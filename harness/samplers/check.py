"""Sampler validation: does a sampler draw what its pdf claims?

Every domain is mapped onto the unit interval or square with a constant Jacobian, so equal
cells there are cells of equal measure:

    interval [a, b]   s = (x - a) / (b - a)                  |D| = b - a
    half_line [0,inf) s = x / (1 + x)                         dx/ds = 1 / (1 - s)^2 (not constant)
    square [0, 1]^2   s = (x, y)                              |D| = 1
    disk (unit)       s = (r^2, phi / 2 pi)                   |D| = pi
    hemisphere (z>0)  s = (cos theta, phi / 2 pi)             |D| = 2 pi   (solid angle)
    sphere            s = ((1 - cos theta) / 2, phi / 2 pi)   |D| = 4 pi

and the claimed density there is q(s) = |D| pdf(x(s)) (pdf(x(s)) dx/ds on the half line).  Expected cell counts come from
adaptive tensor Gauss-Legendre cubature of q over each cell, refined where two rules disagree,
until the error is far below the cell's Poisson noise; what error remains is added to the
chi-square's variance, so a sharp lobe, a step inside a cell or an integrable singularity
can cost power but never cause a false alarm.  Written here because scipy's cubature
integrates one region at a time, where this needs thousands of cells at once, vectorised.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

import reference_estimators as rest

from harness.stats import holm

__all__ = ["Domain", "SamplerCheck", "SamplerTest", "check_sampler", "mcmc_crosscheck", "DOMAINS"]

DOMAINS = ("interval", "half_line", "square", "disk", "hemisphere", "sphere")


# --- domains ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class Domain:
    """A sampling domain and its equal-measure parameterisation s in [0, 1]^k."""

    kind: str
    lo: float = 0.0
    hi: float = 1.0

    @property
    def k(self) -> int:
        return 1 if self.kind in ("interval", "half_line") else 2

    @property
    def udim(self) -> int:
        return self.k

    @property
    def point_dim(self) -> int:
        return {"interval": 1, "half_line": 1, "square": 2, "disk": 2, "hemisphere": 3, "sphere": 3}[self.kind]

    def jacobian(self, s: np.ndarray) -> np.ndarray | float:
        """Measure of the domain per unit of parameter space at s (|D| where constant)."""
        if self.kind == "half_line":
            return 1.0 / (1.0 - s[:, 0]) ** 2
        return {"interval": self.hi - self.lo, "square": 1.0, "disk": math.pi, "hemisphere": 2 * math.pi,
                "sphere": 4 * math.pi}[self.kind]

    def to_points(self, s: np.ndarray) -> np.ndarray:
        if self.kind == "interval":
            return self.lo + (self.hi - self.lo) * s[:, 0]
        if self.kind == "half_line":
            return s[:, 0] / (1.0 - s[:, 0])
        if self.kind == "square":
            return s.copy()
        phi = 2 * math.pi * s[:, 1]
        if self.kind == "disk":
            r = np.sqrt(s[:, 0])
            return np.column_stack([r * np.cos(phi), r * np.sin(phi)])
        z = s[:, 0] if self.kind == "hemisphere" else 1 - 2 * s[:, 0]
        r = np.sqrt(np.maximum(0.0, 1 - z * z))
        return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])

    def to_params(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(s of shape (N, k), mask of points inside the domain)."""
        x = np.asarray(x, dtype=float)
        if self.kind == "interval":
            x = x.reshape(-1)
            s = ((x - self.lo) / (self.hi - self.lo))[:, None]
            return s, np.isfinite(x) & (x >= self.lo) & (x <= self.hi)
        if self.kind == "half_line":
            x = x.reshape(-1)
            return (x / (1.0 + x))[:, None], np.isfinite(x) & (x >= 0)
        if self.kind == "square":
            return x.copy(), np.all(np.isfinite(x), axis=1) & np.all((x >= 0) & (x <= 1), axis=1)
        phi = np.mod(np.arctan2(x[:, 1], x[:, 0]) / (2 * math.pi), 1.0)
        if self.kind == "disk":
            r2 = x[:, 0] ** 2 + x[:, 1] ** 2
            return np.column_stack([r2, phi]), np.all(np.isfinite(x), axis=1) & (r2 <= 1 + 1e-12)
        norm = np.einsum("ij,ij->i", x, x)
        ok = np.all(np.isfinite(x), axis=1) & (np.abs(norm - 1) <= 1e-5)  # float32 unit vectors
        z = np.clip(x[:, 2], -1, 1)
        if self.kind == "hemisphere":
            return np.column_stack([z, phi]), ok & (x[:, 2] >= -1e-12)
        return np.column_stack([(1 - z) / 2, phi]), ok


def _domain(d: str | tuple | Domain) -> Domain:
    if isinstance(d, Domain):
        return d
    if isinstance(d, tuple):
        if len(d) == 3 and d[0] == "interval" and d[2] > d[1]:
            return Domain("interval", float(d[1]), float(d[2]))
        raise ValueError(f"'domain' must be one of {DOMAINS} or ('interval', a, b) with a < b, got {d!r}")
    if d not in DOMAINS:
        raise ValueError(f"'domain' must be one of {DOMAINS} or ('interval', a, b), got {d!r}")
    return Domain(d)


# --- adaptive cubature over many cells at once -------------------------------------------------
_GL_X, _GL_W = np.polynomial.legendre.leggauss(4)
_GL_X, _GL_W = (_GL_X + 1) / 2, _GL_W / 2  # on [0, 1]


def _rule(q: Callable[[np.ndarray], np.ndarray], lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Tensor 4-point Gauss-Legendre integrals of q over boxes [lo, hi] (M, k): (M, m)."""
    m, k = lo.shape
    if k == 1:
        pts = (lo[:, None, 0] + (hi - lo)[:, None, 0] * _GL_X[None, :]).reshape(-1, 1)
        w = _GL_W
    else:
        gx, gy = np.meshgrid(_GL_X, _GL_X, indexing="ij")
        w = np.outer(_GL_W, _GL_W).reshape(-1)
        px = lo[:, None, 0] + (hi - lo)[:, None, 0] * gx.reshape(1, -1)
        py = lo[:, None, 1] + (hi - lo)[:, None, 1] * gy.reshape(1, -1)
        pts = np.column_stack([px.reshape(-1), py.reshape(-1)])
    vals = np.asarray(q(pts), dtype=float)
    vals = vals.reshape(m, w.size, -1)
    return np.einsum("mwc,w->mc", vals, w) * np.prod(hi - lo, axis=1)[:, None]


def _halves(lo: np.ndarray, hi: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """Each box split in two along ``axis``: rows 2i, 2i+1 are the halves of box i."""
    mid = (lo[:, axis] + hi[:, axis]) / 2
    clo, chi = np.repeat(lo, 2, axis=0), np.repeat(hi, 2, axis=0)
    chi[0::2, axis] = mid
    clo[1::2, axis] = mid
    return clo, chi


def cell_integrals(q: Callable[[np.ndarray], np.ndarray], shape: tuple[int, ...], tol: np.ndarray | float,
                   max_depth: int = 24, max_evals: int = 40_000_000) -> tuple[np.ndarray, np.ndarray]:
    """Integrals of q (scalar or vector valued, (M,) or (M, m)) over the cells of a regular
    grid on [0, 1]^k, and their error bounds: arrays (cells, m).

    Each box is integrated by the 4-point tensor rule on itself and on its two halves along
    every axis; where the best split still changes the integral (component 0) by more than
    the box's share of its cell's tolerance, the box is halved along the axis that changed
    most, and so on (up to ``max_depth`` splits or ``max_evals`` evaluations).  Splitting
    along one axis at a time follows a lobe that is thin in one direction only.  The error
    is the change of the last split: honest for smooth parts, an overestimate at steps and
    singularities.
    """
    k = len(shape)
    idx = np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), axis=-1).reshape(-1, k)
    size = np.array(shape, dtype=float)
    lo, hi = idx / size, (idx + 1) / size
    ncell = lo.shape[0]
    tol = np.broadcast_to(np.asarray(tol, dtype=float), (ncell,))
    owner = np.arange(ncell)
    whole = _rule(q, lo, hi)
    total = np.zeros((ncell, whole.shape[1]))
    err = np.zeros_like(total)
    evals = ncell * 4**k
    share = np.ones(ncell)
    for depth in range(max_depth + 1):
        splits = []
        for axis in range(k):
            clo, chi = _halves(lo, hi, axis)
            parts = _rule(q, clo, chi).reshape(-1, 2, whole.shape[1])
            splits.append((clo, chi, parts))
            evals += clo.shape[0] * 4**k
        change = np.stack([np.abs(p.sum(axis=1)[:, 0] - whole[:, 0]) for _, _, p in splits], axis=1)
        best = np.argmax(change, axis=1)
        rows = np.arange(lo.shape[0])
        refined = np.stack([p.sum(axis=1) for _, _, p in splits], axis=1)[rows, best]
        diff = np.abs(refined - whole)
        done = (change[rows, best] <= tol[owner] * share) | (depth == max_depth) | (evals > max_evals)
        np.add.at(total, owner[done], refined[done])
        np.add.at(err, owner[done], diff[done])
        if done.all():
            break
        keep = np.flatnonzero(~done)
        new_lo, new_hi, new_whole = [], [], []
        for axis in range(k):
            sel = keep[best[keep] == axis]
            if sel.size == 0:
                continue
            clo, chi, parts = splits[axis]
            pick = np.stack([2 * sel, 2 * sel + 1], axis=1).reshape(-1)
            new_lo.append(clo[pick])
            new_hi.append(chi[pick])
            new_whole.append(parts[sel].reshape(-1, whole.shape[1]))
            owner_sel = np.repeat(owner[sel], 2)
            share_sel = np.repeat(share[sel] / 2, 2)
            new_lo[-1] = (new_lo[-1], owner_sel, share_sel)
        lo = np.concatenate([t[0] for t in new_lo])
        owner = np.concatenate([t[1] for t in new_lo])
        share = np.concatenate([t[2] for t in new_lo])
        hi = np.concatenate(new_hi)
        whole = np.concatenate(new_whole)
    return total, err


# --- the result ------------------------------------------------------------------------------
@dataclass(frozen=True)
class SamplerCheck:
    """Outcome of :func:`check_sampler`.  ``passed`` is False when a deterministic check
    failed (``failures``) or the Holm-combined statistical tests reject at ``alpha``."""

    passed: bool
    pvalue: float                 # smallest Holm-adjusted p-value of the statistical tests
    alpha: float
    sample_count: int
    tests: pd.DataFrame           # name, statistic, df, pvalue, adjusted, detects
    failures: tuple[dict[str, Any], ...]
    normalization: tuple[float, float]   # integral of the pdf over the domain, its error bound
    residuals: dict[str, np.ndarray] = field(default_factory=dict)  # standardised, per grid; NaN: pooled cell
    # per axis "s0", "s1": observed and expected counts at <= 128 bins (for plots)
    marginals: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)

    def __bool__(self) -> bool:
        return self.passed

    def __str__(self) -> str:
        head = (f"{'PASSED' if self.passed else 'FAILED'}: {self.sample_count} samples, alpha = {self.alpha}, "
                f"Holm-adjusted p = {self.pvalue:.3g}; pdf integrates to {self.normalization[0]:.6f} "
                f"± {self.normalization[1]:.1e}")
        lines = [head]
        for f in self.failures:
            lines.append(f"  {f['check']}: {f['count']} ({f['detail']}); examples: {f['examples']}")
        lines.append(self.tests.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
        return "\n".join(lines)


# --- the check -------------------------------------------------------------------------------
class SamplerTest:
    """The sample-independent part of check_sampler: cubature of the claimed pdf on the base
    grid, done once and reused for any number of samplers or seeds (false-alarm runs)."""

    def __init__(self, pdf: Callable[[np.ndarray], np.ndarray], domain: str | tuple | Domain, *,
                 sample_count: int = 1_000_000, alpha: float = 0.01):
        self.dom = dom = _domain(domain)
        self.pdf = pdf
        self.n = n = int(sample_count)
        if n < 1000:
            raise ValueError(f"'sample_count' must be at least 1000, got {sample_count!r}")
        if not 0 < alpha < 1:
            raise ValueError(f"'alpha' must be in (0, 1), got {alpha!r}")
        self.alpha = alpha
        self.base = base = (4096,) if dom.k == 1 else (128, 256)
        pre_shape = (64,) if dom.k == 1 else (32, 64)
        pre, _ = cell_integrals(lambda sp: np.column_stack([self.q(sp), self.q(sp) ** 2]), pre_shape, 1e-8,
                                max_depth=12)
        self.c = c = float(pre[:, 1].sum() / max(pre[:, 0].sum(), 1e-300))  # E_q[q], in units of q

        def moments(sp: np.ndarray) -> np.ndarray:
            v = self.q(sp)
            h = v / (v + c) if c > 0 else np.zeros_like(v)
            return np.column_stack([v, h * v, h * h * v])

        # tolerance: 1 % of each base cell's Poisson noise, from the pre-pass's expected counts
        per = [b // p for b, p in zip(base, pre_shape)]
        expect = np.maximum(pre[:, 0], 0).reshape(pre_shape)
        for axis, r in enumerate(per):
            expect = np.repeat(expect, r, axis=axis)
        expect = n * expect / int(np.prod(per))
        tol = 0.01 * np.sqrt(np.maximum(expect.reshape(-1), 1.0)) / n / (4 if dom.k == 2 else 2)
        mass3, err3 = cell_integrals(moments, base, tol)
        self.quadrature_faults = int((~np.all(np.isfinite(mass3), axis=1)).sum())
        mass3, err3 = np.nan_to_num(mass3), np.nan_to_num(err3)
        self.mass, self.err = mass3[:, 0].reshape(base), err3[:, 0].reshape(base)
        self.h_moments = (float(mass3[:, 1].sum()), float(mass3[:, 2].sum()), float(err3[:, 1].sum()))
        self.normalization = (float(self.mass.sum()), float(self.err.sum()))

    def q(self, sp: np.ndarray) -> np.ndarray:
        """The claimed density in parameter space: |D| pdf(x(s))."""
        return np.asarray(self.pdf(self.dom.to_points(sp)), dtype=float).reshape(-1) * self.dom.jacobian(sp)

    def check(self, sample: Callable[[np.ndarray], Any], *, seed: int = 0, udim: int | None = None) -> SamplerCheck:
        dom, n, base = self.dom, self.n, self.base
        u = rest.points(n, udim or dom.udim, seed=seed, case_id=0x5A3F)
        out = sample(u)
        x = np.asarray(out[0] if isinstance(out, tuple) else out, dtype=float)
        want = (n,) if dom.point_dim == 1 else (n, dom.point_dim)
        if x.size != n * dom.point_dim:
            raise ValueError(f"'sample' must return points of shape {want} for a {dom.kind}, got {x.shape}")
        x = x.reshape(want)
        failures: list[dict[str, Any]] = []

        def fail(check: str, mask: np.ndarray, detail: str, values: np.ndarray | None = None) -> None:
            where = np.flatnonzero(mask)[:5]
            ex = [{"index": int(i), "point": np.atleast_1d(x[i]).tolist(),
                   **({"value": float(values[i])} if values is not None else {})} for i in where]
            failures.append({"check": check, "count": int(mask.sum()), "detail": detail, "examples": ex})

        s, inside = dom.to_params(x)
        if not inside.all():
            fail("outside_domain", ~inside, f"points outside the {dom.kind}")
        p = np.asarray(self.pdf(x), dtype=float).reshape(-1)
        if p.shape != (n,):
            raise ValueError(f"'pdf' must return shape ({n},), got {p.shape}")
        bad = ~np.isfinite(p) | (p < 0)
        if bad.any():
            fail("bad_pdf", bad, "pdf NaN, infinite or negative at sampled points", p)
        zero = (p == 0) & inside
        if zero.any():
            fail("zero_pdf", zero, "sampled points where the pdf is 0", p)
        if self.quadrature_faults:
            failures.append({"check": "bad_pdf_quadrature", "count": self.quadrature_faults,
                             "detail": "pdf NaN or infinite inside cells (cubature)", "examples": []})
        total, total_err = self.normalization
        if abs(total - 1) > max(1e-3, 10 * total_err):
            failures.append({"check": "normalization", "count": 1,
                             "detail": f"pdf integrates to {total:.6f} ± {total_err:.1e} over the {dom.kind}, not 1",
                             "examples": []})

        counts = _histogram(np.clip(s[inside], 0, np.nextafter(1, 0)), base)
        grids = {"coarse": (16,) if dom.k == 1 else (16, 32), "fine": (512,) if dom.k == 1 else (64, 128)}
        tests, residuals = [], {}
        for name, shape in grids.items():
            o, e, r = (_coarsen(a, shape) for a in (counts, self.mass, self.err))
            stat, df, resid = _chi_square(o.reshape(-1), n * e.reshape(-1), n * r.reshape(-1))
            residuals[name] = np.where(n * e >= 5, resid.reshape(shape), np.nan)  # pooled cells: NaN
            tests.append((f"chi-square {'x'.join(map(str, shape))}", stat, df,
                          stats.chi2.sf(stat, df) if df > 0 else 1.0,
                          "large-scale misfit" if name == "coarse" else "narrow features: lobes, bands, steps"))
        marginals = {}
        for axis in range(dom.k):
            shape = tuple(base[a] if a == axis else 1 for a in range(dom.k))
            o, e, r = (_coarsen(a, shape) for a in (counts, self.mass, self.err))
            stat, df, _ = _chi_square(o.reshape(-1), n * e.reshape(-1), n * r.reshape(-1))
            tests.append((f"marginal s{axis} ({base[axis]} bins)", stat, df,
                          stats.chi2.sf(stat, df) if df > 0 else 1.0, "fine structure along one axis"))
            bins = min(base[axis], 128)
            marginals[f"s{axis}"] = {"observed": o.reshape(bins, -1).sum(axis=1),
                                     "expected": n * e.reshape(bins, -1).sum(axis=1)}
        # pdf moment: sample mean of h(p(X)) against its cubature value; the variance adds the
        # cubature error and a rounding floor (a constant pdf makes h constant)
        e1, e2, e1_err = self.h_moments
        jac = dom.jacobian(s)
        ps = (p * jac)[inside & ~bad] if np.ndim(jac) else p[inside & ~bad] * jac
        hs = ps / (ps + self.c) if self.c > 0 and ps.size else np.zeros(1)
        denom = math.sqrt(max(e2 - e1 * e1, 0.0) / max(hs.size, 1) + e1_err**2 + 1e-24)
        z = (float(hs.mean()) - e1) / denom
        tests.append(("pdf moment", z * z, 1, float(stats.chi2.sf(z * z, 1)), "density wrong where it is high or low"))

        table = pd.DataFrame(tests, columns=["test", "statistic", "df", "pvalue", "detects"])
        rejected, adjusted = holm(np.nan_to_num(table["pvalue"].to_numpy(), nan=0.0), self.alpha)
        table["adjusted"] = adjusted
        passed = not failures and not rejected.any()
        return SamplerCheck(passed, float(adjusted.min()), self.alpha, n, table, tuple(failures), self.normalization,
                            residuals, marginals)


def check_sampler(sample: Callable[[np.ndarray], Any], pdf: Callable[[np.ndarray], np.ndarray],
                  domain: str | tuple | Domain, *, sample_count: int = 1_000_000, seed: int = 0,
                  alpha: float = 0.01, udim: int | None = None) -> SamplerCheck:
    """Test that ``sample`` draws points with the density ``pdf`` claims.

    ``sample`` maps canonical uniforms of shape (N, udim) (default: 1 for intervals, 2 else)
    to points; it may return (points, pdf values), as the core's samplers do.  ``pdf`` maps
    points to the claimed density (per unit length, area, or solid angle; 0 outside its
    support).  Points: (N,) on an interval, (N, 2) on the square and disk, unit vectors
    (N, 3) on the hemisphere and sphere; ``domain`` is one of "interval" ([0, 1]), ("interval",
    a, b), "square", "disk", "hemisphere", "sphere".

    Deterministic checks first, each failure with counts and examples: samples outside the
    domain; samples where the pdf is 0; NaN, infinite or negative pdf values; the pdf not
    integrating to 1 (adaptive cubature, |integral - 1| above 1e-3 and above 10 times the
    quadrature error: a pdf 0.5 % too large fails here, deterministically).

    Then statistical tests, combined by Holm at ``alpha`` (the false-alarm rate;
    tests/samplers/test_sampler_check.py measures it over 200 seeds per correct sampler):
      chi-square, coarse grid   what a sampler gets wrong over large regions;
      chi-square, fine grid     narrow features: a wrong lobe width, a band 10 % too dense;
      marginals (1-D, fine)     along each axis at 128/256 bins (4096 on an interval), what
                                2-D cells average away;
      pdf moment                E[h(pdf(X))] with h(p) = p / (p + c) bounded, against its
                                cubature value: a density wrong where it is high or low.
    Expected counts below 5 are pooled; residual cubature error enters the variance.
    """
    test = SamplerTest(pdf, domain, sample_count=sample_count, alpha=alpha)
    return test.check(sample, seed=seed, udim=udim)


def _histogram(s: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    idx = np.zeros(s.shape[0], dtype=np.int64)
    for axis, m in enumerate(shape):
        idx = idx * m + np.minimum((s[:, axis] * m).astype(np.int64), m - 1)
    return np.bincount(idx, minlength=int(np.prod(shape))).astype(float).reshape(shape)


def _coarsen(a: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Sums blocks of a base-grid array down to ``shape`` (each base size a multiple)."""
    if a.ndim == 1:
        return a.reshape(shape[0], -1).sum(axis=1)
    return a.reshape(shape[0], a.shape[0] // shape[0], shape[1], a.shape[1] // shape[1]).sum(axis=(1, 3))


def _chi_square(observed: np.ndarray, expected: np.ndarray, quad_err: np.ndarray) -> tuple[float, int, np.ndarray]:
    """Pearson's statistic with all cells of expectation < 5 pooled into one and the cubature
    error added to each cell's variance; standardised residuals per cell."""
    var = expected + quad_err**2
    resid = np.where(var > 0, (observed - expected) / np.sqrt(np.maximum(var, 1e-300)), 0.0)
    big = expected >= 5
    stat = float(np.sum((observed[big] - expected[big]) ** 2 / var[big]))
    cells = int(big.sum())
    small_e, small_o = float(expected[~big].sum()), float(observed[~big].sum())
    if small_e > 0 or small_o > 0:
        pooled_var = small_e + float(np.sum(quad_err[~big] ** 2))
        stat += (small_o - small_e) ** 2 / max(pooled_var, 5.0) if small_e >= 5 or small_o > 0 else 0.0
        cells += 1
    return stat, max(cells - 1, 0), resid


# --- MCMC cross-check ----------------------------------------------------------------------------
def mcmc_crosscheck(sample: Callable[[np.ndarray], Any], pdf: Callable[[np.ndarray], np.ndarray],
                    domain: str | tuple | Domain, *, sample_count: int = 20_000, seed: int = 0,
                    alpha: float = 0.01, udim: int | None = None) -> SamplerCheck:
    """An independent check of ``sample`` against ``pdf`` without quadrature: draws from the
    claimed pdf by MCMC (emcee's affine-invariant ensemble in the equal-measure parameter
    space, thinned by the integrated autocorrelation time) and compares them with the
    sampler's draws by two-sample tests: Kolmogorov-Smirnov on each axis and a chi-square
    contingency test on an 8 x 8 (or 16-bin) grid, combined by Holm at ``alpha``.

    Its false-alarm rate holds when the thinned chain is close to independent draws (the
    thinning is by 2 tau); use it where quadrature is impractical (rough pdfs, many modes
    inside one cell) and as an independent check of the quadrature-based test.
    """
    import emcee

    dom = _domain(domain)
    n = int(sample_count)
    rng = np.random.default_rng(seed)
    k = dom.k

    def log_q(sp: np.ndarray) -> np.ndarray:
        sp = np.atleast_2d(sp)
        ok = np.all((sp >= 0) & (sp <= 1), axis=1)
        out = np.full(sp.shape[0], -np.inf)
        if ok.any():
            v = np.asarray(pdf(dom.to_points(np.clip(sp[ok], 0, 1))), dtype=float).reshape(-1)
            with np.errstate(divide="ignore"):
                out[ok] = np.where(v > 0, np.log(np.maximum(v, 1e-300)), -np.inf)
        return out

    walkers = 32
    start = rng.random((walkers, k))
    sampler = emcee.EnsembleSampler(walkers, k, log_q, vectorize=True)
    sampler.random_state = np.random.RandomState(int(rng.integers(2**31))).get_state()  # reproducible chains
    steps = 2000
    state = sampler.run_mcmc(start, steps, progress=False)
    tau = float(np.max(sampler.get_autocorr_time(tol=0, quiet=True)))
    thin = max(1, int(math.ceil(2 * tau)))
    need = n // walkers + 1
    sampler.reset()
    sampler.run_mcmc(state, need * thin, progress=False)
    chain = sampler.get_chain(thin=thin, flat=True)[:n]

    u = rest.points(n, udim or dom.udim, seed=seed, case_id=0x3C3C)
    out = sample(u)
    x = np.asarray(out[0] if isinstance(out, tuple) else out, dtype=float)
    s, inside = dom.to_params(x)
    failures = []
    if not inside.all():
        failures.append({"check": "outside_domain", "count": int((~inside).sum()), "detail": "points outside the domain",
                         "examples": [{"index": int(i)} for i in np.flatnonzero(~inside)[:5]]})
    s = s[inside]
    tests = []
    for axis in range(k):
        r = stats.ks_2samp(s[:, axis], chain[:, axis])
        tests.append((f"KS two-sample s{axis}", r.statistic, 0, r.pvalue, "marginal mismatch"))
    shape = (16,) if k == 1 else (8, 8)
    a, b = _histogram(np.clip(s, 0, 0.999999), shape).reshape(-1), _histogram(np.clip(chain, 0, 0.999999), shape).reshape(-1)
    keep = (a + b) > 0
    chi = stats.chi2_contingency(np.vstack([a[keep], b[keep]]))
    tests.append(("contingency chi-square", chi.statistic, chi.dof, chi.pvalue, "joint mismatch on a coarse grid"))
    table = pd.DataFrame(tests, columns=["test", "statistic", "df", "pvalue", "detects"])
    rejected, adjusted = holm(table["pvalue"].to_numpy(), alpha)
    table["adjusted"] = adjusted
    table.attrs["tau"], table.attrs["thin"] = tau, thin
    return SamplerCheck(not failures and not rejected.any(), float(adjusted.min()), alpha, n, table, tuple(failures),
                        (math.nan, math.nan))
