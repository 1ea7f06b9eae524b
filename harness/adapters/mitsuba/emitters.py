"""Mitsuba 3 emitters as batch sample / pdf / eval triples over directions: environment maps
seen from the origin (:class:`EnvmapSampler`), and area lights on shapes (a rectangle, a
sphere, any shape with an ``area`` emitter) sampled by direction from a reference point
(:class:`AreaEmitterSampler`).  Delta emitters are refused (:func:`refuse_delta_emitter`).

    s = area_emitter_sampler({"type": "sphere", "center": [0, 0, 2], "radius": 0.5,
                              "emitter": {"type": "area", "radiance": 1.0}}, ref=(0, 0, 0))
    x = s.sample(u)       # u (N, 2) -> world directions (N, 3) from ref; NaN where none is produced
    s.pdf(x)              # (N,) per steradian at ref; 0 where the ray from ref misses the light
    s.eval(x)             # (N, channels) radiance arriving from x (0 where it misses)

Densities are per unit solid angle on the sphere of directions at the reference point (the
emitter's ``sample_direction`` / ``pdf_direction``).  For a direction given to ``pdf`` the
adapter traces a ray from the reference point in a scene holding only the light and builds
the DirectionSample3f Mitsuba's integrators build from the hit (position, normal, uv,
distance), so a direction that misses the shape, or reaches its back, has density 0.  A
textured (bitmap) radiance makes Mitsuba sample the texture over the whole surface, then
reject points facing away from the reference point (a sphere's far side): those samples are
not produced, and the failure-aware check tests their count against 1 - P.
"""
from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from harness.adapters.mitsuba.batch import MitsubaSampler, zeros
from harness.adapters.mitsuba.cap import Cap, bounding_cap, box_cap
from harness.adapters.mitsuba.rectangle import Rectangle
from harness.adapters.mitsuba.runtime import using_variant
from harness.samplers.domains import Domain

__all__ = ["AreaEmitterSampler", "EnvmapSampler", "area_emitter_sampler", "envmap_sampler", "light_bitmap",
           "rectangle_light", "refuse_delta_emitter", "sky_bitmap", "sphere_light"]


class EnvmapSampler(MitsubaSampler):
    """An ``envmap`` emitter seen from the origin: ``sample_direction(it, u)`` -> (ds, radiance
    / pdf), ``pdf_direction(it, ds)``, radiance ``emitter.eval(si)`` with si.wi = -d;
    directions in world space on the sphere (Mitsuba's envmap puts v = 0 of the image at +y)."""

    kind = "envmap"
    udim = 2
    domain = "sphere"

    def __init__(self, bitmap: np.ndarray | None = None, *, plugin: dict[str, Any] | None = None,
                 variant: str = "llvm_ad_rgb", name: str | None = None, texel_breaks: bool = True):
        params = dict(plugin or {"type": "envmap"})
        self.texel_breaks = bool(texel_breaks)
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
                                      else str(self.plugin.get("filename")))
                         + ("" if self.texel_breaks else ", without texel breaks"))
        super().__init__(variant, label)
        self._build_checked(f"an envmap from {self.plugin!r}")
        self._resolution = None if self.image is None else self.image.shape[:2]
        if self.texel_breaks and self.image is None:    # the file's (height, width), as Mitsuba read it
            with using_variant(variant) as mi:
                width, height = mi.Bitmap(str(self.plugin["filename"])).size()
            self._resolution = (int(height), int(width))

    def _build(self, mi: Any) -> Any:
        d = dict(self.plugin)
        if self.image is not None:
            d["bitmap"] = mi.Bitmap(self.image)
        return mi.load_dict(d)

    @property
    def pole(self) -> str:
        """The sphere's pole the check measures theta from: with ``texel_breaks``, +y, where
        the map's rows (cones about +y) are cuts of the first parameter."""
        return "y" if self.texel_breaks else "z"

    @property
    def breaks(self) -> tuple[np.ndarray, np.ndarray] | None:
        """With ``texel_breaks`` (the default), where the pdf kinks, in the parameters of
        ``Domain("sphere", pole="y")``: Mitsuba samples the map's luminance interpolated
        bilinearly between texel centres, rows at theta = pi i / (H - 1) and columns at
        u = (j + 1/2) / W, where u = phi_m / 2 pi with d = (sin theta sin phi_m, cos theta,
        -sin theta cos phi_m), so the domain's azimuth atan2(x, z) is pi - phi_m (probed on a
        random 8 x 16 map: the kinks lie there to 1e-3 of a texel).  Else None."""
        if not self.texel_breaks:
            return None
        height, width = self._resolution
        theta = math.pi * np.arange(1, height - 1) / (height - 1)
        phi = math.pi - 2 * math.pi * (np.arange(width) + 0.5) / width
        return Domain("sphere", pole=self.pole).breaks(theta, phi)

    @staticmethod
    def _it(mi, width):
        return zeros(mi, "Interaction3f", width)

    def _ds(self, mi, width, x, y, z):
        ds = zeros(mi, "DirectionSample3f", width)
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
        si = zeros(mi, "SurfaceInteraction3f", width)
        si.wi = -mi.Vector3f(x, y, z)
        return emitter.eval(si)

    def _spec(self) -> dict[str, Any]:
        if self.image is not None:
            digest = hashlib.sha256(self.image.tobytes()).hexdigest()
        else:  # the file's contents, so that an edited map is a different sampler
            with open(str(self.plugin["filename"]), "rb") as f:
                digest = hashlib.sha256(f.read()).hexdigest()
        return {"plugin": {k: v for k, v in self.plugin.items()}, "image_sha256": digest,
                "bitmap_shape": list(self.image.shape) if self.image is not None else None,
                "texel_breaks": self.texel_breaks}


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


