"""pyrender adapter: Monte Carlo over a rasterizer (headless, OSMesa).

A rasterizer draws one deterministic frame per call, so the Monte Carlo lives in how frames
are combined.  Frame i is drawn with the i-th point of a point set u_i in (0,1)^d (random,
jittered-stratified or Owen-scrambled Sobol', from ``reference_estimators.points``), and the
estimate at budget ``spp`` is the plain average of ``spp`` frames:

* ``antialias``: u_i maps to a sub-pixel offset (dx, dy) drawn from the pixel filter's
  footprint (``box``: uniform in [-1/2, 1/2]^2 pixels; ``tent``: the separable tent of radius
  1 pixel, by inversion, which keeps stratification), applied by shifting the camera's
  principal point by (dx, dy) pixels.  For a pinhole camera that shift is an exact
  translation of the image plane: the frame's content moves by (dx, dy) pixels, so pixel
  (row i, column j) samples the image point (j + 1/2 - dx, i + 1/2 - dy) (for integer shifts
  the frame moves bitwise, which the tests check; the filters are symmetric, so the sign does
  not matter).  The average estimates the filtered image (the pixel filter applied to the
  frame as a function of the sample position).
* ``soft_shadow``: u_i maps to a point y_i of the scene's area light (rectangle: uniform;
  disk: the concentric map, which keeps strata compact), where the frame places a pyrender
  spot light pointing straight down.  Radiometric convention: every frame's spot light
  carries the area light's full intensity I, and the average of N frames estimates the image
  of an area light whose intensity I is spread uniformly over its area (intensity I/|A| per
  unit area, each point with pyrender's spot profile and 1/d^2 fall-off).  Shadows come from
  pyrender's spot-light shadow maps (``RenderFlags.SHADOWS_SPOT``; pyrender 0.1.45 has no
  point-light shadows).
* ``antialias+soft_shadow``: both at once, from 4-dimensional points (offset, light point).
  (``antialias`` alone on a scene with an area light keeps the spot at its centre: hard
  shadows.)

The estimand is the expectation of the *displayed* frame: pyrender encodes each frame with
gamma 1/2.2, clamps to [0, 1] and quantises to 8 bits, and the image returned is the
average of those bytes / 255 (float64, (height, width, 3), in [0, 1]).  That is not the gamma
of the averaged radiance; references must therefore come from this same estimator at a high
frame count (``exact()`` is None), which the suite runner renders and caches.  Frames are
summed in float64, which is exact for bytes (any order, any count below 2^45 frames), and a
frame with NaN pixels (impossible from 8-bit frames, possible from a modified frame source)
makes those pixels NaN in the estimate: they are reported by ``image_faults``, never averaged
away.

Judging these estimates.  A stratified or Sobol' estimate of a pixel on a shadow or
silhouette edge that lines up with the strata is a two-point mixture (one point per strip
decides lit or shadowed), so a handful of replicas can all land on one side and their spread
understates the error: test such estimates for bias against a reference made of random-point
parts (iid frames, whose spread is honest), as tests/test_pyrender_adapter.py does.

Engineering notes.  One ``OffscreenRenderer`` per (width, height) lives for the process
(context, compiled shaders and uploaded meshes are reused) and is freed at exit; all GL work
holds one lock, so threads may share renderers (frames are drawn one at a time).  Two
pyrender 0.1.45 defects are worked around here without patching pyrender: its shader-program
cache is keyed by the current context's ctypes pointer object, which under OSMesa compares
unequal on every call, so every frame recompiled (and leaked) its shaders, ~110 instead of
~1300 frames/s at 32x32 -- each renderer here gets a cache keyed by shader names and defines
(it owns exactly one context); and ``Mesh.bounds`` uses ``np.infty`` (removed in numpy 2),
so scenes set mesh bounds up front (harness.adapters.pyrender.scenes).  Shadow frames cost ~4 ms, most of it
pyrender's fixed 2048^2 shadow map.

    r = make_renderer({"scene": "shadow", "technique": "soft_shadow", "points": "stratified"})
    out = r.render(spp=64, seed=3)     # Render(image (32, 32, 3) float64 in [0, 1], spp=64, seconds)
"""
from __future__ import annotations

import os

