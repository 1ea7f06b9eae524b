"""Mitsuba 3 renders as estimators: a scene, an integrator and a variant render at a budget
(samples per pixel) and a seed.

Spec keys (a suite's ``[[render]]`` table with ``adapter = "mitsuba"``):

    scene        a built-in scene (below) or the path of a Mitsuba XML scene file (relative:
                 from the suite file's folder)
    integrator   "path", "direct", "ptracer", "volpath", "volpathmis", ... (a Mitsuba plugin)
    variant      "scalar_rgb" (default) or "llvm_ad_rgb" (or any installed variant)
    max_depth    path length limit of the integrator (default: the scene's)
    width, height  film size of a built-in scene (default 32 x 32)

Built-in scenes (box pixel filter, so pixels are independent estimates):

    furnace   white furnace: a diffuse sphere of albedo 1 under a constant environment of
              radiance 1.  Every pixel's radiance is exactly 1: energy is conserved at every
              bounce, so a sampler whose weight loses or adds energy shows at once.
    plane     a diffuse plane of albedo 0.5 filling the view, seen from above, under a constant
              environment of radiance 1.  The plane cannot shadow itself, so every pixel is
              exactly 0.5 * 1 = 0.5 (rho * L).
    cornell   Mitsuba's Cornell box (area light, diffuse walls); no exact answer.
    glossy    a rough-conductor sphere (GGX, alpha 0.1) on a diffuse floor under a small area
              light; no exact answer.
    media     a sphere of homogeneous scattering medium in the Cornell box (for volpath);
              no exact answer.

Scenes without an exact answer are compared with a reference rendered by ``reference()``
(the path integrator, or volpath where the scene has media, at the same depth; depth 2 for
the direct integrator).  The JIT
variants compile a kernel on their first render at a budget; ``render`` does one untimed
render first at each new budget, so wall times measure rendering, not compilation.
"""
from __future__ import annotations

import hashlib
import time
from pathlib import Path
from typing import Any

import numpy as np

from harness.adapters.base import ENVIRONMENT, Render, RenderError
from harness.adapters.mitsuba.runtime import VARIANT_LOCK, activate
from harness.adapters.mitsuba.scene_files import scene_files

__all__ = ["MitsubaRenderer", "make_renderer", "SCENES"]

SCENES = ("furnace", "plane", "cornell", "glossy", "media")
_EXACT = {"furnace": 1.0, "plane": 0.5}
_MEDIA_SCENES = {"media"}
_KEYS = {"scene", "integrator", "variant", "max_depth", "width", "height"}


def _mi():
    import mitsuba as mi  # imported only when a Mitsuba case runs

    return mi


def _film(width: int, height: int) -> dict[str, Any]:
    return {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"},
            "pixel_format": "rgb", "component_format": "float32"}


