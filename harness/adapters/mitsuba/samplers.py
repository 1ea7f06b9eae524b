"""Mitsuba 3 BSDFs, microfacet distributions and environment maps as sample / pdf pairs for
``harness.samplers.check``, and the check Mitsuba's own chi-square cannot make: that the
weight a sampler returns equals eval / pdf.

    s = bsdf_sampler({"type": "roughconductor", "distribution": "ggx", "alpha": 0.01}, wi=45)
    x = s.sample(u)               # u (N, 3) -> directions (N, 3); NaN rows where Mitsuba fails
    s.pdf(x)                      # (N,) solid-angle density of bsdf.pdf
    check_mitsuba_sampler(s)      # a SamplerCheck, like check_sampler's, failures allowed for
    weight_consistency(s)         # a WeightCheck: weight == eval / pdf, sample pdf == pdf()

Conventions.  Directions are unit vectors in the local shading frame (the normal is +z, the
frame is the identity); the incident direction ``wi`` points away from the surface, given as
a polar angle theta_i in degrees (azimuth 0) or as a 3-vector.  u[:, 0] selects the lobe or
component (BSDFs only), u[:, 1:3] is the 2-D sample.  Uniforms arrive as float64 in (0, 1)
and are rounded to float32, clamped below 1 (a float64 just below 1 would round to 1.0, a
value Mitsuba's warps never see).  Domains: the hemisphere z >= 0 for reflection-only BSDFs
and microfacet normals, the sphere for BSDFs with transmission and for environment maps.

Failed samples.  Mitsuba signals a sample it could not produce with a zero weight (the path
integrator ends the path there): a reflection below the horizon, a microfacet the wrong way
round.  ``sample`` returns such rows as NaN, so the samples drawn form a defective
distribution whose pdf integrates to P <= 1 over the domain; P < 1 is normal for microfacet
models at grazing angles.  check_sampler insists on P = 1 and on every sample landing in the
domain, so ``check_mitsuba_sampler`` splits the question in two, both exact under the null:
the failure count is Binomial(N, 1 - P) with P from the cubature of the pdf (an exact
binomial test, its p-value maximised over P's cubature error bound: conservative), and the
directions that were produced follow pdf / P (check_sampler's tests on them, the cubature
reused with its integrals divided by P).  All p-values are combined by Holm.  A pdf 0.5 %
too large is caught by the failure count where P < 1 and by the normalisation (P > 1 + 1e-3)
otherwise.

Variants.  ``mi.set_variant`` is process-global, so every public call takes ``VARIANT_LOCK``,
sets the sampler's variant and uses Mitsuba objects built for that variant only (cached per
variant).  JIT variants (llvm_ad_*, cuda_ad_*) run each batch as one kernel; scalar variants
loop over samples in Python (tens of microseconds per sample: cross-checks on small N only),
and ``check_mitsuba_sampler`` refuses them, as its cubature evaluates the pdf at ~10^7
points.  RGB and mono variants only: spectral variants would need sampled wavelengths.
"""
from __future__ import annotations

import contextlib
import copy
import dataclasses
import math
import os
import threading
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

import reference_estimators as rest

from harness.samplers.check import SamplerCheck, SamplerTest, _domain
from harness.stats import holm

os.environ.setdefault("DRJIT_LIBLLVM_PATH", "/usr/lib/x86_64-linux-gnu/libLLVM-19.so")

__all__ = ["VARIANT_LOCK", "MitsubaSampler", "BSDFSampler", "MicrofacetSampler", "EnvmapSampler", "Mutant",
           "SampleBatch", "WeightCheck", "CatalogueEntry", "bsdf_sampler", "microfacet_sampler", "envmap_sampler",
           "sky_bitmap", "make_sampler", "check_mitsuba_sampler", "weight_consistency", "catalogue", "wrong_catalogue",
           "run_catalogue"]

#: Held while a call sets Mitsuba's (process-global) variant and uses its objects.  Reentrant.
VARIANT_LOCK = threading.RLock()

_SAMPLE_CASE = 0x5A3F   # the stream check_sampler draws its uniforms from
_WEIGHT_CASE = 0x3E17   # weight_consistency's stream
_BELOW_ONE = np.float32(1.0) - np.float32(2.0**-24)


@contextlib.contextmanager
def _mitsuba(variant: str) -> Iterator[Any]:
    import mitsuba as mi  # imported only when a Mitsuba sampler is used

    with VARIANT_LOCK:
        if mi.variant() != variant:
            mi.set_variant(variant)
        yield mi


def _is_jit(variant: str) -> bool:
    return variant.startswith(("llvm_", "cuda_"))


def _check_variant(variant: str) -> None:
    import mitsuba as mi

    if not isinstance(variant, str) or variant not in mi.variants():
        raise ValueError(f"'variant' must be an installed Mitsuba variant ({', '.join(mi.variants())}), got {variant!r}")
    if "spectral" in variant or "polarized" in variant:
        raise ValueError(f"'variant' must be an RGB or mono variant (e.g. 'llvm_ad_rgb', 'scalar_rgb'), got {variant!r}: "
                         "spectral variants need sampled wavelengths, polarized ones return Mueller matrices")


def _direction(wi: float | Sequence[float], name: str = "wi") -> tuple[float, float, float]:
    """A polar angle in degrees (azimuth 0) or a 3-vector, as a unit vector in the upper hemisphere."""
    if np.ndim(wi) == 0:
        theta = float(wi)
        if not 0 <= theta < 90:
            raise ValueError(f"'{name}' as an angle must be a polar angle in degrees in [0, 90), got {wi!r}")
        t = math.radians(theta)
        return (math.sin(t), 0.0, math.cos(t))
    v = np.asarray(wi, dtype=float)
    norm = float(np.linalg.norm(v)) if v.shape == (3,) else 0.0
    if v.shape != (3,) or not np.all(np.isfinite(v)) or norm == 0 or v[2] <= 0:
        raise ValueError(f"'{name}' must be a polar angle in degrees or a 3-vector with z > 0, got {wi!r}")
    return tuple(float(c) for c in v / norm)  # type: ignore[return-value]


def _floats(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32)


def _uniforms(u: np.ndarray, udim: int) -> list[np.ndarray]:
    u = np.asarray(u, dtype=float)
    if u.ndim != 2 or u.shape[1] < udim:
        raise ValueError(f"'u' must have shape (N, {udim}), got {u.shape}")
    return [np.minimum(_floats(u[:, i]), _BELOW_ONE) for i in range(udim)]


def _unit_columns(x: np.ndarray, normalize: bool = True) -> tuple[list[np.ndarray], np.ndarray]:
    """Direction columns as float32 (normalised in float64 first unless ``normalize`` is
    False) and the rows that are finite non-zero vectors (the others become +z)."""
    x = np.asarray(x, dtype=float).reshape(-1, 3)
    norm = np.sqrt(np.einsum("ij,ij->i", x, x))
    ok = np.isfinite(norm) & (norm > 0)
    y = np.where(ok[:, None], x / np.where(ok, norm, 1.0)[:, None] if normalize else x, np.array([0.0, 0.0, 1.0]))
    return [_floats(y[:, i]) for i in range(3)], ok


