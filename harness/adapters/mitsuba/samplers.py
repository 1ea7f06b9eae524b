"""Mitsuba 3 BSDFs and microfacet distributions as batch sample / pdf (/ eval) pairs for the
sampler checks (``harness.adapters.mitsuba.checks``), and :func:`make_sampler`, which builds
any adapter (these, phase functions from ``phase``, emitters from ``emitters``) from a suite
table.

    s = bsdf_sampler({"type": "roughconductor", "distribution": "ggx", "alpha": 0.01}, wi=45)
    x = s.sample(u)               # u (N, 3) -> directions (N, 3); NaN rows where none is produced
    s.pdf(x)                      # (N,) solid-angle density of bsdf.pdf
    s.eval(x)                     # (N, channels): f cos theta_o, whose ratio to pdf the weight is
    s.sample_batch(u)             # a SampleBatch: directions, weights, sample pdfs, valid rows

Conventions.  Directions are unit vectors in the local shading frame (the normal is +z, the
frame is the identity); the incident direction ``wi`` points away from the surface, given as
a polar angle theta_i in degrees (azimuth 0) or as a 3-vector; it may come from below the
surface (theta_i > 90) only for BSDFs with a back side (``twosided``, dielectrics,
``principled``).  u[:, 0] selects the lobe or component, u[:, 1:3] is the 2-D sample.
Domains: the hemisphere z >= 0 for BSDFs that only reflect and are lit from above (and for
microfacet normals), the sphere otherwise.

Samples not produced.  Mitsuba signals a sample it could not produce with a zero weight (the
path integrator ends the path there): a reflection below the horizon, a microfacet the wrong
way round.  A BSDF with a Dirac delta lobe beside smooth ones (``mask``: the pass-through;
``plastic``: the smooth coating) samples the delta lobe with the probability the pdf's mass
leaves for it, at one direction with no density.  ``sample`` returns both kinds as NaN rows, so
the samples drawn form a defective distribution whose pdf integrates to P <= 1 over the
domain, and the failure-aware check tests the count of missing samples against N (1 - P): a
mask's opacity 0.3 leaves P = 0.3.  BSDFs with only delta lobes (``conductor``,
``dielectric``) are refused: they have no density.

Variants.  JIT variants run each batch as one kernel; scalar variants loop over samples in
Python (tens of microseconds per sample: cross-checks on small N only).  RGB and mono only.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from harness.adapters.mitsuba.batch import (
    MitsubaSampler,
    SampleBatch,
    direction,
    plugin_label,
    polar_angle,
    zeros,
)
from harness.adapters.mitsuba.emitters import (
    AreaEmitterSampler,
    EnvmapSampler,
    area_emitter_sampler,
    envmap_sampler,
    refuse_delta_emitter,
    sky_bitmap,
)
from harness.adapters.mitsuba.phase import PhaseSampler, phase_sampler
from harness.adapters.mitsuba.runtime import using_variant

__all__ = ["AreaEmitterSampler", "BSDFSampler", "EnvmapSampler", "MicrofacetSampler", "MitsubaSampler",
           "PhaseSampler", "SampleBatch", "area_emitter_sampler", "bsdf_sampler", "envmap_sampler",
           "make_sampler", "microfacet_sampler", "phase_sampler", "plugin_label", "sky_bitmap"]


class BSDFSampler(MitsubaSampler):
    """A Mitsuba BSDF at a fixed incident direction: ``bsdf.sample(ctx, si, u0, (u1, u2))``,
    ``bsdf.pdf(ctx, si, wo)``, ``bsdf.eval(ctx, si, wo)`` (f times cos theta_o) with a default
    BSDFContext (radiance transport, all lobes) and an identity shading frame.  Samples of a
    Dirac delta lobe are rows of ``SampleBatch.delta``, not produced (see the module)."""

    kind = "bsdf"
    udim = 3
    sample_outputs = ("x", "weight", "pdf", "delta", "sampled_type")

    def __init__(self, plugin: dict[str, Any], wi: float | Sequence[float] = 0.0,
                 variant: str = "llvm_ad_rgb", name: str | None = None):
        if not isinstance(plugin, dict) or not isinstance(plugin.get("type"), str):
            raise ValueError(f"'plugin' must be a Mitsuba plugin dict with a 'type' key, got {plugin!r}")
        self.plugin = dict(plugin)
        super().__init__(variant, name or plugin_label(self.plugin))
        bsdf = self._build_checked(repr(self.plugin))
        with using_variant(self.variant) as mi:
            self.delta_lobes, smooth, self.transmits, back = self._flags(mi, bsdf)
        if not smooth:
            raise ValueError(f"'plugin': {self.plugin['type']!r} has only Dirac delta lobes; "
                             "a sampler test needs a density")
        try:
            self.wi = direction(wi, below=back)
        except ValueError as e:
            if back:
                raise
            raise ValueError(f"{e} ({self.plugin['type']!r} is one-sided: lit from above only)") from None
        theta = polar_angle(self.wi)
        if name is None:
            self.name = f"{self.name} θi={theta:g}°"
        self.domain = "sphere" if self.transmits or self.wi[2] < 0 else "hemisphere"

    @staticmethod
    def _flags(mi: Any, bsdf: Any) -> tuple[bool, bool, bool, bool]:
        """(has a Dirac lobe, has a smooth lobe, transmits smoothly, has a back side)."""
        f, F = bsdf.flags(), mi.BSDFFlags
        smooth_transmission = mi.has_flag(f, F.DiffuseTransmission) or mi.has_flag(f, F.GlossyTransmission)
        return (bool(mi.has_flag(f, F.Delta)), bool(mi.has_flag(f, F.Smooth)), bool(smooth_transmission),
                bool(mi.has_flag(f, F.BackSide)))

    def _build(self, mi: Any) -> Any:
        return mi.load_dict(self.plugin)

    def _si(self, mi: Any, width: int | None) -> Any:
        si = zeros(mi, "SurfaceInteraction3f", width)
        si.wi = mi.Vector3f(*self.wi)
        si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
        si.n = mi.Normal3f(0.0, 0.0, 1.0)
        si.uv = mi.Point2f(0.5, 0.5)
        return si

    def _sample_kernel(self, mi, bsdf, width, u0, u1, u2):
        bs, weight = bsdf.sample(mi.BSDFContext(), self._si(mi, width), u0, mi.Point2f(u1, u2))
        delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
        return bs.wo, weight, bs.pdf, delta, bs.sampled_type

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
    sample_outputs = ("x", "pdf")

    def __init__(self, distribution: str = "ggx", alpha: float = 0.1, *, visible: bool = True,
                 wi: float | Sequence[float] = 0.0, variant: str = "llvm_ad_rgb", name: str | None = None):
        if distribution not in ("ggx", "beckmann"):
            raise ValueError(f"'distribution' must be 'ggx' or 'beckmann', got {distribution!r}")
        if not (isinstance(alpha, (int, float)) and 0 < alpha <= 10):
            raise ValueError(f"'alpha' must be a roughness in (0, 10], got {alpha!r}")
        self.distribution, self.alpha, self.visible = distribution, float(alpha), bool(visible)
        self.wi = direction(wi)
        label = name or (f"microfacet {distribution} α={alpha:g} {'visible' if visible else 'all'} normals"
                         + (f" θi={polar_angle(self.wi):g}°" if visible else ""))
        super().__init__(variant, label)

    def _build(self, mi: Any) -> Any:
        kind = mi.MicrofacetType.GGX if self.distribution == "ggx" else mi.MicrofacetType.Beckmann
        return mi.MicrofacetDistribution(kind, self.alpha, self.visible)

    def _sample_kernel(self, mi, distr, width, u0, u1):
        m, p = distr.sample(mi.Vector3f(*self.wi), mi.Point2f(u0, u1))
        return m, p

    def _pdf_kernel(self, mi, distr, width, x, y, z):
        return distr.pdf(mi.Vector3f(*self.wi), mi.Vector3f(x, y, z))

    def eval(self, x: Any) -> None:
        """None: a microfacet distribution returns no weight."""
        return None

    def _spec(self) -> dict[str, Any]:
        return {"distribution": self.distribution, "alpha": self.alpha, "visible": self.visible,
                "wi": list(self.wi)}


def bsdf_sampler(plugin: dict[str, Any], *, wi: float | Sequence[float] = 0.0, variant: str = "llvm_ad_rgb",
                 name: str | None = None) -> BSDFSampler:
    """A Mitsuba BSDF (a ``mi.load_dict`` plugin dict) as a sampler at incident direction
    ``wi`` (polar angle in degrees, or a 3-vector; below the surface only for BSDFs with a
    back side): udim 3 (u0 picks the lobe), the hemisphere for reflection-only BSDFs lit from
    above, else the sphere.  Dirac lobes beside smooth ones are samples not produced; BSDFs
    with only Dirac lobes (smooth conductors, dielectrics) are refused: they have no density."""
    return BSDFSampler(plugin, wi, variant, name)


def microfacet_sampler(distribution: str = "ggx", alpha: float = 0.1, *, visible: bool = True,
                       wi: float | Sequence[float] = 0.0, variant: str = "llvm_ad_rgb",
                       name: str | None = None) -> MicrofacetSampler:
    """Normals of ``mi.MicrofacetDistribution(distribution, alpha, visible)`` on the
    hemisphere; ``wi`` matters only for visible-normal sampling."""
    return MicrofacetSampler(distribution, alpha, visible=visible, wi=wi, variant=variant, name=name)


_PHASES = ("hg", "rayleigh", "isotropic", "blendphase")
_SHAPES = ("rectangle", "sphere", "disk", "cube", "cylinder", "obj", "ply", "serialized")
_DELTA_EMITTERS = ("spot", "point", "directional", "projector", "directionalarea")


def make_sampler(spec: dict[str, Any]) -> MitsubaSampler:
    """A sampler from a suite table's keys (``[[sampler]]`` with ``adapter = "mitsuba"``):

        plugin   a Mitsuba plugin dict: any BSDF; a phase function (hg, rayleigh, isotropic,
                 blendphase); {type = "envmap"} (procedural sky unless ``filename`` is
                 given); a shape with an area emitter ({type = "sphere", center = [0, 0, 2],
                 radius = 0.5, emitter = {type = "area", radiance = ...}}); or {type =
                 "microfacet", distribution = "ggx", alpha = 0.1, sample_visible = true}
        wi       polar angle of the incident direction in degrees, or a 3-vector (default 0;
                 BSDFs, microfacet distributions and phase functions)
        ref      the reference point an emitter on a shape is sampled from (default origin)
        texel_breaks  an envmap's: check it about +y with its texel lines declared as the
                 pdf's breaks (``envmap_sampler``; default true)
        variant  default "llvm_ad_rgb"

    Delta emitters (spot, point, directional) are refused.  Raises ValueError naming the key
    at fault."""
    unknown = set(spec) - {"plugin", "wi", "variant", "name", "ref", "texel_breaks"}
    if unknown:
        raise ValueError(f"'{sorted(unknown)[0]}': unknown key for a Mitsuba sampler; "
                         "expected plugin, wi, ref, texel_breaks, variant, name")
    plugin = spec.get("plugin")
    if not isinstance(plugin, dict) or not isinstance(plugin.get("type"), str):
        raise ValueError(f"'plugin': expected a table with a 'type' key (a Mitsuba plugin), got {plugin!r}")
    variant = spec.get("variant", "llvm_ad_rgb")
    wi = spec.get("wi", 0.0)
    name = spec.get("name")
    kind = plugin["type"]
    if "ref" in spec and kind not in _SHAPES:
        raise ValueError(f"'ref': only emitters on shapes are sampled from a reference point, not {kind!r}")
    if kind in _DELTA_EMITTERS:
        refuse_delta_emitter(kind)
    texel_breaks = spec.get("texel_breaks", True)
    if "texel_breaks" in spec and (not isinstance(texel_breaks, bool) or kind != "envmap"):
        raise ValueError(f"'texel_breaks': true or false, for an envmap only; got {texel_breaks!r} for a "
                         f"{kind!r}")
    if kind == "envmap":
        return envmap_sampler(plugin=plugin, variant=variant, name=name, texel_breaks=texel_breaks)
    if kind in _SHAPES:
        return area_emitter_sampler(plugin, ref=spec.get("ref", (0.0, 0.0, 0.0)), variant=variant, name=name)
    if kind in _PHASES:
        return phase_sampler(plugin, wi=wi, variant=variant, name=name)
    if kind == "microfacet":
        extra = set(plugin) - {"type", "distribution", "alpha", "sample_visible"}
        if extra:
            raise ValueError(f"'plugin': unknown key {sorted(extra)[0]!r} for a microfacet distribution; "
                             "expected distribution, alpha, sample_visible")
        return microfacet_sampler(plugin.get("distribution", "ggx"), plugin.get("alpha", 0.1),
                                  visible=plugin.get("sample_visible", True), wi=wi, variant=variant,
                                  name=name)
    return bsdf_sampler(plugin, wi=wi, variant=variant, name=name)