def envmap_sampler(bitmap: np.ndarray | None = None, *, plugin: dict[str, Any] | None = None,
                   variant: str = "llvm_ad_rgb", name: str | None = None,
                   texel_breaks: bool = True) -> EnvmapSampler:
    """Directions from an ``envmap`` emitter built from ``bitmap`` (a lat-long float array;
    default: ``sky_bitmap()``) or from ``plugin`` (e.g. {"type": "envmap", "filename": ...,
    "scale": 2}), on the sphere.  ``texel_breaks`` (default): check it on the sphere with its
    pole at +y and the texel lines declared as the pdf's breaks (``EnvmapSampler.breaks``):
    on the 256 x 128 sky the u0 table's bound is 3e-6 and u1's 2-3e-5 where without them
    (``texel_breaks=False``) they are 0.03-0.04 (a u0 test without power at any n) and
    1-2e-3, for 1.4 times the setup's pdf calls (about twice its time); no false alarm in 200
    seeds either way (benchmarks/envmap_calibration.py)."""
    return EnvmapSampler(bitmap, plugin=plugin, variant=variant, name=name, texel_breaks=texel_breaks)


def refuse_delta_emitter(kind: str) -> None:
    """Raises the ValueError for emitters with no density to test: a ``spot`` or ``point``
    light is a Dirac delta in position, so ``sample_direction`` from a reference point returns
    the one direction towards it (``pdf_direction`` is 0: a delta has no density); a
    ``directional`` light is a delta in direction.  Mitsuba 3.9 does not report the density of
    the direction ``sample_ray`` draws inside a spot's cone either (its weight folds the
    uniform-cone pdf into the falloff), so there is no reported pdf to check: testing a
    density the adapter wrote itself would test the adapter."""
    raise ValueError(f"'plugin': a {kind!r} light is a Dirac delta in position or direction: from a "
                     "reference point sample_direction returns a single direction (a delta, "
                     "pdf_direction 0) and sample_ray's direction density is not exposed by Mitsuba, so "
                     "there is no density to test")


def _radiance(value: Any) -> tuple[Any, np.ndarray | None]:
    """An area emitter's ``radiance`` as a plugin value (a float, an rgb, a texture dict with
    a numpy ``bitmap``) and the bitmap array, if any."""
    if isinstance(value, np.ndarray):
        value = {"type": "bitmap", "bitmap": value}
    if isinstance(value, dict) and isinstance(value.get("bitmap"), (np.ndarray, list)):
        img = np.ascontiguousarray(value["bitmap"], dtype=np.float32)
        if img.ndim == 2:
            img = img[:, :, None]
        if img.ndim != 3 or img.shape[2] not in (1, 3) or min(img.shape[:2]) < 1 or not np.all(img >= 0):
            raise ValueError("'radiance': a bitmap must be a non-negative (height, width, 3) or (height, "
                             f"width, 1) array, got shape {img.shape}")
        return {"raw": True, **value, "type": "bitmap", "bitmap": img}, img
    if isinstance(value, (list, tuple)):
        if len(value) != 3:
            raise ValueError(f"'radiance' must be a float, an RGB triple or a texture, got {value!r}")
        return {"type": "rgb", "value": [float(v) for v in value]}, None
    return value, None