def _to_numpy(value: Any, n: int) -> np.ndarray:
    a = np.array(value, dtype=np.float64)
    if a.ndim == 2:          # a JIT vector or colour: (channels, N)
        a = a.T
    return np.broadcast_to(a, (n,) + a.shape[1:]).copy() if a.shape[:1] != (n,) else a


def _batch(mi: Any, variant: str, kernel: Callable[..., tuple], columns: list[np.ndarray]) -> list[np.ndarray]:
    """Runs ``kernel(mi, width, *columns)`` once over drjit arrays (JIT variants) or once per
    row with Python floats (scalar variants; width None); returns numpy arrays (N,) or (N, c)."""
    import drjit as dr

    n = len(columns[0])
    if n == 0:  # drjit arrays of width 0 are not all supported: run one dummy row, keep none
        return [o[:0] for o in _batch(mi, variant, kernel, [np.zeros(1, dtype=np.float32) for _ in columns])]
    if _is_jit(variant):
        outs = kernel(mi, n, *(mi.Float(c) for c in columns))
        dr.eval(*outs)
        return [_to_numpy(o, n) for o in outs]
    rows = [kernel(mi, None, *(float(c[i]) for c in columns)) for i in range(n)]
    if not rows:
        return []
    return [np.array([np.asarray(r[k], dtype=np.float64) for r in rows]) for k in range(len(rows[0]))]


# --- samplers --------------------------------------------------------------------------------
@dataclass(frozen=True)
class SampleBatch:
    """What a sampler returned for uniforms ``u``: directions ``x`` (N, 3) as Mitsuba gave them
    (also where it failed), the weight (N, channels) (None for microfacet distributions), the
    pdf the sample call reported (N,), and ``valid``: the rows Mitsuba produced (weight not all
    zero, pdf > 0, finite direction)."""

    u: np.ndarray
    x: np.ndarray
    weight: np.ndarray | None
    sample_pdf: np.ndarray
    valid: np.ndarray


class MitsubaSampler:
    """Base of the adapters: ``sample(u)`` (N, udim) -> directions (N, 3) with NaN rows for
    failed samples, ``pdf(x)`` (N, 3) -> (N,) per solid angle (0 for non-finite rows),
    ``sample_batch(u)`` -> SampleBatch, ``eval(x)`` -> (N, channels) or None, ``domain``,
    ``udim``, ``name``, ``fingerprint()``."""

    kind = "mitsuba"
    udim = 2
    domain = "sphere"

    def __init__(self, variant: str, name: str):
        _check_variant(variant)
        self.variant = variant
        self.name = name
        self._obj: Any = None

    # subclasses: _build(mi) -> the Mitsuba object; _sample_kernel, _pdf_kernel, _eval_kernel
    def _object(self, mi: Any) -> Any:
        """The Mitsuba object, built once for this sampler's variant; call with the variant set
        (inside ``_mitsuba(self.variant)``), as every method does."""
        if self._obj is None:
            self._obj = self._build(mi)
        return self._obj

    def _build(self, mi: Any) -> Any:
        raise NotImplementedError

    def sample_batch(self, u: np.ndarray) -> SampleBatch:
        cols = _uniforms(u, self.udim)
        with _mitsuba(self.variant) as mi:
            obj = self._object(mi)
            out = _batch(mi, self.variant, lambda m, w, *c: self._sample_kernel(m, obj, w, *c), cols)
        x, weight, spdf = out if len(out) == 3 else (out[0], None, out[1])
        x = x.reshape(-1, 3)
        valid = np.all(np.isfinite(x), axis=1) & (spdf > 0)
        if weight is not None:
            weight = weight.reshape(len(x), -1)
            valid &= np.any(weight != 0, axis=1)
        return SampleBatch(np.asarray(u, dtype=float), x, weight, spdf, valid)

    def sample(self, u: np.ndarray) -> np.ndarray:
        b = self.sample_batch(u)
        return np.where(b.valid[:, None], b.x, np.nan)

    def pdf(self, x: np.ndarray, *, normalize: bool = True) -> np.ndarray:
        """Density per solid angle at directions x (N, 3), normalised in float64 and rounded
        to float32 (``normalize=False``: rounded as given, to re-evaluate a returned float32
        direction exactly)."""
        cols, ok = _unit_columns(x, normalize)
        with _mitsuba(self.variant) as mi:
            obj = self._object(mi)
            (p,) = _batch(mi, self.variant, lambda m, w, *c: (self._pdf_kernel(m, obj, w, *c),), cols)
        return np.where(ok, p.reshape(-1), 0.0)

    def eval(self, x: np.ndarray, *, normalize: bool = True) -> np.ndarray | None:
        """The value whose ratio to the pdf the sample weight must be (BSDF: f cos theta_o;
        emitter: radiance), (N, channels); None where the sampler has no weight."""
        cols, ok = _unit_columns(x, normalize)
        with _mitsuba(self.variant) as mi:
            obj = self._object(mi)
            (v,) = _batch(mi, self.variant, lambda m, w, *c: (self._eval_kernel(m, obj, w, *c),), cols)
        v = v.reshape(len(ok), -1)
        return np.where(ok[:, None], v, 0.0)

    def fingerprint(self) -> dict[str, Any]:
        import mitsuba as mi

        return {"adapter": "mitsuba", "mitsuba": mi.__version__, "kind": self.kind, "name": self.name,
                "variant": self.variant, **self._spec()}

    def _spec(self) -> dict[str, Any]:
        return {}

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r}, variant={self.variant!r}, domain={self.domain!r})"


