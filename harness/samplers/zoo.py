"""A zoo of correct and subtly wrong samplers (sample, pdf, domain), the hard cases for
chi-square tests: sharp lobes, steps inside cells, integrable singularities, tabulated
environment maps; and mutants that a good test must catch.  Used to measure the false-alarm
rate and the power of check_sampler, and by benchmarks/sampler_tests.py."""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

import reference_estimators as rest

from harness.samplers.domains import Domain

__all__ = ["ZooSampler", "correct", "smooth_warps", "wrong"]


@dataclass(frozen=True)
class ZooSampler:
    name: str
    domain: str | tuple
    sample: Callable[[np.ndarray], np.ndarray]
    pdf: Callable[[np.ndarray], np.ndarray]
    fault: str = ""
    breaks: tuple | None = None     # where the pdf steps, declared (check_sampler's ``breaks``)


def _core(name: str, domain, **params) -> ZooSampler:
    s = rest.sampler(name, **params)
    label = name + ("(" + ", ".join(f"{k}={v:g}" for k, v in params.items()) + ")" if params else "")
    return ZooSampler(label, domain, lambda u: s.sample(u)[0], s.pdf)


def _uniform_theta_sphere() -> ZooSampler:
    """theta = pi u0, phi = 2 pi u1: pdf 1 / (2 pi^2 sin theta), singular at both poles."""
    def sample(u):
        th, ph = math.pi * u[:, 0], 2 * math.pi * u[:, 1]
        return np.column_stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)])

    def pdf(w):
        st = np.sqrt(np.maximum(0.0, 1 - np.clip(w[:, 2], -1, 1) ** 2))
        with np.errstate(divide="ignore"):
            return np.where(st > 0, 1 / (2 * math.pi**2 * st), np.inf)
    return ZooSampler("uniform_theta_sphere (pole singularity)", "sphere", sample, pdf)


def _envmap(table: np.ndarray, scale_texel: tuple[int, int] | None = None,
            declared: bool = False) -> ZooSampler:
    """A lat-long environment map on the sphere: (u, v) from a piecewise-constant table,
    theta = pi v, phi = 2 pi u, pdf_w = pdf_uv / (2 pi^2 sin theta): texel steps and pole
    singularities.  ``scale_texel`` makes the claimed pdf 10 % too large in one texel;
    ``declared``: the texel edges are declared as the pdf's breaks."""
    s = rest.sampler("piecewise_constant_2d", table=table)
    claimed = table.copy()
    if scale_texel is not None:
        claimed[scale_texel] *= 1.1
    c = rest.sampler("piecewise_constant_2d", table=claimed)

    def sample(u):
        uv = s.sample(u)[0]
        th, ph = math.pi * uv[:, 1], 2 * math.pi * uv[:, 0]
        return np.column_stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)])

    def pdf(w):
        z = np.clip(w[:, 2], -1, 1)
        th = np.arccos(z)
        ph = np.mod(np.arctan2(w[:, 1], w[:, 0]) / (2 * math.pi), 1.0)
        st = np.sin(th)
        uv = np.column_stack([ph, np.minimum(th / math.pi, np.nextafter(1, 0))])
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(st > 0, c.pdf(uv) / (2 * math.pi**2 * st), np.inf)
    share = f"{table[scale_texel] / table.sum():.1%} of the mass" if scale_texel is not None else ""
    rows, columns = table.shape
    name = (f"envmap {rows}x{columns} on the sphere" + (", texel edges declared" if declared else "")
            + (f", one texel's pdf 10 % too large ({share})" if scale_texel else ""))
    fault = "one texel's pdf 10 % too large" if scale_texel is not None else ""
    edges = (math.pi * np.arange(1, rows) / rows, 2 * math.pi * np.arange(columns) / columns)
    breaks = Domain("sphere").breaks(*edges) if declared else None
    return ZooSampler(name, "sphere", sample, pdf, fault, breaks)