os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")  # before pyrender or OpenGL is imported

import atexit
import hashlib
import itertools
import json
import math
import numbers
import threading
import time
from typing import Any, Mapping

import numpy as np
import OpenGL
import OpenGL.GL as gl
import pyrender
import trimesh
from pyrender.constants import SHADOW_TEX_SZ
from pyrender.shader_program import ShaderProgramCache

import reference_estimators as rest

from harness.adapters.base import ENVIRONMENT, Render
from harness.adapters.pyrender import scenes
from harness.stats.validate import integer_in

__all__ = ["make_renderer", "PyrenderRenderer", "TECHNIQUES", "POINTS", "PIXEL_FILTERS", "LIGHT_SHAPES",
           "SCENE_NAMES", "frame_offsets", "light_points"]

TECHNIQUES = ("antialias", "soft_shadow", "antialias+soft_shadow")
POINTS = ("random", "stratified", "sobol")
PIXEL_FILTERS = ("box", "tent")
LIGHT_SHAPES = ("rectangle", "disk")
SCENE_NAMES = tuple(scenes.SCENES)
MAX_SIZE = 1024           # pixels per side; OSMesa renders in software
MAX_SEED = 2**64 - 1
MAX_SPP = 2**24        # frames per estimate: their points are held in memory (dim x 8 bytes each)
_KEYS = ("scene", "technique", "points", "width", "height", "pixel_filter", "light_size", "light_shape")


# --- mapping canonical points to offsets and light points -----------------------------------
def frame_offsets(u: np.ndarray, pixel_filter: str = "box") -> np.ndarray:
    """Sub-pixel offsets (n, 2) in pixels from canonical points u (n, 2) in (0, 1):
    ``box`` -> uniform on [-1/2, 1/2]^2; ``tent`` -> density (1-|x|)(1-|y|) on [-1, 1]^2 by
    inverting each coordinate's CDF.  Both maps are monotone per coordinate, so strata of u
    stay strata of offsets."""
    u = np.asarray(u, dtype=np.float64)
    if pixel_filter == "box":
        return u - 0.5
    if pixel_filter == "tent":
        return np.where(u < 0.5, np.sqrt(2.0 * u) - 1.0, 1.0 - np.sqrt(2.0 * (1.0 - u)))
    raise ValueError(f"'pixel_filter' must be one of {list(PIXEL_FILTERS)}, got {pixel_filter!r}")


def light_points(u: np.ndarray, shape: str, size: float) -> np.ndarray:
    """Points (n, 2) on a horizontal emitter centred at 0, uniform per unit area, from canonical
    points u (n, 2): ``rectangle`` of side ``size`` (affine map), ``disk`` of diameter ``size``
    (Shirley-Chiu concentric map: area-preserving, so uniform u gives uniform points, and
    compact strata of u give compact regions of the disk)."""
    u = np.asarray(u, dtype=np.float64)
    if shape == "rectangle":
        return (u - 0.5) * size
    if shape == "disk":
        a, b = 2.0 * u[:, 0] - 1.0, 2.0 * u[:, 1] - 1.0
        first = np.abs(a) > np.abs(b)
        r = np.where(first, a, b)
        with np.errstate(divide="ignore", invalid="ignore"):
            phi = np.where(first, (math.pi / 4) * b / a, math.pi / 2 - (math.pi / 4) * a / b)
        phi = np.where(r == 0, 0.0, phi)
        return 0.5 * size * np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1)
    raise ValueError(f"'light_shape' must be one of {list(LIGHT_SHAPES)}, got {shape!r}")


# --- shared OSMesa renderers ---------------------------------------------------------------------
class _ContextProgramCache(ShaderProgramCache):
    """pyrender's shader cache keyed by shader names and defines only: each renderer owns
    exactly one GL context, and pyrender's own key (the context's ctypes pointer object) never
    compares equal under OSMesa, which recompiles and leaks the shaders on every frame."""

    def __init__(self) -> None:
        super().__init__()
        self._by_source: dict[tuple, Any] = {}

    def get_program(self, vertex_shader, fragment_shader, geometry_shader=None, defines=None):
        key = (vertex_shader, fragment_shader, geometry_shader, tuple(sorted((defines or {}).items())))
        program = self._by_source.get(key)
        if program is None:
            program = super().get_program(vertex_shader, fragment_shader, geometry_shader, defines)
            self._by_source[key] = program
        return program

    def clear(self) -> None:
        super().clear()
        self._by_source = {}