class BSDFSampler(MitsubaSampler):
    """A Mitsuba BSDF at a fixed incident direction: ``bsdf.sample(ctx, si, u0, (u1, u2))``,
    ``bsdf.pdf(ctx, si, wo)``, ``bsdf.eval(ctx, si, wo)`` (f times cos theta_o) with a default
    BSDFContext (radiance transport, all lobes) and an identity shading frame."""

    kind = "bsdf"
    udim = 3

    def __init__(self, plugin: dict[str, Any], wi: float | Sequence[float] = 0.0, variant: str = "llvm_ad_rgb",
                 name: str | None = None):
        if not isinstance(plugin, dict) or not isinstance(plugin.get("type"), str):
            raise ValueError(f"'plugin' must be a Mitsuba plugin dict with a 'type' key, got {plugin!r}")
        self.plugin = dict(plugin)
        self.wi = _direction(wi)
        theta = math.degrees(math.acos(min(1.0, self.wi[2])))
        label = name or _plugin_label(self.plugin) + f" θi={theta:g}°"
        super().__init__(variant, label)
        with _mitsuba(self.variant) as mi:
            try:
                bsdf = self._object(mi)
            except Exception as e:  # Mitsuba raises RuntimeError / TypeError for a bad plugin dict
                raise ValueError(f"'plugin': Mitsuba cannot build {self.plugin!r}: {e}") from None
            self.transmits = mi.has_flag(bsdf.flags(), mi.BSDFFlags.Transmission)
            self.delta = mi.has_flag(bsdf.flags(), mi.BSDFFlags.Delta)
        if self.delta:
            raise ValueError(f"'plugin': {self.plugin['type']!r} has a Dirac delta lobe; a sampler test needs a density")
        self.domain = "sphere" if self.transmits else "hemisphere"

    def _build(self, mi: Any) -> Any:
        return mi.load_dict(self.plugin)

    def _si(self, mi: Any, width: int | None) -> Any:
        import drjit as dr

        si = dr.zeros(mi.SurfaceInteraction3f, width) if width is not None else dr.zeros(mi.SurfaceInteraction3f)
        si.wi = mi.Vector3f(*self.wi)
        si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
        si.n = mi.Normal3f(0.0, 0.0, 1.0)
        si.uv = mi.Point2f(0.5, 0.5)
        return si

    def _sample_kernel(self, mi, bsdf, width, u0, u1, u2):
        bs, weight = bsdf.sample(mi.BSDFContext(), self._si(mi, width), u0, mi.Point2f(u1, u2))
        return bs.wo, weight, bs.pdf

    def _pdf_kernel(self, mi, bsdf, width, x, y, z):
        return bsdf.pdf(mi.BSDFContext(), self._si(mi, width), mi.Vector3f(x, y, z))

    def _eval_kernel(self, mi, bsdf, width, x, y, z):
        return bsdf.eval(mi.BSDFContext(), self._si(mi, width), mi.Vector3f(x, y, z))

    def _spec(self) -> dict[str, Any]:
        return {"plugin": self.plugin, "wi": list(self.wi)}


class MicrofacetSampler(MitsubaSampler):
    """``mi.MicrofacetDistribution``: normals m on the hemisphere from ``sample(wi, u)``, their
    density ``pdf(wi, m)`` (D(m) cos theta_m, or the visible normals' G1(wi, m) <wi, m> D(m) /
    cos theta_i).  No weight: ``eval`` is None and only the sample pdf is cross-checked."""

    kind = "microfacet"
    udim = 2
    domain = "hemisphere"

    def __init__(self, distribution: str = "ggx", alpha: float = 0.1, *, visible: bool = True,
                 wi: float | Sequence[float] = 0.0, variant: str = "llvm_ad_rgb", name: str | None = None):
        if distribution not in ("ggx", "beckmann"):
            raise ValueError(f"'distribution' must be 'ggx' or 'beckmann', got {distribution!r}")
        if not (isinstance(alpha, (int, float)) and 0 < alpha <= 10):
            raise ValueError(f"'alpha' must be a roughness in (0, 10], got {alpha!r}")
        self.distribution, self.alpha, self.visible = distribution, float(alpha), bool(visible)
        self.wi = _direction(wi)
        theta = math.degrees(math.acos(min(1.0, self.wi[2])))
        label = name or (f"microfacet {distribution} α={alpha:g} {'visible' if visible else 'all'} normals"
                         + (f" θi={theta:g}°" if visible else ""))
        super().__init__(variant, label)

    def _build(self, mi: Any) -> Any:
        kind = mi.MicrofacetType.GGX if self.distribution == "ggx" else mi.MicrofacetType.Beckmann
        return mi.MicrofacetDistribution(kind, self.alpha, self.visible)

    def _sample_kernel(self, mi, distr, width, u0, u1):
        m, p = distr.sample(mi.Vector3f(*self.wi), mi.Point2f(u0, u1))
        return m, p

    def _pdf_kernel(self, mi, distr, width, x, y, z):
        return distr.pdf(mi.Vector3f(*self.wi), mi.Vector3f(x, y, z))

    def eval(self, x: np.ndarray, *, normalize: bool = True) -> None:
        return None

    def _spec(self) -> dict[str, Any]:
        return {"distribution": self.distribution, "alpha": self.alpha, "visible": self.visible, "wi": list(self.wi)}


class EnvmapSampler(MitsubaSampler):
    """An ``envmap`` emitter seen from the origin: ``sample_direction(it, u)`` -> (ds, radiance
    / pdf), ``pdf_direction(it, ds)``, radiance ``emitter.eval(si)`` with si.wi = -d;
    directions in world space on the sphere (Mitsuba's envmap puts v = 0 of the image at +y)."""

    kind = "envmap"
    udim = 2
    domain = "sphere"

    def __init__(self, bitmap: np.ndarray | None = None, *, plugin: dict[str, Any] | None = None,
                 variant: str = "llvm_ad_rgb", name: str | None = None):
        params = dict(plugin or {"type": "envmap"})
        if params.get("type") != "envmap":
            raise ValueError(f"'plugin' must be an envmap plugin dict ({{'type': 'envmap', ...}}), got {plugin!r}")
        if "bitmap" in params:
            if bitmap is not None:
                raise ValueError("'bitmap': given twice, as an argument and in 'plugin'")
            bitmap = np.array(params.pop("bitmap"))
        if bitmap is None and "filename" not in params:
            bitmap = sky_bitmap()
        self.image = None if bitmap is None else np.ascontiguousarray(bitmap, dtype=np.float32)
        if self.image is not None and (self.image.ndim != 3 or self.image.shape[2] not in (1, 3)
                                       or self.image.shape[1] < 2 or self.image.shape[0] < 2):
            raise ValueError(f"'bitmap' must be a (height, width, 3) or (height, width, 1) array, got {self.image.shape}")
        self.plugin = params
        label = name or ("envmap " + (f"{self.image.shape[1]}x{self.image.shape[0]}" if self.image is not None
                                      else str(self.plugin.get("filename"))))
        super().__init__(variant, label)
        with _mitsuba(self.variant) as mi:
            try:
                self._object(mi)
            except Exception as e:
                raise ValueError(f"'plugin': Mitsuba cannot build an envmap from {self.plugin!r}: {e}") from None

    def _build(self, mi: Any) -> Any:
        d = dict(self.plugin)
        if self.image is not None:
            d["bitmap"] = mi.Bitmap(self.image)
        return mi.load_dict(d)

    @staticmethod
    def _it(mi, width):
        import drjit as dr

        return dr.zeros(mi.Interaction3f, width) if width is not None else dr.zeros(mi.Interaction3f)

    def _ds(self, mi, width, x, y, z):
        import drjit as dr

        ds = dr.zeros(mi.DirectionSample3f, width) if width is not None else dr.zeros(mi.DirectionSample3f)
        ds.d = mi.Vector3f(x, y, z)
        return ds

    def _sample_kernel(self, mi, emitter, width, u0, u1):
        ds, weight = emitter.sample_direction(self._it(mi, width), mi.Point2f(u0, u1))
        return ds.d, weight, ds.pdf

    def _pdf_kernel(self, mi, emitter, width, x, y, z):
        return emitter.pdf_direction(self._it(mi, width), self._ds(mi, width, x, y, z))

    def _eval_kernel(self, mi, emitter, width, x, y, z):
        # emitter.eval at an escaped ray's interaction (wi = -d), as the path integrator calls
        # it; eval_direction would read the sampled ds.uv rather than the direction
        import drjit as dr

        si = dr.zeros(mi.SurfaceInteraction3f, width) if width is not None else dr.zeros(mi.SurfaceInteraction3f)
        si.wi = -mi.Vector3f(x, y, z)
        return emitter.eval(si)

    def _spec(self) -> dict[str, Any]:
        import hashlib

        if self.image is not None:
            digest = hashlib.sha256(self.image.tobytes()).hexdigest()
        else:  # the file's contents, so that an edited map is a different sampler
            with open(str(self.plugin["filename"]), "rb") as f:
                digest = hashlib.sha256(f.read()).hexdigest()
        return {"plugin": {k: v for k, v in self.plugin.items()}, "image_sha256": digest,
                "bitmap_shape": list(self.image.shape) if self.image is not None else None}