def _matrix(value: Any) -> Any:
    """A ``to_world`` given as a nested 4x4 list (as a suite file can write it), else as is."""
    if isinstance(value, (list, tuple, np.ndarray)):
        m = np.asarray(value, dtype=float)
        if m.shape != (4, 4) or not np.all(np.isfinite(m)):
            raise ValueError(f"'to_world' must be a 4x4 matrix, got {value!r}")
        return m
    return value


def _to_world_array(value: Any) -> np.ndarray | None:
    """A shape's ``to_world`` as a 4 x 4 array (a Mitsuba transform's matrix); None for none."""
    if value is None or isinstance(value, np.ndarray):
        return value
    return np.asarray(value.matrix, dtype=float).reshape(4, 4)


class AreaEmitterSampler(MitsubaSampler):
    """An ``area`` emitter on a shape, sampled by direction from the reference point ``ref``
    (world space): ``emitter.sample_direction(it, u)`` -> (ds, radiance / pdf);
    ``emitter.pdf_direction(it, ds)`` and ``emitter.eval(si)`` at the surface interaction
    of the ray from ``ref`` along a direction (see the module).

    Directions, pdfs and weights are world quantities on the sphere (``domain``).
    ``mapping``: the map in which ``check_mitsuba_sampler`` runs its statistical tests, "auto"
    (default) a rectangle's own square (:class:`~harness.adapters.mitsuba.rectangle.Rectangle`,
    a bitmap's texel grid declared as its breaks) where its radiance is a constant (a number,
    an RGB triple) or a nearest-filtered numpy bitmap without a ``to_uv`` and ``ref`` sees it
    at no more than a grazing angle float32 resolves (:meth:`Rectangle.of_rectangle`); else
    the cone of directions holding the light (:mod:`harness.adapters.mitsuba.cap`): a sphere's
    own, any other shape's round its bounding box's corners (None where ``ref`` is inside the
    box or the cone would pass a hemisphere); None (tested on the whole sphere); or a
    :class:`~harness.adapters.mitsuba.cap.Cap` or a
    :class:`~harness.adapters.mitsuba.rectangle.Rectangle`."""

    kind = "emitter"
    udim = 2
    domain = "sphere"
    check_threads = None   # its pdf traces a ray a direction: every drjit worker (MitsubaSampler)
    sample_outputs = ("x", "weight", "pdf", "dist", "cos")

    def __init__(self, shape: dict[str, Any], *, ref: Sequence[float] = (0.0, 0.0, 0.0),
                 variant: str = "llvm_ad_rgb", name: str | None = None,
                 mapping: Cap | Rectangle | str | None = "auto"):
        if not isinstance(shape, dict) or not isinstance(shape.get("type"), str):
            raise ValueError(f"'plugin' must be a Mitsuba shape dict with a 'type' key, got {shape!r}")
        emitter = shape.get("emitter")
        if not isinstance(emitter, dict) or emitter.get("type") != "area":
            raise ValueError(f"'plugin': the shape {shape['type']!r} needs an 'emitter' = {{'type': 'area', "
                             f"'radiance': ...}} to be sampled as a light, got {emitter!r}")
        r = np.asarray(ref, dtype=float)
        if r.shape != (3,) or not np.all(np.isfinite(r)):
            raise ValueError(f"'ref' must be a finite 3-vector (a point in world space), got {ref!r}")
        self.ref = tuple(float(c) for c in r)
        radiance, self.image = _radiance(emitter.get("radiance", 1.0))
        self.plugin = {**shape, "emitter": {**emitter, "radiance": radiance}}
        if "to_world" in shape:
            self.plugin["to_world"] = _matrix(shape["to_world"])
        super().__init__(variant, name or self._label())
        scene, _ = self._build_checked(f"an area light on {shape['type']!r}")
        if isinstance(mapping, str) and mapping == "auto":
            mapping = self._auto_mapping(scene)
        elif mapping is not None and not isinstance(mapping, (Cap, Rectangle)):
            raise ValueError(f"'mapping' must be 'auto', None, a Cap or a Rectangle, got {mapping!r}")
        self.mapping = mapping

    def _auto_mapping(self, scene: Any) -> Cap | Rectangle | None:
        """The map the check tests this light in (see the class)."""
        kind = self.plugin["type"]
        radiance = self.plugin["emitter"]["radiance"]
        # a constant or nearest-filtered radiance is 5x faster in the square (0.17-0.21 s against
        # 0.97-1.09 s: 2-3 million pdf calls against 14-23); a bilinear bitmap's float32 pdf is
        # noisy along its steep slopes (1e-5 relative: the float32 uv of a direction's hit times
        # a 100 : 1 texel step), which the square's CDF tables chase (54 million pdf calls,
        # 2.5 s, where the cap's map spends 33 million, 1.2 s); any other texture (a file, a
        # procedural one: its texel grid unknown) keeps the cap too
        constant = isinstance(radiance, (int, float)) or (isinstance(radiance, dict)
                                                          and radiance.get("type") == "rgb")
        nearest = (self.image is not None and radiance.get("filter_type", "bilinear") == "nearest"
                   and "to_uv" not in radiance)
        if kind == "rectangle" and (constant or nearest):
            texels = None if self.image is None else (self.image.shape[1], self.image.shape[0])
            rect = Rectangle.of_rectangle(self.ref, _to_world_array(self.plugin.get("to_world")), texels,
                                          float32="double" not in self.variant)
            if rect is not None:
                return rect
        with using_variant(self.variant):
            bb = scene.shapes()[0].bbox()
            lo, hi = np.array(bb.min, dtype=float).ravel(), np.array(bb.max, dtype=float).ravel()
        if kind == "sphere":
            return bounding_cap(self.ref, (lo + hi) / 2, float((hi - lo).max() / 2))
        return box_cap(self.ref, lo, hi)

    def _label(self) -> str:
        rad = self.plugin["emitter"]["radiance"]
        if self.image is not None:
            h, w = self.image.shape[:2]
            what = f"bitmap {w}x{h} {rad.get('filter_type', 'bilinear')}"
        else:
            what = "constant"
        return f"area {self.plugin['type']} {what} from ({', '.join(f'{c:g}' for c in self.ref)})"

    def _build(self, mi: Any) -> Any:
        d = dict(self.plugin)
        em = dict(d["emitter"])
        rad = em["radiance"]
        if self.image is not None:
            em["radiance"] = {**rad, "bitmap": mi.Bitmap(self.image)}
        d["emitter"] = em
        if isinstance(d.get("to_world"), np.ndarray):
            d["to_world"] = mi.ScalarTransform4f(d["to_world"].tolist())
        scene = mi.load_dict({"type": "scene", "light": d})
        return scene, scene.emitters()[0]

    def _it(self, mi: Any, width: int | None) -> Any:
        it = zeros(mi, "Interaction3f", width)
        it.p = mi.Point3f(*self.ref)
        return it

    def _hit(self, mi: Any, scene: Any, width: int | None, x: Any, y: Any, z: Any) -> tuple[Any, Any, Any]:
        it = self._it(mi, width)
        si = scene.ray_intersect(mi.Ray3f(it.p, mi.Vector3f(x, y, z)))
        return it, si, si.is_valid()

    def _sample_kernel(self, mi, obj, width, u0, u1):
        import drjit as dr

        _, emitter = obj
        ds, weight = emitter.sample_direction(self._it(mi, width), mi.Point2f(u0, u1))
        return ds.d, weight, ds.pdf, ds.dist, -dr.dot(ds.d, ds.n)

    def _pdf_kernel(self, mi, obj, width, x, y, z):
        import drjit as dr

        scene, emitter = obj
        it, si, hit = self._hit(mi, scene, width, x, y, z)
        ds = mi.DirectionSample3f(scene, si, it)
        return dr.select(hit, emitter.pdf_direction(it, ds, hit), 0.0)

    def _eval_kernel(self, mi, obj, width, x, y, z):
        import drjit as dr

        scene, emitter = obj
        _, si, hit = self._hit(mi, scene, width, x, y, z)
        return dr.select(hit, emitter.eval(si, hit), 0.0)

    def _spec(self) -> dict[str, Any]:
        plugin = {**self.plugin, "emitter": dict(self.plugin["emitter"])}
        if self.image is not None:
            plugin["emitter"]["radiance"] = {k: v for k, v in plugin["emitter"]["radiance"].items()
                                             if k != "bitmap"}
        if isinstance(plugin.get("to_world"), np.ndarray):
            plugin["to_world"] = plugin["to_world"].tolist()
        digest = hashlib.sha256(self.image.tobytes()).hexdigest() if self.image is not None else None
        return {"plugin": plugin, "ref": list(self.ref), "image_sha256": digest,
                "mapping": None if self.mapping is None else {"kind": type(self.mapping).__name__,
                                                              **self.mapping.spec()}}


