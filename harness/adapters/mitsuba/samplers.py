"""Mitsuba 3 BSDFs, microfacet distributions and environment maps as batch sample / pdf
(/ eval) pairs for the sampler checks (``harness.samplers.check`` and, for samplers that may
fail to produce a sample, ``harness.adapters.mitsuba.checks``).

    s = bsdf_sampler({"type": "roughconductor", "distribution": "ggx", "alpha": 0.01}, wi=45)
    x = s.sample(u)               # u (N, 3) -> directions (N, 3); NaN rows where Mitsuba fails
    s.pdf(x)                      # (N,) solid-angle density of bsdf.pdf
    s.eval(x)                     # (N, channels): f cos theta_o, whose ratio to pdf the weight is
    s.sample_batch(u)             # a SampleBatch: directions, weights, sample pdfs, valid rows

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
models at grazing angles.

Variants.  Every call holds ``runtime.VARIANT_LOCK`` and sets the sampler's variant; Mitsuba
objects are built once per sampler, for its variant.  JIT variants run each batch as one
kernel; scalar variants loop over samples in Python (tens of microseconds per sample:
cross-checks on small N only).  RGB and mono variants only.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from harness.adapters.mitsuba.runtime import check_variant, is_jit, using_variant

__all__ = ["MitsubaSampler", "BSDFSampler", "MicrofacetSampler", "EnvmapSampler", "SampleBatch",
           "bsdf_sampler", "microfacet_sampler", "envmap_sampler", "sky_bitmap", "make_sampler",
           "plugin_label"]

_BELOW_ONE = np.float32(1.0) - np.float32(2.0**-24)


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
    unit = x / np.where(ok, norm, 1.0)[:, None] if normalize else x
    y = np.where(ok[:, None], unit, np.array([0.0, 0.0, 1.0]))
    return [_floats(y[:, i]) for i in range(3)], ok


def _to_numpy(value: Any, n: int) -> np.ndarray:
    a = np.array(value, dtype=np.float64)
    if a.ndim == 2:          # a JIT vector or colour: (channels, N)
        a = a.T
    return np.broadcast_to(a, (n,) + a.shape[1:]).copy() if a.shape[:1] != (n,) else a


def _batch(mi: Any, variant: str, kernel: Callable[..., tuple],
           columns: list[np.ndarray]) -> list[np.ndarray]:
    """Runs ``kernel(mi, width, *columns)`` once over drjit arrays (JIT variants) or once per
    row with Python floats (scalar variants; width None); returns numpy arrays (N,) or (N, c)."""
    import drjit as dr

    n = len(columns[0])
    if n == 0:  # drjit arrays of width 0 are not all supported: run one dummy row, keep none
        return [o[:0] for o in _batch(mi, variant, kernel, [np.zeros(1, dtype=np.float32) for _ in columns])]
    if is_jit(variant):
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
        check_variant(variant)
        self.variant = variant
        self.name = name
        self._obj: Any = None

    # subclasses: _build(mi) -> the Mitsuba object; _sample_kernel, _pdf_kernel, _eval_kernel
    def _object(self, mi: Any) -> Any:
        """The Mitsuba object, built once for this sampler's variant; call with the variant set
        (inside ``using_variant(self.variant)``), as every method does."""
        if self._obj is None:
            self._obj = self._build(mi)
        return self._obj

    def _build(self, mi: Any) -> Any:
        raise NotImplementedError

    def sample_batch(self, u: np.ndarray) -> SampleBatch:
        cols = _uniforms(u, self.udim)
        with using_variant(self.variant) as mi:
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
        with using_variant(self.variant) as mi:
            obj = self._object(mi)
            (p,) = _batch(mi, self.variant, lambda m, w, *c: (self._pdf_kernel(m, obj, w, *c),), cols)
        return np.where(ok, p.reshape(-1), 0.0)

    def eval(self, x: np.ndarray, *, normalize: bool = True) -> np.ndarray | None:
        """The value whose ratio to the pdf the sample weight must be (BSDF: f cos theta_o;
        emitter: radiance), (N, channels); None where the sampler has no weight."""
        cols, ok = _unit_columns(x, normalize)
        with using_variant(self.variant) as mi:
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

    def __init__(self, plugin: dict[str, Any], wi: float | Sequence[float] = 0.0,
                 variant: str = "llvm_ad_rgb", name: str | None = None):
        if not isinstance(plugin, dict) or not isinstance(plugin.get("type"), str):
            raise ValueError(f"'plugin' must be a Mitsuba plugin dict with a 'type' key, got {plugin!r}")
        self.plugin = dict(plugin)
        self.wi = _direction(wi)
        theta = math.degrees(math.acos(min(1.0, self.wi[2])))
        label = name or plugin_label(self.plugin) + f" θi={theta:g}°"
        super().__init__(variant, label)
        with using_variant(self.variant) as mi:
            try:
                bsdf = self._object(mi)
            except Exception as e:  # Mitsuba raises RuntimeError / TypeError for a bad plugin dict
                raise ValueError(f"'plugin': Mitsuba cannot build {self.plugin!r}: {e}") from None
            self.transmits = mi.has_flag(bsdf.flags(), mi.BSDFFlags.Transmission)
            self.delta = mi.has_flag(bsdf.flags(), mi.BSDFFlags.Delta)
        if self.delta:
            raise ValueError(f"'plugin': {self.plugin['type']!r} has a Dirac delta lobe; "
                             "a sampler test needs a density")
        self.domain = "sphere" if self.transmits else "hemisphere"

    def _build(self, mi: Any) -> Any:
        return mi.load_dict(self.plugin)

    def _si(self, mi: Any, width: int | None) -> Any:
        import drjit as dr

        si = (dr.zeros(mi.SurfaceInteraction3f, width) if width is not None
              else dr.zeros(mi.SurfaceInteraction3f))
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
        return {"distribution": self.distribution, "alpha": self.alpha, "visible": self.visible,
                "wi": list(self.wi)}


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
            raise ValueError("'plugin' must be an envmap plugin dict ({'type': 'envmap', ...}), "
                             f"got {plugin!r}")
        if "bitmap" in params:
            if bitmap is not None:
                raise ValueError("'bitmap': given twice, as an argument and in 'plugin'")
            bitmap = np.array(params.pop("bitmap"))
        if bitmap is None and "filename" not in params:
            bitmap = sky_bitmap()
        self.image = None if bitmap is None else np.ascontiguousarray(bitmap, dtype=np.float32)
        if self.image is not None and (self.image.ndim != 3 or self.image.shape[2] not in (1, 3)
                                       or self.image.shape[1] < 2 or self.image.shape[0] < 2):
            raise ValueError("'bitmap' must be a (height, width, 3) or (height, width, 1) array, "
                             f"got {self.image.shape}")
        self.plugin = params
        label = name or ("envmap " + (f"{self.image.shape[1]}x{self.image.shape[0]}" if self.image is not None
                                      else str(self.plugin.get("filename"))))
        super().__init__(variant, label)
        with using_variant(self.variant) as mi:
            try:
                self._object(mi)
            except Exception as e:
                raise ValueError(f"'plugin': Mitsuba cannot build an envmap from {self.plugin!r}: "
                                 f"{e}") from None

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

        si = (dr.zeros(mi.SurfaceInteraction3f, width) if width is not None
              else dr.zeros(mi.SurfaceInteraction3f))
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


def plugin_label(plugin: dict[str, Any]) -> str:
    """A short label of a plugin dict without its incident angle, e.g.
    "roughconductor ggx α=0.1 visible=True"."""
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
        raise ValueError(f"'{sorted(unknown)[0]}': unknown key for a Mitsuba sampler; "
                         "expected plugin, wi, variant, name")
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
            raise ValueError(f"'plugin': unknown key {sorted(extra)[0]!r} for a microfacet distribution; "
                             "expected distribution, alpha, sample_visible")
        return microfacet_sampler(plugin.get("distribution", "ggx"), plugin.get("alpha", 0.1),
                                  visible=plugin.get("sample_visible", True), wi=wi, variant=variant,
                                  name=name)
    return bsdf_sampler(plugin, wi=wi, variant=variant, name=name)