def sky_bitmap(width: int = 256, height: int = 128, *, sun_theta: float = 40.0, sun_phi: float = 70.0,
               sun_radius: float = 2.0, sun_radiance: float = 2000.0, sun_edge: float = 1.5) -> np.ndarray:
    """A procedural HDR lat-long sky (height, width, 3) float32: a smooth blue sky brightening
    towards the horizon, a dim smooth ground and a small bright sun: a disk of angular radius
    ``sun_radius`` degrees at polar angle ``sun_theta`` from the image's top and azimuth
    ``sun_phi``, radiance ``sun_radiance`` (with the defaults about 2/3 of the map's
    luminance), its rim falling off smoothly over ``sun_edge`` degrees (about one texel; 0
    gives a hard edge: a 5000:1 step between neighbouring texels).  Row 0 is the top of the
    image (theta = 0), column 0 phi = 0."""
    if width < 4 or height < 2:
        raise ValueError(f"'width' and 'height' must be at least 4 and 2, got {width} x {height}")
    theta = (np.arange(height) + 0.5) / height * math.pi
    phi = (np.arange(width) + 0.5) / width * 2 * math.pi
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    ct = np.cos(th)
    sky = np.where(ct > 0, 0.4 + 0.6 * (1 - ct) ** 2, 0.05 + 0.03 * np.cos(2 * ph) * (-ct))
    img = sky[:, :, None] * np.array([0.55, 0.7, 1.0])[None, None, :]
    ts, ps = math.radians(sun_theta), math.radians(sun_phi)
    sun_dir = np.array([math.sin(ts) * math.cos(ps), math.sin(ts) * math.sin(ps), math.cos(ts)])
    d = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), ct], axis=-1)
    angle = np.degrees(np.arccos(np.clip(d @ sun_dir, -1.0, 1.0)))
    if sun_edge > 0:
        t = np.clip((sun_radius + sun_edge / 2 - angle) / sun_edge, 0.0, 1.0)
        disk = t * t * (3 - 2 * t)
    else:
        disk = (angle <= sun_radius).astype(float)
    img += sun_radiance * disk[:, :, None] * np.array([1.0, 0.95, 0.85])[None, None, :]
    return img.astype(np.float32)


def _plugin_label(plugin: dict[str, Any]) -> str:
    p = plugin
    parts = [p["type"]]
    if "distribution" in p:
        parts.append(str(p["distribution"]))
    if "alpha" in p:
        parts.append(f"α={p['alpha']:g}")
    for key, short in (("sample_visible", "visible"), ("int_ior", "ior")):
        if key in p:
            parts.append(f"{short}={p[key]}")
    return " ".join(parts)


def bsdf_sampler(plugin: dict[str, Any], *, wi: float | Sequence[float] = 0.0, variant: str = "llvm_ad_rgb",
                 name: str | None = None) -> BSDFSampler:
    """A Mitsuba BSDF (a ``mi.load_dict`` plugin dict) as a sampler at incident direction
    ``wi`` (polar angle in degrees, or a 3-vector with z > 0): udim 3 (u0 picks the lobe), the
    hemisphere for reflection-only BSDFs, the sphere for BSDFs with transmission.  BSDFs with
    a Dirac delta lobe (smooth conductors, dielectrics) are refused: they have no density."""
    return BSDFSampler(plugin, wi, variant, name)


def microfacet_sampler(distribution: str = "ggx", alpha: float = 0.1, *, visible: bool = True,
                       wi: float | Sequence[float] = 0.0, variant: str = "llvm_ad_rgb",
                       name: str | None = None) -> MicrofacetSampler:
    """Normals of ``mi.MicrofacetDistribution(distribution, alpha, visible)`` on the
    hemisphere; ``wi`` matters only for visible-normal sampling."""
    return MicrofacetSampler(distribution, alpha, visible=visible, wi=wi, variant=variant, name=name)


def envmap_sampler(bitmap: np.ndarray | None = None, *, plugin: dict[str, Any] | None = None,
                   variant: str = "llvm_ad_rgb", name: str | None = None) -> EnvmapSampler:
    """Directions from an ``envmap`` emitter built from ``bitmap`` (a lat-long float array;
    default: ``sky_bitmap()``) or from ``plugin`` (e.g. {"type": "envmap", "filename": ...,
    "scale": 2}), on the sphere."""
    return EnvmapSampler(bitmap, plugin=plugin, variant=variant, name=name)


def make_sampler(spec: dict[str, Any]) -> MitsubaSampler:
    """A sampler from a suite table's keys (``[[sampler]]`` with ``adapter = "mitsuba"``):

        plugin   a Mitsuba plugin dict: any BSDF; {type = "envmap"} (procedural sky unless
                 ``filename`` is given); or {type = "microfacet", distribution = "ggx",
                 alpha = 0.1, sample_visible = true}
        wi       polar angle of the incident direction in degrees, or a 3-vector (default 0)
        variant  default "llvm_ad_rgb"

    Raises ValueError naming the key at fault."""
    unknown = set(spec) - {"plugin", "wi", "variant", "name"}
    if unknown:
        raise ValueError(f"'{sorted(unknown)[0]}': unknown key for a Mitsuba sampler; expected plugin, wi, variant, name")
    plugin = spec.get("plugin")
    if not isinstance(plugin, dict) or not isinstance(plugin.get("type"), str):
        raise ValueError(f"'plugin': expected a table with a 'type' key (a Mitsuba plugin), got {plugin!r}")
    variant = spec.get("variant", "llvm_ad_rgb")
    wi = spec.get("wi", 0.0)
    name = spec.get("name")
    if plugin["type"] == "envmap":
        return envmap_sampler(plugin=plugin, variant=variant, name=name)
    if plugin["type"] == "microfacet":
        extra = set(plugin) - {"type", "distribution", "alpha", "sample_visible"}
        if extra:
            raise ValueError(f"'plugin': unknown key {sorted(extra)[0]!r} for a microfacet distribution; expected "
                             "distribution, alpha, sample_visible")
        return microfacet_sampler(plugin.get("distribution", "ggx"), plugin.get("alpha", 0.1),
                                  visible=plugin.get("sample_visible", True), wi=wi, variant=variant, name=name)
    return bsdf_sampler(plugin, wi=wi, variant=variant, name=name)