def area_emitter_sampler(shape: dict[str, Any], *, ref: Sequence[float] = (0.0, 0.0, 0.0),
                         variant: str = "llvm_ad_rgb", name: str | None = None,
                         mapping: Cap | Rectangle | str | None = "auto") -> AreaEmitterSampler:
    """Directions towards an area light on a shape (a Mitsuba shape dict with ``emitter =
    {"type": "area", "radiance": ...}``; the radiance a float, an RGB triple, a texture dict,
    or a numpy array / {"type": "bitmap", "bitmap": array, "filter_type": "nearest"}) from
    the reference point ``ref``, density per steradian (its statistical tests run in the
    light's own square or in the equal-area map of the cap holding it unless ``mapping`` is None:
    see :class:`AreaEmitterSampler`);
    ``to_world`` may be a 4x4 nested list."""
    return AreaEmitterSampler(shape, ref=ref, variant=variant, name=name, mapping=mapping)


def rectangle_light(radiance: Any, *, center: Sequence[float] = (0.0, 0.0, 1.0), size: float = 1.0,
                    facing_down: bool = True) -> dict[str, Any]:
    """A square area light of side ``2 size`` centred at ``center`` in a plane z = const,
    emitting towards -z (``facing_down``, towards the origin below it) or +z, as a shape dict
    for :func:`area_emitter_sampler`."""
    s = float(size)
    flip = -1.0 if facing_down else 1.0
    c = [float(v) for v in center]
    to_world = [[s, 0, 0, c[0]], [0, flip * s, 0, c[1]], [0, 0, flip * s, c[2]], [0, 0, 0, 1]]
    return {"type": "rectangle", "to_world": to_world, "emitter": {"type": "area", "radiance": radiance}}