def _disk_polar() -> ZooSampler:
    """r = u0 (not sqrt): pdf 1 / (2 pi r) per area, singular at the centre."""
    def sample(u):
        r, ph = u[:, 0], 2 * math.pi * u[:, 1]
        return np.column_stack([r * np.cos(ph), r * np.sin(ph)])

    def pdf(x):
        r = np.hypot(x[:, 0], x[:, 1])
        with np.errstate(divide="ignore"):
            return np.where(r <= 1, 1 / (2 * math.pi * r), 0.0)
    return ZooSampler("disk, r = u (centre singularity)", "disk", sample, pdf)


def _disk_uniform() -> ZooSampler:
    def sample(u):
        r, ph = np.sqrt(u[:, 0]), 2 * math.pi * u[:, 1]
        return np.column_stack([r * np.cos(ph), r * np.sin(ph)])
    return ZooSampler("disk, uniform", "disk", sample,
                      lambda x: np.where(np.hypot(x[:, 0], x[:, 1]) <= 1, 1 / math.pi, 0))


def _env_table(seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = rng.gamma(0.7, 1.0, (16, 32))
    t[5:7, 10:14] *= 40  # a bright "sun"
    return t


def correct() -> list[ZooSampler]:
    table1d = np.array([0.0, 1.0, 0.0, 2.0, 0.0, 0.0, 3.0, 0.5, 0.0])
    steps = rest.sampler("piecewise_constant_1d", table=table1d, a=-1.0, b=2.0)
    return [
        _core("linear", "interval", a=1.0, b=0.37),
        _core("power", "interval", k=-0.5),
        _core("power", "interval", k=-0.9),   # a strong singularity: the cubature's tail extrapolated
        _core("trimmed_logistic", "interval", mu=0.3, s=1e-3, a=0.0, b=1.0),
        ZooSampler("piecewise_constant_1d (zero bins, steps in cells)", ("interval", -1.0, 2.0),
                   lambda u: steps.sample(u)[0], steps.pdf),
        _core("cosine_hemisphere", "hemisphere"),
        _core("ggx", "hemisphere", alpha=0.01),
        _core("ggx", "hemisphere", alpha=0.5),
        _core("uniform_cone", "sphere", cos_max=0.9),
        _core("uniform_sphere", "sphere"),
        _uniform_theta_sphere(),
        _envmap(_env_table()),
        _envmap(_env_table(), declared=True),
        ZooSampler("piecewise_constant_2d (texel steps)", "square",
                   lambda u, s=rest.sampler("piecewise_constant_2d", table=_env_table()): s.sample(u)[0],
                   rest.sampler("piecewise_constant_2d", table=_env_table()).pdf),
        _disk_uniform(),
        _disk_polar(),
    ]


def wrong() -> list[ZooSampler]:
    lin = rest.sampler("linear", a=1.0, b=0.37)
    cos = rest.sampler("cosine_hemisphere")
    ggx, ggx_wide = rest.sampler("ggx", alpha=0.01), rest.sampler("ggx", alpha=0.0105)
    power, power_off = rest.sampler("power", k=-0.5), rest.sampler("power", k=-0.48)
    band_mass = 0.5**2 - 0.45**2  # of the cosine lobe in 0.45 < z < 0.5

    def band_pdf(w):
        z = w[:, 2]
        return cos.pdf(w) * np.where((z > 0.45) & (z < 0.5), 1.1, 1.0) / (1 + 0.1 * band_mass)

    def sphere_skewed_azimuth(u):
        z, ph = 1 - 2 * u[:, 0], 2 * math.pi * u[:, 1] ** 1.02
        r = np.sqrt(np.maximum(0, 1 - z * z))
        return np.column_stack([r * np.cos(ph), r * np.sin(ph), z])

    return [
        ZooSampler("linear, pdf 0.5 % too large", "interval", lambda u: lin.sample(u)[0],
                   lambda x: 1.005 * lin.pdf(x), "pdf 0.5 % too large"),
        ZooSampler("cosine, pdf 1.1x in a thin band", "hemisphere", lambda u: cos.sample(u)[0], band_pdf,
                   "pdf 1.1x too large in a thin band (renormalised)"),
        ZooSampler("ggx alpha 0.0105 sampled, 0.01 claimed", "hemisphere", lambda u: ggx_wide.sample(u)[0],
                   ggx.pdf, "lobe 5 % too wide"),
        ZooSampler("power k=-0.48 sampled, -0.5 claimed", "interval", lambda u: power_off.sample(u)[0],
                   power.pdf, "exponent off by 0.02 at a singularity"),
        ZooSampler("sphere, azimuth u^1.02", "sphere", sphere_skewed_azimuth,
                   lambda w: np.full(w.shape[0], 0.25 / math.pi), "azimuth slightly non-uniform"),
        _envmap(_env_table(), scale_texel=np.unravel_index(np.argmax(_env_table()), (16, 32))),  # brightest
        _envmap(_env_table(), scale_texel=np.unravel_index(np.argmax(_env_table()), (16, 32)), declared=True),
    ]


def smooth_warps() -> list[ZooSampler]:
    """Mutants below any bin width: smooth warps of a correct sampler that a binned test at
    1e6 samples misses (issue 17's measured cases), for the transform tests to catch."""
    cos = rest.sampler("cosine_hemisphere")
    ggx, ggx_off = rest.sampler("ggx", alpha=0.1), rest.sampler("ggx", alpha=0.1003)

    def cosine_azimuth_warp(u):
        return cos.sample(np.column_stack([u[:, 0], u[:, 1] ** 1.005]))[0]

    def sphere_tilt(u):
        # density (1 + t z) / (4 pi) by inversion in s = (1 - z) / 2: s + t (s - s^2) = u0
        t = 0.002
        s = ((1 + t) - np.sqrt((1 + t) ** 2 - 4 * t * u[:, 0])) / (2 * t)
        z, ph = 1 - 2 * s, 2 * math.pi * u[:, 1]
        r = np.sqrt(np.maximum(0, 1 - z * z))
        return np.column_stack([r * np.cos(ph), r * np.sin(ph), z])

    pole, env, declared = _uniform_theta_sphere(), _envmap(_env_table()), _envmap(_env_table(), declared=True)

    def pole_azimuth_warp(u):
        return pole.sample(np.column_stack([u[:, 0], u[:, 1] ** 1.005]))

    def envmap_azimuth_warp(u):   # the table's columns (the azimuth) are chosen by u0
        return env.sample(np.column_stack([u[:, 0] ** 1.005, u[:, 1]]))

    return [
        ZooSampler("cosine hemisphere, azimuth u^1.005", "hemisphere", cosine_azimuth_warp, cos.pdf,
                   "azimuth warped by u^1.005"),
        # the same warp where the density is singular at the poles, and has texel steps: the
        # conditional's tables must be accurate there too for the transform to see it
        ZooSampler("uniform_theta_sphere, azimuth u^1.005", "sphere", pole_azimuth_warp, pole.pdf,
                   "azimuth warped by u^1.005"),
        ZooSampler("envmap 16x32, azimuth u^1.005", "sphere", envmap_azimuth_warp, env.pdf,
                   "azimuth warped by u^1.005"),
        ZooSampler("envmap 16x32, texel edges declared, azimuth u^1.005", "sphere", envmap_azimuth_warp,
                   env.pdf, "azimuth warped by u^1.005", declared.breaks),
        ZooSampler("ggx alpha 0.1003 sampled, 0.1 claimed", "hemisphere", lambda u: ggx_off.sample(u)[0],
                   ggx.pdf, "lobe 0.3 % too wide"),
        ZooSampler("sphere, density tilted 0.2 %", "sphere", sphere_tilt,
                   lambda w: np.full(w.shape[0], 0.25 / math.pi), "density (1 + 0.002 z) / 4 pi"),
    ]