# --- deliberately wrong samplers -------------------------------------------------------------
class Mutant:
    """A sampler with a planted fault, for power checks: its samples come from ``base`` and its
    pdf from ``pdf_from`` (default ``base``) times ``pdf_scale``; ``weight_fault(batch)``
    rewrites the weights ``sample_batch`` returns (e.g. drops cos theta_o)."""

    def __init__(self, base: MitsubaSampler, name: str, *, pdf_scale: float = 1.0,
                 pdf_from: MitsubaSampler | None = None,
                 weight_fault: Callable[[SampleBatch], np.ndarray] | None = None):
        self.base, self.name, self.pdf_scale = base, name, pdf_scale
        self.pdf_from, self.weight_fault = pdf_from or base, weight_fault
        self.domain, self.udim, self.variant, self.kind = base.domain, base.udim, base.variant, base.kind

    def sample(self, u: np.ndarray) -> np.ndarray:
        return self.base.sample(u)

    def sample_batch(self, u: np.ndarray) -> SampleBatch:
        b = self.base.sample_batch(u)
        if self.weight_fault is None or b.weight is None:
            return b
        return SampleBatch(b.u, b.x, self.weight_fault(b), b.sample_pdf, b.valid)

    def pdf(self, x: np.ndarray, *, normalize: bool = True) -> np.ndarray:
        return self.pdf_scale * self.pdf_from.pdf(x, normalize=normalize)

    def eval(self, x: np.ndarray, *, normalize: bool = True) -> np.ndarray | None:
        return self.base.eval(x, normalize=normalize)

    def fingerprint(self) -> dict[str, Any]:
        return {**self.base.fingerprint(), "mutant": self.name}

    def __repr__(self) -> str:
        return f"Mutant({self.name!r} of {self.base!r})"


# --- the checks ------------------------------------------------------------------------------
def _normalised(test: SamplerTest, total: float) -> SamplerTest:
    """``test`` for the density pdf / total: its cubature integrals are linear in the pdf
    (the moment test's h(p) = p / (p + c) is invariant when p and c scale together)."""
    t = copy.copy(test)
    pdf = test.pdf
    t.pdf = lambda x: np.asarray(pdf(x), dtype=float) / total
    t.mass, t.err = test.mass / total, test.err / total
    t.c = test.c / total
    t.h_moments = tuple(v / total for v in test.h_moments)
    t.normalization = (test.normalization[0] / total, test.normalization[1] / total)
    return t


def _failure_pvalue(failed: int, n: int, total: float, total_err: float) -> float:
    """Two-sided exact binomial test of ``failed`` of ``n`` against failure probability
    1 - P, P anywhere in total ± total_err: 1 where the observed rate lies in that interval,
    else the p-value at its end nearest the observed rate (conservative)."""
    lo, hi = min(max(1 - total - total_err, 0.0), 1.0), min(max(1 - total + total_err, 0.0), 1.0)
    rate = failed / n
    if lo <= rate <= hi:
        return 1.0
    q = lo if rate < lo else hi
    if q <= 0:
        return 0.0 if failed > 0 else 1.0
    if q >= 1:
        return 0.0 if failed < n else 1.0
    return float(stats.binomtest(failed, n, q).pvalue)


def check_mitsuba_sampler(sampler: Any, *, sample_count: int = 1_000_000, seed: int = 0,
                          alpha: float = 0.01) -> SamplerCheck:
    """check_sampler for a sampler that may fail to produce a sample (NaN rows of
    ``sampler.sample``), as Mitsuba's BSDFs do; ``sampler`` needs ``sample``, ``pdf``,
    ``domain`` and ``udim`` (any MitsubaSampler or Mutant, or an object of your own).

    Uniforms come from the stream check_sampler uses (seed, case 0x5A3F), so a sampler that
    never fails gets check_sampler's result plus one row.  Deterministic failures: the pdf
    integrating to more than 1 (by more than 1e-3 and 10 times the cubature error), and
    check_sampler's own on the produced samples (outside the domain, zero/NaN/negative pdf).
    Statistical tests, Holm-combined at ``alpha`` (the false-alarm rate of the whole check):
    check_sampler's chi-squares, marginals and pdf moment on the produced samples against
    pdf / P, and an exact binomial test of the failure count against N (1 - P), P the
    cubature integral of the pdf over the domain.  ``normalization`` holds P and its error
    bound; ``tests`` also reports the failure count.
    """
    if _scalar_variant(sampler):
        raise ValueError(f"check_mitsuba_sampler needs a JIT variant ('llvm_ad_rgb'): the cubature evaluates the pdf "
                         f"at ~10^7 points, per-sample Python calls of the {sampler.variant!r} variant would take hours")
    n = int(sample_count)
    if n < 1000:
        raise ValueError(f"'sample_count' must be at least 1000, got {sample_count!r}")
    dom = _domain(sampler.domain)
    u = rest.points(n, sampler.udim, seed=seed, case_id=_SAMPLE_CASE)
    x = np.asarray(sampler.sample(u), dtype=float).reshape(n, dom.point_dim)
    failed = ~np.all(np.isfinite(x), axis=1)
    produced = x[~failed]
    m = produced.shape[0]
    if m < 1000:
        table = pd.DataFrame([("failed samples", float(failed.sum()), 0, 0.0, "samples the sampler did not produce")],
                             columns=["test", "statistic", "df", "pvalue", "detects"])
        table["adjusted"] = 0.0
        fail = {"check": "too_few_samples", "count": int(failed.sum()),
                "detail": f"only {m} of {n} samples produced", "examples": _examples(u, failed)}
        return SamplerCheck(False, 0.0, alpha, n, table, (fail,), (math.nan, math.nan))
    raw = SamplerTest(sampler.pdf, dom, sample_count=m, alpha=alpha)
    total, total_err = raw.normalization
    failures: list[dict[str, Any]] = []
    if not total > 0:
        failures.append({"check": "normalization", "count": 1, "detail": f"pdf integrates to {total:.6g} over the "
                         f"{dom.kind}", "examples": []})
        total = 1.0
    elif total - 1 > max(1e-3, 10 * total_err):
        failures.append({"check": "normalization", "count": 1,
                         "detail": f"pdf integrates to {total:.6f} ± {total_err:.1e} over the {dom.kind}, more than 1",
                         "examples": []})
    shape = _normalised(raw, total).check(lambda _u: produced, seed=seed, udim=sampler.udim)
    index = np.flatnonzero(~failed)  # the shape check's examples index the produced samples
    for f in shape.failures:
        if f["check"] != "normalization":
            examples = [{**ex, "index": int(index[ex["index"]]), "u": u[index[ex["index"]]].tolist()}
                        for ex in f["examples"]]
            failures.append({**f, "examples": examples})
    k = int(failed.sum())
    p_fail = _failure_pvalue(k, n, raw.normalization[0], raw.normalization[1])
    expected = n * max(1 - raw.normalization[0], 0.0)
    table = shape.tests.drop(columns=["adjusted"])
    table.loc[len(table)] = ("failed samples", float(k), 1, p_fail,
                             f"failure count vs N(1-P) = {expected:.1f}: pdf mass where no samples go")
    rejected, adjusted = holm(np.nan_to_num(table["pvalue"].to_numpy(dtype=float), nan=0.0), alpha)
    table["adjusted"] = adjusted
    passed = not failures and not rejected.any()
    # the shape check's per-cell results (residuals, marginals) are kept: they describe the
    # produced samples, the only ones with a direction
    return dataclasses.replace(shape, passed=passed, pvalue=float(adjusted.min()), sample_count=n, tests=table,
                               failures=tuple(failures), normalization=raw.normalization)