def _scene_dict(name: str, width: int, height: int) -> dict[str, Any]:
    mi = _mi()
    T = mi.ScalarTransform4f
    rgb = lambda v: {"type": "rgb", "value": v}  # noqa: E731
    sensor = lambda origin, target, up, fov: {  # noqa: E731
        "type": "perspective", "fov": fov, "to_world": T().look_at(origin=origin, target=target, up=up),
        "film": _film(width, height), "sampler": {"type": "independent"}}
    if name == "furnace":
        return {"type": "scene", "sensor": sensor([0, 0, 4], [0, 0, 0], [0, 1, 0], 40),
                "sky": {"type": "constant", "radiance": rgb(1.0)},
                "ball": {"type": "sphere", "bsdf": {"type": "diffuse", "reflectance": rgb(1.0)}}}
    if name == "plane":
        return {"type": "scene", "sensor": sensor([0, 0, 1], [0, 0, 0], [0, 1, 0], 40),
                "sky": {"type": "constant", "radiance": rgb(1.0)},
                "ground": {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": rgb(0.5)}}}
    if name == "glossy":
        return {"type": "scene", "sensor": sensor([0, 1.5, 4], [0, 0.3, 0], [0, 1, 0], 35),
                "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(4),
                          "bsdf": {"type": "diffuse", "reflectance": rgb(0.6)}},
                "ball": {"type": "sphere", "to_world": T().translate([0, 0.6, 0]).scale(0.6),
                         "bsdf": {"type": "roughconductor", "distribution": "ggx", "alpha": 0.1}},
                "light": {"type": "rectangle",
                          "to_world": T().translate([1, 3, 1]).rotate([1, 0, 0], 90).scale(0.3),
                          "emitter": {"type": "area", "radiance": rgb(40.0)}}}
    d = mi.cornell_box()
    d["sensor"]["film"] = _film(width, height)
    d["sensor"]["sampler"] = {"type": "independent"}
    d.pop("integrator", None)
    if name == "media":
        d.pop("small-box")
        d.pop("large-box")
        d["fog"] = {"type": "sphere", "to_world": T().translate([0, -0.4, 0]).scale(0.5),
                    "bsdf": {"type": "null"},
                    "interior": {"type": "homogeneous", "albedo": rgb(0.8), "sigma_t": 3.0}}
    return d


class MitsubaRenderer:
    """One scene x integrator x variant.  Images are (height, width, 3) linear RGB radiance."""

    def __init__(self, scene: str, integrator: str = "path", variant: str = "scalar_rgb",
                 max_depth: int | None = None, width: int = 32, height: int = 32):
        self.scene_name, self.integrator_type, self.variant = scene, integrator, variant
        self.max_depth, self.width, self.height = max_depth, width, height
        self._scene = self._integrator = None
        self._warm: set[int] = set()
        self._loaded: dict[str, Any] = {}   # a scene file's digests and its reads', as loaded
        self._keyed: dict[str, Any] = {}    # ... as the last fingerprint took them

    # --- protocol ----------------------------------------------------------------------------
    def render(self, spp: int, seed: int) -> Render:
        with VARIANT_LOCK:  # Mitsuba's variant is process-global: hold it for the whole render
            return self._render(spp, seed)

    def _render(self, spp: int, seed: int) -> Render:
        mi = self._activate()
        if spp not in self._warm and not self.variant.startswith("scalar"):
            # some kernels depend on spp (the light tracer's): compile untimed at this budget
            np.asarray(mi.render(self._scene, integrator=self._integrator, spp=int(spp), seed=2**31 - 1))
            self._warm.add(spp)
        start = time.perf_counter()
        image = np.array(mi.render(self._scene, integrator=self._integrator, spp=int(spp), seed=int(seed)),
                         dtype=np.float64)  # np.array forces the JIT variants to finish
        seconds = time.perf_counter() - start
        if image.ndim == 2:
            image = image[:, :, None]
        return Render(image[:, :, :3], int(spp), seconds)

    def exact(self) -> np.ndarray | None:
        value = _EXACT.get(self.scene_name)
        return None if value is None else np.full((self.height, self.width, 3), value)

    def fingerprint(self) -> dict[str, Any]:
        """The settings (a scene file by its content) and the environment: Mitsuba's version,
        where the scene file lies and the digests of the files it reads (meshes, textures,
        included XML: :func:`~harness.adapters.mitsuba.scene_files.scene_files`), part of the
        store key, not of the seeds (an edited mesh is rendered again, on the same seeds)."""
        mi = _mi()
        scene, environment = self.scene_name, {"mitsuba": mi.__version__}
        if self._is_file:
            now = self._files_now()
            scene, environment["reads"] = now["scene"], now["reads"]
            environment["file"] = str(Path(self.scene_name).resolve())
            with VARIANT_LOCK:   # (renders hold it while they use the scene)
                self._keyed = now
                if self._scene is not None and self._loaded != now:
                    # the files changed since the scene was loaded: the renders this key stands
                    # for are of the files as they are now, so the scene is loaded again
                    self._scene = None
                    self._warm.clear()
        return {"adapter": "mitsuba", "scene": scene, "integrator": self.integrator_type,
                "variant": self.variant, "max_depth": self.max_depth, "width": self.width,
                "height": self.height, ENVIRONMENT: environment}

    def reference(self) -> MitsubaRenderer:
        """The renderer of this scene's reference: path tracing (volpath with media) at the
        same depth and variant."""
        ref = "volpath" if self.scene_name in _MEDIA_SCENES else "path"
        depth = 2 if self.integrator_type == "direct" else self.max_depth  # direct: paths of 2 segments
        return MitsubaRenderer(self.scene_name, ref, self.variant, depth, self.width, self.height)

    # --- internals ---------------------------------------------------------------------------
    def _files_now(self) -> dict[str, Any]:
        """A scene file's SHA-256 and the digests of the files it reads, as they are now."""
        path = Path(self.scene_name)
        return {"scene": {"sha256": hashlib.sha256(path.read_bytes()).hexdigest()},
                "reads": scene_files(path, self.variant)}

    @property
    def _is_file(self) -> bool:
        return self.scene_name not in SCENES

    def _activate(self):
        """Sets this renderer's variant (process-global in Mitsuba) and loads the scene once (a
        scene file again after :meth:`fingerprint` found it or a file it reads changed)."""
        mi = activate(self.variant)
        if self._scene is None:
            if self._is_file:
                now = self._files_now()
                if self._keyed and now != self._keyed:   # the key stands for other files
                    before, after = self._keyed["reads"], now["reads"]
                    changed = [k for k in sorted({*before, *after}) if before.get(k) != after.get(k)]
                    raise RenderError(f"{self.scene_name}: its files changed after the run took its key "
                                      f"({', '.join(changed) or 'the scene file'}); run it again")
                self._loaded = now
                try:
                    self._scene = mi.load_file(self.scene_name)
                except RuntimeError as e:   # Mitsuba's parser: a missing mesh, a bad plugin
                    first = str(e).splitlines()[0]
                    raise RenderError(f"Mitsuba cannot load {self.scene_name}: {first}") from e
            else:
                self._scene = mi.load_dict(_scene_dict(self.scene_name, self.width, self.height))
            integ: dict[str, Any] = {"type": self.integrator_type}
            if self.max_depth is not None and self.integrator_type != "direct":  # direct has no depth
                integ["max_depth"] = self.max_depth
            self._integrator = mi.load_dict(integ)
        return mi


def make_renderer(spec: dict[str, Any], *, base: Path | None = None) -> MitsubaRenderer:
    """A MitsubaRenderer from a suite table's keys; ``ValueError`` names a bad key.  A scene
    file's relative path is taken from ``base`` (the suite file's folder; the working folder
    without one), as the other adapters take theirs."""
    unknown = set(spec) - _KEYS
    if unknown:
        raise ValueError(f"'{sorted(unknown)[0]}': unknown key for adapter 'mitsuba'; "
                         f"expected one of {sorted(_KEYS)}")
    scene = spec.get("scene")
    if not isinstance(scene, str) or not scene:
        raise ValueError(f"'scene': expected a built-in scene name {list(SCENES)} or the path of an XML file")
    if scene not in SCENES:
        path = (base or Path.cwd()) / scene
        if not path.is_file():
            raise ValueError(f"'scene': {scene!r} is neither a built-in scene {list(SCENES)} "
                             f"nor an existing file ({path.resolve()})")
        scene = str(path.resolve())
    integrator = spec.get("integrator", "path")
    if not isinstance(integrator, str):
        raise ValueError(f"'integrator': expected a Mitsuba integrator name, got {integrator!r}")
    variant = spec.get("variant", "scalar_rgb")
    mi = _mi()
    if variant not in mi.variants():
        raise ValueError(f"'variant': {variant!r} is not an installed Mitsuba variant {mi.variants()}")
    if not variant.endswith("rgb"):
        raise ValueError(f"'variant': expected an RGB variant (images are compared as RGB), got {variant!r}")
    max_depth = spec.get("max_depth")
    if max_depth is not None and (isinstance(max_depth, bool) or not isinstance(max_depth, int)
                                  or max_depth < -1 or max_depth == 0):
        raise ValueError(f"'max_depth': expected -1 (unlimited) or a positive integer, got {max_depth!r}")
    if integrator == "direct" and max_depth not in (None, 2):
        raise ValueError("'max_depth': the direct integrator renders paths of 2 segments only; "
                         "give 2 or leave it out")
    size = {}
    for k in ("width", "height"):
        v = spec.get(k, 32)
        if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 8192:
            raise ValueError(f"'{k}': expected an integer in [1, 8192], got {v!r}")
        if k in spec and scene not in SCENES:
            raise ValueError(f"'{k}': the film size of an XML scene comes from its file")
        size[k] = v
    r = MitsubaRenderer(scene, integrator, variant, max_depth, size["width"], size["height"])
    try:
        with VARIANT_LOCK:
            r._activate()
    except RenderError as e:  # the scene file's (its own XML, a mesh it reads, ...)
        raise ValueError(f"'scene': {e}") from e
    except Exception as e:  # Mitsuba's own message: unknown plugin, bad XML, ...
        key = "integrator" if "integrator" in str(e).lower() or "plugin" in str(e).lower() else "scene"
        raise ValueError(f"'{key}': Mitsuba cannot load it: {str(e).splitlines()[0]}") from e
    return r