_GL_LOCK = threading.RLock()
_OFFSCREEN: dict[tuple[int, int], pyrender.OffscreenRenderer] = {}
_LAST_SCENE: dict[tuple[int, int], int] = {}   # token of the PyrenderRenderer that last drew with each
_TOKENS = itertools.count()


def _offscreen(width: int, height: int) -> pyrender.OffscreenRenderer:
    """The process's renderer for (width, height); call with ``_GL_LOCK`` held."""
    r = _OFFSCREEN.get((width, height))
    if r is None:
        r = pyrender.OffscreenRenderer(width, height)
        r._renderer._program_cache = _ContextProgramCache()
        _OFFSCREEN[(width, height)] = r
    return r


@atexit.register
def _release_renderers() -> None:
    """Frees every OSMesa context (registered after pyrender's import, so it runs first)."""
    with _GL_LOCK:
        while _OFFSCREEN:
            _, r = _OFFSCREEN.popitem()
            try:
                r.delete()
            except Exception:  # a context that is already gone at shutdown; nothing left to free
                pass
        _LAST_SCENE.clear()


def _gl_strings(width: int, height: int) -> dict[str, str]:
    """GL vendor, renderer and version of the context that draws the frames (the Mesa build
    changes rasterisation, so it belongs in the fingerprint)."""
    with _GL_LOCK:
        r = _offscreen(width, height)
        r._platform.make_current()
        return {k: gl.glGetString(v).decode() for k, v in
                (("vendor", gl.GL_VENDOR), ("renderer", gl.GL_RENDERER), ("version", gl.GL_VERSION))}


# --- spec validation -----------------------------------------------------------------------------
def _choice(spec: Mapping[str, Any], key: str, options: tuple[str, ...], default: str | None) -> str:
    if key not in spec:
        if default is None:
            raise ValueError(f"pyrender spec: missing required key {key!r}; expected one of {list(options)}")
        return default
    v = spec[key]
    if not isinstance(v, str) or v not in options:
        raise ValueError(f"pyrender spec: {key!r} must be one of {list(options)}, got {v!r}")
    return v


def _size(spec: Mapping[str, Any], key: str) -> int:
    v = spec.get(key, 32)
    if isinstance(v, bool) or not isinstance(v, numbers.Integral) or not 1 <= v <= MAX_SIZE:
        raise ValueError(f"pyrender spec: {key!r} must be an integer number of pixels in [1, {MAX_SIZE}], "
                         f"got {v!r}")
    return int(v)