def _scalar_variant(sampler: Any) -> bool:
    variant = getattr(sampler, "variant", None)
    return isinstance(variant, str) and not _is_jit(variant)


def _examples(u: np.ndarray, mask: np.ndarray, k: int = 5) -> list[dict[str, Any]]:
    return [{"index": int(i), "u": u[i].tolist()} for i in np.flatnonzero(mask)[:k]]


@dataclass(frozen=True)
class WeightCheck:
    """Outcome of :func:`weight_consistency`.  ``passed``: no weight differs from eval / pdf
    beyond the tolerance and none is NaN, infinite or negative (vacuously True for samplers
    without a weight: microfacet distributions).  ``pdf_consistent``: the pdf each sample call
    reports agrees with ``pdf()`` (reported separately: it matters for MIS weights, not for
    the weight).  Counts are over the produced samples."""

    passed: bool
    pdf_consistent: bool
    sample_count: int
    produced: int
    mismatches: int                # weight vs eval/pdf beyond tolerance, any channel
    bad_weights: int               # NaN, infinite or negative weight
    pdf_mismatches: int            # sample pdf vs pdf() beyond tolerance
    max_rel_error: float           # largest |weight / (eval/pdf) - 1| over the produced samples
    max_pdf_rel_error: float       # largest |sample pdf / pdf() - 1|
    rtol: float
    atol: float
    pdf_rtol: float
    examples: tuple[dict[str, Any], ...] = field(default_factory=tuple)

    def __bool__(self) -> bool:
        return self.passed

    def to_payload(self) -> dict[str, Any]:
        """JSON-able, in the shape a suite stores a sampler check (passed, pvalue, tests,
        failures, normalization): deterministic, so pvalue is 1 and a mismatch is a failure;
        the sample-pdf agreement is a test row, informational (never a failure)."""
        tests = [{"test": "weight == eval/pdf", "statistic": float(self.mismatches), "df": 0, "pvalue": 1.0,
                  "detects": f"weight off eval/pdf by > {self.atol:g} + {self.rtol:g} rel + float32 rounding",
                  "adjusted": 1.0},
                 {"test": "NaN/Inf/negative weights", "statistic": float(self.bad_weights), "df": 0, "pvalue": 1.0,
                  "detects": "invalid weights", "adjusted": 1.0},
                 {"test": "sample pdf == pdf() (informational)", "statistic": float(self.pdf_mismatches), "df": 0,
                  "pvalue": 1.0, "detects": f"largest relative difference {self.max_pdf_rel_error:.3g}", "adjusted": 1.0}]
        failures = []
        for check, count, kind in (("weight_mismatch", self.mismatches, "weight != eval/pdf"),
                                   ("bad_weight", self.bad_weights, "NaN/Inf/negative weight")):
            if count:
                failures.append({"check": check, "count": count,
                                 "detail": f"{kind} ({count} of {self.produced} produced samples; largest relative "
                                           f"difference {self.max_rel_error:.3g})",
                                 "examples": [e for e in self.examples if e["check"] == kind]})
        return {"passed": self.passed, "pvalue": 1.0, "tests": tests, "failures": failures,
                "normalization": [float("nan"), float("nan")]}

    def __str__(self) -> str:
        head = (f"{'PASSED' if self.passed else 'FAILED'}: {self.produced} of {self.sample_count} samples produced; "
                f"{self.mismatches} weight(s) differ from eval/pdf beyond {self.atol:g} + {self.rtol:g} relative + "
                f"float32 rounding (largest relative difference {self.max_rel_error:.2g}); {self.bad_weights} "
                f"NaN/Inf/negative weight(s); {self.pdf_mismatches} sample pdf(s) differ from pdf() beyond "
                f"{self.pdf_rtol:g} relative + rounding (largest {self.max_pdf_rel_error:.2g})")
        return "\n".join([head] + [f"  {e}" for e in self.examples])


_NUDGE_ULPS = 4


def _nudged(x32: np.ndarray) -> Iterator[np.ndarray]:
    """x (float32 values) with one component moved by 4 float32 ulps up or down: 6 copies."""
    for c in range(3):
        for to in (np.inf, -np.inf):
            y = x32.copy()
            col = y[:, c]
            for _ in range(_NUDGE_ULPS):
                col = np.nextafter(col, np.float32(to), dtype=np.float32)
            y[:, c] = col
            yield y.astype(np.float64)


def _rounding_spread(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, at: np.ndarray) -> np.ndarray:
    """max |f(x') - f(x)| over the 6 nudged copies x' of x: what float32 rounding of the
    direction can change f by (NaN-safe: a non-finite change counts as infinite)."""
    spread = np.zeros_like(at)
    for y in _nudged(x.astype(np.float32)):
        with np.errstate(all="ignore"):
            d = np.abs(f(y) - at)
        spread = np.maximum(spread, np.where(np.isfinite(d), d, np.inf))
    return spread