def sphere_light(radiance: Any, *, center: Sequence[float] = (1.0, 0.6, 1.6),
                 radius: float = 0.5) -> dict[str, Any]:
    """A spherical area light (its uv poles along z), as a shape dict for
    :func:`area_emitter_sampler`.  The default centre is off the z axis on purpose: seen from
    the origin, a sphere on the axis fills a cone around the pole of the check's sphere
    parameterisation, whose rim then lies along a row of cells, between the cubature's nodes."""
    return {"type": "sphere", "center": [float(v) for v in center], "radius": float(radius),
            "emitter": {"type": "area", "radiance": radiance}}


def light_bitmap(width: int = 32, height: int = 16, *, seed: int = 1) -> np.ndarray:
    """A test texture for area lights (height, width, 3) float32: a smooth ramp times a
    checkerboard of 8 x 4 blocks, radiance from 0.05 to 6 (a 100 : 1 step between
    neighbouring blocks), with per-texel noise from ``seed``."""
    if width < 2 or height < 2:
        raise ValueError(f"'width' and 'height' must be at least 2, got {width} x {height}")
    v, u = np.meshgrid((np.arange(height) + 0.5) / height, (np.arange(width) + 0.5) / width, indexing="ij")
    checker = np.where((np.floor(u * 8) + np.floor(v * 4)) % 2 == 0, 1.0, 0.01)
    noise = np.random.default_rng(seed).uniform(0.8, 1.2, size=(height, width))
    lum = (1 + 5 * u * v) * checker * noise
    return (lum[:, :, None] * np.array([1.0, 0.8, 0.6])[None, None, :]).astype(np.float32)