# --- the renderer -------------------------------------------------------------------------------
class PyrenderRenderer:
    """One validated configuration: scene, technique, point set, image size, filter, light.
    See the module docstring for what an estimate estimates."""

    def __init__(self, spec: Mapping[str, Any]) -> None:
        if not isinstance(spec, Mapping):
            raise ValueError(f"pyrender spec must be a table of keys {list(_KEYS)}, "
                             f"got {type(spec).__name__}")
        unknown = sorted(set(spec) - set(_KEYS))
        if unknown:
            raise ValueError(f"pyrender spec: unknown key(s) {unknown}; expected keys among {list(_KEYS)}")
        self._spec = dict(spec)
        self.scene_name = _choice(spec, "scene", SCENE_NAMES, None)
        self.technique = _choice(spec, "technique", TECHNIQUES, None)
        self.points = _choice(spec, "points", POINTS, "random")
        self.width, self.height = _size(spec, "width"), _size(spec, "height")
        self.desc = scenes.scene(self.scene_name)
        self.antialias = self.technique in ("antialias", "antialias+soft_shadow")
        self.soft_shadow = self.technique in ("soft_shadow", "antialias+soft_shadow")
        if not self.antialias and "pixel_filter" in spec:
            raise ValueError(f"pyrender spec: 'pixel_filter' applies to the antialias techniques, "
                             f"not to technique {self.technique!r}")
        self.pixel_filter = (_choice(spec, "pixel_filter", PIXEL_FILTERS, "box") if self.antialias
                             else None)
        self.light_shape: str | None = None
        self.light_size: float | None = None
        if self.soft_shadow:
            if self.desc.area_light is None:
                with_light = [n for n in SCENE_NAMES if scenes.scene(n).area_light is not None]
                raise ValueError(f"pyrender spec: 'scene' {self.scene_name!r} has no area light "
                                 f"for technique {self.technique!r}; expected one of {with_light}")
            self.light_shape = _choice(spec, "light_shape", LIGHT_SHAPES, "rectangle")
            size = spec.get("light_size", self.desc.area_light.size)
            if (isinstance(size, bool) or not isinstance(size, numbers.Real) or not math.isfinite(size)
                    or not 0 < size <= 2.0):
                raise ValueError(f"pyrender spec: 'light_size' must be a number in (0, 2] (scene units: "
                                 f"side of the rectangle or diameter of the disk; the light must stay "
                                 f"between the slab's shadow and the view), got {size!r}")
            self.light_size = float(size)
        else:
            for key in ("light_shape", "light_size"):
                if key in spec:
                    raise ValueError(f"pyrender spec: {key!r} applies to the soft_shadow techniques, "
                                     f"not to technique {self.technique!r}")
        self.dim = 2 * (self.antialias + self.soft_shadow)
        self.flags = (pyrender.RenderFlags.SHADOWS_SPOT if self.desc.area_light is not None
                      else pyrender.RenderFlags.NONE)
        self._scene, self._cam_node, self._camera, self._spot_node = scenes.build(
            self.desc, self.width, self.height)
        self._cx, self._cy = 0.5 * self.width, 0.5 * self.height
        self._light_pose = np.eye(4)
        if self.desc.area_light is not None:
            self._light_pose[:3, 3] = self.desc.area_light.center
        self._token = next(_TOKENS)

    # frames ---------------------------------------------------------------------------------
    def _placements(self, u: np.ndarray) -> np.ndarray:
        """Per frame (rows of u, shape (n, dim)): principal point (cx, cy) in pixels and light
        position (x, y) in scene units, shape (n, 4), mapped for all frames at once."""
        out = np.empty((u.shape[0], 4))
        out[:, 0:2] = (self._cx, self._cy)
        out[:, 2:4] = self._light_pose[:2, 3]
        k = 0
        if self.antialias:
            out[:, 0:2] += frame_offsets(u[:, 0:2], self.pixel_filter)
            k = 2
        if self.soft_shadow:
            out[:, 2:4] += light_points(u[:, k:k + 2], self.light_shape, self.light_size)
        return out

    def _frame_bytes(self, r: pyrender.OffscreenRenderer, place: np.ndarray) -> np.ndarray:
        """One frame (height, width, 3) at one row of ``_placements``: pyrender's display-encoded
        bytes; ``_GL_LOCK`` held."""
        self._camera.cx, self._camera.cy = place[0], place[1]
        if self._spot_node is not None:
            pose = self._light_pose.copy()
            pose[:2, 3] = place[2:4]
            self._scene.set_pose(self._spot_node, pose)
        color, _depth = r.render(self._scene, flags=self.flags)
        return color

    def _current(self) -> pyrender.OffscreenRenderer:
        """The shared renderer with this scene uploaded; ``_GL_LOCK`` held.  After another
        scene used the context, one frame re-uploads this scene's meshes and shadow map."""
        key = (self.width, self.height)
        r = _offscreen(*key)
        if _LAST_SCENE.get(key) != self._token:
            self._frame_bytes(r, self._placements(np.full((1, self.dim), 0.5))[0])
            _LAST_SCENE[key] = self._token
        return r

    def frame(self, u: Any) -> np.ndarray:
        """One frame for the canonical point u (``dim`` numbers in [0, 1]: pixel offset, then
        light point), as float64 (height, width, 3) in [0, 1]: what ``render`` averages."""
        v = np.asarray(u, dtype=np.float64)
        if v.shape != (self.dim,) or not np.all((v >= 0) & (v <= 1)):
            raise ValueError(f"'u' must be {self.dim} numbers in [0, 1] for technique {self.technique!r}, "
                             f"got {u!r}")
        place = self._placements(v[None, :])[0]
        with _GL_LOCK:
            return self._frame_bytes(self._current(), place) / 255.0

    # the protocol -----------------------------------------------------------------------------
    def render(self, spp: int, seed: int) -> Render:
        """Average of ``spp`` frames drawn with the points of (seed, case 0, replica 0).
        ``seconds``: generating the points plus drawing and averaging the frames (not the
        wait for another thread's frames, nor re-uploading this scene after another scene used
        the same context)."""
        n = integer_in(spp, "spp", 1, MAX_SPP)
        s = integer_in(seed, "seed", 0, MAX_SEED)
        t0 = time.perf_counter()
        places = self._placements(rest.points(n, self.dim, self.points, seed=s, case_id=0, replica=0))
        acc = np.zeros((self.height, self.width, 3), dtype=np.float64)
        elapsed = time.perf_counter() - t0
        with _GL_LOCK:
            r = self._current()
            t1 = time.perf_counter()
            for place in places:
                acc += self._frame_bytes(r, place)   # float64 sum: exact for bytes; NaN stays NaN
            acc /= 255.0 * n
            elapsed += time.perf_counter() - t1
        return Render(acc, n, elapsed)

    def exact(self) -> None:
        """None: a rasterizer's filtered or area-lit image has no closed form; references are
        this estimator at a high frame count, rendered and cached by the suite runner."""
        return None

    def reference(self) -> "PyrenderRenderer":
        """The renderer of this configuration's reference: the same estimand with Owen-scrambled
        Sobol' points, the most accurate of the three.  The runner renders the reference as
        independent parts (independent scrambles: i.i.d. unbiased estimates), so its standard
        error comes from their spread."""
        return PyrenderRenderer({**self._spec, "points": "sobol"})

    def fingerprint(self) -> dict[str, Any]:
        """Everything that fixes the images (JSON-able): the settings, the ``environment``
        (library versions, the core's build, the GL strings: part of the store key, not of the
        seeds), and ``estimand_digest``: a hash of all of it but the point set, which names the
        expected image a reference estimates."""
        environment = {"pyrender": pyrender.__version__, "PyOpenGL": OpenGL.__version__,
                       "trimesh": trimesh.__version__, "gl": _gl_strings(self.width, self.height),
                       "core": rest.core_fingerprint()}
        fp: dict[str, Any] = {
            "adapter": "pyrender", "scene": self.scene_name, "scene_digest": scenes.digest(self.desc),
            "width": self.width, "height": self.height, "technique": self.technique, "points": self.points,
            "pixel_filter": self.pixel_filter, "light_shape": self.light_shape, "light_size": self.light_size,
            "image": "mean of 8-bit frames / 255 (pyrender gamma 1/2.2, clamped)",
            "shadow_map": SHADOW_TEX_SZ if self.desc.area_light is not None else None,
            "points_source": "reference_estimators.points(spp, dim, points, seed=seed, case_id=0, replica=0)",
            ENVIRONMENT: environment,
        }
        # what fixes the expected image: everything but the point set and the core that draws it
        # (random, stratified and Sobol' estimate the same image, so they can share one reference)
        estimand = {k: v for k, v in fp.items() if k not in ("points", "points_source", ENVIRONMENT)}
        estimand["renderer"] = {k: v for k, v in environment.items() if k != "core"}
        fp["estimand_digest"] = hashlib.sha256(json.dumps(estimand, sort_keys=True).encode()).hexdigest()[:16]
        return fp


def make_renderer(spec: dict[str, Any]) -> PyrenderRenderer:
    """A renderer for a suite's ``[[render]] adapter = "pyrender"`` table.

    Keys: ``scene`` (required: "edges" or "shadow"), ``technique`` (required: "antialias",
    "soft_shadow" or "antialias+soft_shadow"; the soft ones need the "shadow" scene),
    ``points`` ("random" (default), "stratified", "sobol"), ``width`` and ``height`` (pixels,
    default 32), ``pixel_filter`` ("box" (default) or "tent"; antialias only), ``light_shape``
    ("rectangle" (default) or "disk") and ``light_size`` (side or diameter in scene units,
    (0, 2], default 1; soft shadows only).  Anything else raises ValueError naming the key.
    """
    return PyrenderRenderer(spec)