def weight_consistency(sampler: Any, *, sample_count: int = 1_000_000, seed: int = 0, rtol: float = 1e-4,
                       atol: float = 1e-6, pdf_rtol: float = 1e-3, max_examples: int = 5) -> WeightCheck:
    """For every sample Mitsuba produces: the weight it returns (a Spectrum: BSDF f cos / pdf,
    emitter radiance / pdf) must equal ``eval(x) / pdf(x)`` re-evaluated at the returned
    float32 direction, per channel; weights must be finite and non-negative.  Separately, the
    pdf the sample call reports must equal ``pdf(x)``.

    A weight mismatch is invisible to a chi-square test (it only sees where samples go) and
    biases every estimate that uses the weight: a weight missing cos theta_o, or 0.1 % too
    large, fails here deterministically.  Tolerance: ``atol + rtol |eval/pdf|`` plus what
    float32 rounding of the direction can explain, measured, not guessed: the largest change
    of eval/pdf when one component of the direction moves by 4 float32 ulps (computed for the
    samples outside the plain tolerance only).  That term matters where eval/pdf is steep in
    the direction: an environment map's sun edge (radiance 0.4 next to 2000 one texel away)
    and its poles (theta from acos of a float32 near 1); elsewhere rtol 1e-4 (about 800
    float32 ulps) dominates, and correct plugins stay below 1e-5.  The sample pdf gets
    ``pdf_rtol`` (it may be computed another way, e.g. from the sampled microfacet normal
    rather than the half vector of the returned direction) plus the same rounding term.
    Failed samples (zero weight) are not compared: the failure-count test of
    ``check_mitsuba_sampler`` judges whether they are as many as the pdf says.  Microfacet
    distributions have no weight: only the pdf agreement is checked.
    """
    n = int(sample_count)
    if n < 1:
        raise ValueError(f"'sample_count' must be positive, got {sample_count!r}")
    u = rest.points(n, sampler.udim, seed=seed, case_id=_WEIGHT_CASE)
    b = sampler.sample_batch(u)
    idx = np.flatnonzero(b.valid)
    xv = b.x[idx]
    p = sampler.pdf(xv, normalize=False)
    sp = b.sample_pdf[idx]
    examples: list[dict[str, Any]] = []

    def where(j: int) -> dict[str, Any]:
        return {"index": int(idx[j]), "u": b.u[idx[j]].tolist(), "direction": xv[j].tolist()}

    with np.errstate(all="ignore"):
        pdf_diff = np.abs(sp - p)
        pdf_rel = np.where(p > 0, pdf_diff / p, np.inf)
    pdf_bad = ~(pdf_diff <= pdf_rtol * np.abs(p))
    if pdf_bad.any():
        sel = np.flatnonzero(pdf_bad)
        spread = _rounding_spread(lambda y: sampler.pdf(y, normalize=False), xv[sel], p[sel])
        pdf_bad[sel] = ~(pdf_diff[sel] <= pdf_rtol * np.abs(p[sel]) + spread)
    mismatches = bad = 0
    max_rel = 0.0
    if b.weight is not None:
        w = b.weight[idx]
        e = sampler.eval(xv, normalize=False)
        with np.errstate(all="ignore"):
            ratio = e / p[:, None]
            diff = np.abs(w - ratio)
            rel = np.where(np.abs(ratio) > atol, diff / np.abs(ratio), diff)
        bad_mask = ~np.all(np.isfinite(w) & (w >= 0), axis=1)
        mis = ~np.all(diff <= atol + rtol * np.abs(ratio), axis=1) & ~bad_mask
        if mis.any():
            sel = np.flatnonzero(mis)

            def weight_of(y: np.ndarray) -> np.ndarray:
                with np.errstate(all="ignore"):
                    return sampler.eval(y, normalize=False) / sampler.pdf(y, normalize=False)[:, None]

            spread = _rounding_spread(weight_of, xv[sel], ratio[sel])
            mis[sel] = ~np.all(diff[sel] <= atol + rtol * np.abs(ratio[sel]) + spread, axis=1)
        good = ~bad_mask
        max_rel = float(np.max(np.nan_to_num(rel[good], nan=np.inf))) if good.any() else 0.0
        mismatches, bad = int(mis.sum()), int(bad_mask.sum())
        for label, mask in (("weight != eval/pdf", mis), ("NaN/Inf/negative weight", bad_mask)):
            for j in np.flatnonzero(mask)[:max_examples]:
                examples.append({"check": label, **where(j), "weight": w[j].tolist(), "eval/pdf": ratio[j].tolist(),
                                 "eval": e[j].tolist(), "pdf": float(p[j])})
    for j in np.flatnonzero(pdf_bad)[:max_examples]:
        examples.append({"check": "sample pdf != pdf()", **where(j), "sample_pdf": float(sp[j]), "pdf": float(p[j])})
    max_pdf_rel = float(np.max(pdf_rel)) if pdf_rel.size else 0.0
    return WeightCheck(mismatches == 0 and bad == 0, not pdf_bad.any(), n, int(idx.size), mismatches, bad,
                       int(pdf_bad.sum()), max_rel, max_pdf_rel, rtol, atol, pdf_rtol, tuple(examples))


# --- the catalogue ---------------------------------------------------------------------------
@dataclass(frozen=True)
class CatalogueEntry:
    """One sampler to check: ``make()`` builds it (lazily: building imports Mitsuba);
    ``plugin`` names it without the incident angle ``theta`` (degrees; None where there is
    none); ``fault`` says what was planted ('' for a real plugin)."""

    plugin: str
    theta: float | None
    make: Callable[[], Any]
    fault: str = ""
    group: str = ""

    @property
    def label(self) -> str:
        return self.plugin + (f" θi={self.theta:g}°" if self.theta is not None else "")


THETAS = (0.0, 45.0, 80.0)
ALPHAS = (0.01, 0.1, 0.5)


def catalogue(*, thetas: Sequence[float] = THETAS, alphas: Sequence[float] = ALPHAS,
              variant: str = "llvm_ad_rgb") -> list[CatalogueEntry]:
    """The real plugins checked, each at every incident angle in ``thetas`` (degrees):
    diffuse; roughconductor, GGX and Beckmann, at every alpha, visible-normal sampling on
    and off; roughdielectric (GGX, alpha 0.1 and 0.5, int_ior 1.5); roughplastic (GGX, alpha
    0.1); the microfacet distributions themselves (GGX and Beckmann at every alpha; visible
    normals at every angle, all normals once: they do not depend on wi); envmaps from
    ``sky_bitmap()`` with a soft-rimmed and a hard-edged sun."""
    out: list[CatalogueEntry] = []

    def bsdf(group: str, plugin: dict[str, Any]) -> None:
        for t in thetas:
            out.append(CatalogueEntry(_plugin_label(plugin), float(t),
                                      lambda t=t: bsdf_sampler(plugin, wi=t, variant=variant), "", group))

    bsdf("diffuse", {"type": "diffuse"})
    for dist in ("ggx", "beckmann"):
        for a in alphas:
            for vis in (True, False):
                bsdf("roughconductor", {"type": "roughconductor", "distribution": dist, "alpha": a, "sample_visible": vis})
    for a in (0.1, 0.5):
        bsdf("roughdielectric", {"type": "roughdielectric", "distribution": "ggx", "alpha": a, "int_ior": 1.5})
    bsdf("roughplastic", {"type": "roughplastic", "distribution": "ggx", "alpha": 0.1})
    for dist in ("ggx", "beckmann"):
        for a in alphas:
            for t in thetas:
                out.append(CatalogueEntry(f"microfacet {dist} α={a:g} visible", float(t),
                                          lambda d=dist, a=a, t=t: microfacet_sampler(d, a, visible=True, wi=t,
                                                                                      variant=variant),
                                          "", "microfacet"))
            out.append(CatalogueEntry(f"microfacet {dist} α={a:g} all normals", None,
                                      lambda d=dist, a=a: microfacet_sampler(d, a, visible=False, variant=variant),
                                      "", "microfacet"))
    out.append(CatalogueEntry("envmap 256x128 sky, sun with a soft rim", None,
                              lambda: envmap_sampler(variant=variant), "", "envmap"))
    out.append(CatalogueEntry("envmap 256x128 sky, hard-edged sun", None,
                              lambda: envmap_sampler(sky_bitmap(sun_edge=0.0), variant=variant), "", "envmap"))
    return out


def _no_cosine(b: SampleBatch) -> np.ndarray:
    """The weight without cos theta_o (f / pdf instead of f cos / pdf)."""
    with np.errstate(all="ignore"):
        return b.weight / np.abs(b.x[:, 2:3])


def wrong_catalogue(*, variant: str = "llvm_ad_rgb") -> list[CatalogueEntry]:
    """Planted faults every check must catch: a pdf 0.5 % too large or too small (BSDFs with
    and without failed samples, envmap); the pdf of GGX alpha 0.1 claimed for samples of
    alpha 0.11 (conductor and distribution) and of 0.01 for 0.011; Beckmann's pdf for GGX
    samples; the envmap's pdf with the sun 1 degree away; a weight missing cos theta_o; a
    weight 0.1 % too large (BSDF and envmap)."""
    def ggx(a: float, t: float = 45.0) -> BSDFSampler:
        return bsdf_sampler({"type": "roughconductor", "distribution": "ggx", "alpha": a}, wi=t, variant=variant)

    def entry(plugin: str, theta: float | None, make: Callable[[], Any], fault: str) -> CatalogueEntry:
        return CatalogueEntry(plugin, theta, make, fault, "wrong")

    return [
        entry("roughconductor ggx α=0.1, pdf × 1.005", 45.0,
              lambda: Mutant(ggx(0.1), "pdf × 1.005", pdf_scale=1.005), "pdf 0.5 % too large"),
        entry("roughconductor ggx α=0.1, pdf × 1.005", 0.0,
              lambda: Mutant(ggx(0.1, 0.0), "pdf × 1.005", pdf_scale=1.005), "pdf 0.5 % too large"),
        entry("diffuse, pdf × 0.995", 45.0,
              lambda: Mutant(bsdf_sampler({"type": "diffuse"}, wi=45, variant=variant), "pdf × 0.995", pdf_scale=0.995),
              "pdf 0.5 % too small"),
        entry("roughconductor ggx samples α=0.11, pdf α=0.1", 45.0,
              lambda: Mutant(ggx(0.11), "pdf of α=0.1", pdf_from=ggx(0.1)), "pdf of another alpha"),
        entry("roughconductor ggx samples α=0.011, pdf α=0.01", 45.0,
              lambda: Mutant(ggx(0.011), "pdf of α=0.01", pdf_from=ggx(0.01)), "pdf of another alpha"),
        entry("microfacet ggx visible samples α=0.11, pdf α=0.1", 45.0,
              lambda: Mutant(microfacet_sampler("ggx", 0.11, wi=45, variant=variant), "pdf of α=0.1",
                             pdf_from=microfacet_sampler("ggx", 0.1, wi=45, variant=variant)), "pdf of another alpha"),
        entry("roughconductor ggx samples, beckmann pdf α=0.1", 45.0,
              lambda: Mutant(ggx(0.1), "beckmann pdf", pdf_from=bsdf_sampler(
                  {"type": "roughconductor", "distribution": "beckmann", "alpha": 0.1}, wi=45, variant=variant)),
              "pdf of another distribution"),
        entry("envmap, pdf × 1.005", None,
              lambda: Mutant(envmap_sampler(variant=variant), "pdf × 1.005", pdf_scale=1.005), "pdf 0.5 % too large"),
        entry("envmap, pdf of the map with the sun 1° away", None,
              lambda: Mutant(envmap_sampler(variant=variant), "sun moved",
                             pdf_from=envmap_sampler(sky_bitmap(sun_phi=71.0), variant=variant)),
              "pdf of a slightly different map"),
        entry("roughconductor ggx α=0.1, weight without cos θo", 45.0,
              lambda: Mutant(ggx(0.1), "weight without cos", weight_fault=_no_cosine), "weight omits cos θo"),
        entry("roughplastic ggx α=0.1, weight × 1.001", 45.0,
              lambda: Mutant(bsdf_sampler({"type": "roughplastic", "distribution": "ggx", "alpha": 0.1}, wi=45,
                                          variant=variant),
                             "weight × 1.001", weight_fault=lambda b: b.weight * 1.001), "weight 0.1 % too large"),
        entry("envmap, weight × 1.001", None,
              lambda: Mutant(envmap_sampler(variant=variant), "weight × 1.001", weight_fault=lambda b: b.weight * 1.001),
              "weight 0.1 % too large"),
    ]


def run_catalogue(entries: Sequence[CatalogueEntry], *, sample_count: int = 1_000_000, seed: int = 0,
                  alpha: float = 0.01, weight_samples: int | None = None,
                  progress: Callable[[dict[str, Any]], None] | None = None) -> pd.DataFrame:
    """Runs ``check_mitsuba_sampler`` and ``weight_consistency`` on every entry.  The
    chi-square verdicts are Holm-corrected across all entries at family-wise ``alpha`` (each
    check's p-value is its smallest within-check Holm-adjusted p-value, a valid p-value for
    the whole check; deterministic failures always fail).  The weight check is
    deterministic (no alpha).

    One row per entry: label, plugin, theta, group, fault, domain, n, failed (samples Mitsuba
    did not produce), P and P_err (the pdf's integral over the domain and its cubature error
    bound), pvalue, adjusted, chi2 ('pass' / 'FAIL'), failures (deterministic), weight
    ('pass' / 'FAIL' / 'n/a' for microfacet distributions), weight_mismatches, bad_weights,
    weight_max_rel, pdf_consistent, pdf_mismatches, pdf_max_rel, seconds_chi2 (pdf cubature
    included), seconds_weight.  ``attrs['checks']`` holds the (SamplerCheck, WeightCheck)
    pairs."""
    import time

    rows = []
    checks = []
    for e in entries:
        start = time.perf_counter()
        s = e.make()
        r = check_mitsuba_sampler(s, sample_count=sample_count, seed=seed, alpha=alpha)
        mid = time.perf_counter()
        w = weight_consistency(s, sample_count=weight_samples or sample_count, seed=seed)
        end = time.perf_counter()
        failed_row = r.tests[r.tests["test"] == "failed samples"]
        has_weight = s.eval(np.array([[0.0, 0.0, 1.0]])) is not None
        row = {"label": e.label, "plugin": e.plugin, "theta": e.theta, "group": e.group, "fault": e.fault,
               "domain": s.domain, "n": r.sample_count,
               "failed": int(failed_row["statistic"].iloc[0]) if len(failed_row) else 0,
               "P": r.normalization[0], "P_err": r.normalization[1], "pvalue": r.pvalue,
               "failures": "; ".join(f"{f['check']}: {f['count']}" for f in r.failures),
               "weight": ("pass" if w.passed else "FAIL") if has_weight else "n/a",
               "weight_mismatches": w.mismatches, "bad_weights": w.bad_weights, "weight_max_rel": w.max_rel_error,
               "pdf_consistent": w.pdf_consistent, "pdf_mismatches": w.pdf_mismatches, "pdf_max_rel": w.max_pdf_rel_error,
               "seconds_chi2": mid - start, "seconds_weight": end - mid}
        rows.append(row)
        checks.append((r, w))
        if progress is not None:
            progress(row)
    table = pd.DataFrame(rows)
    if len(table):
        rejected, adjusted = holm(table["pvalue"].to_numpy(dtype=float), alpha)
        table["adjusted"] = adjusted
        table["chi2"] = np.where(rejected | (table["failures"] != ""), "FAIL", "pass")
    table.attrs["checks"] = checks
    table.attrs["alpha"] = alpha
    return table
