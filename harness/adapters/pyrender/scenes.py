"""Built-in scenes of the pyrender adapter, made from trimesh primitives in code (no files).

A scene is a plain description (``SceneDesc``): meshes with colours and poses, a pinhole
camera, fixed lights and at most one area light.  ``build`` turns it into a ``pyrender.Scene``
for one renderer; ``digest`` hashes every number that reaches the image (vertices, faces,
colours, poses, camera, lights), so a change to a scene here changes the adapter's
fingerprint and with it any cached reference.

Scenes (camera and lights fixed here; sizes scale with the image, the view does not):

* ``edges``: a box turned 30 degrees (diagonal edges), a sphere (curved silhouette) and a bar
  0.04 units wide (about a third of a pixel at 32x32, so single frames break it up) against a
  dark background, lit by a directional light: antialiasing at edges.
* ``shadow``: a ground plane, a square slab floating 1.2 above it and a square area light 3
  above the ground (side ``light_size``, default 1): soft shadows with an umbra (about 0.7
  units wide) and a penumbra (about 0.7 units, 6 pixels at 32x32) on the ground.

Units: scene units for lengths, radians for angles, pyrender's intensities (a spot light's
irradiance falls as intensity / d^2).  Materials are diffuse (metallic 0, roughness 1).
"""
from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass, field

import numpy as np
import trimesh

__all__ = ["AreaLight", "Camera", "MeshDesc", "SceneDesc", "SCENES", "scene", "build", "digest"]


@dataclass(frozen=True)
class MeshDesc:
    """A trimesh primitive with a diffuse colour (linear RGB in [0, 1]) and a 4x4 pose."""

    name: str
    mesh: trimesh.Trimesh
    color: tuple[float, float, float]
    pose: np.ndarray


@dataclass(frozen=True)
class Camera:
    """A pinhole camera at ``pose`` (OpenGL convention: looks along its local -z, y up) with
    vertical field of view ``yfov`` (radians); square pixels, principal point at the centre."""

    pose: np.ndarray
    yfov: float
    znear: float = 0.05
    zfar: float = 100.0

    def focal(self, height: int) -> float:
        """Focal length in pixels for an image ``height`` pixels high."""
        return 0.5 * height / math.tan(0.5 * self.yfov)


@dataclass(frozen=True)
class AreaLight:
    """A horizontal emitter (rectangle of side ``size`` or disk of diameter ``size``) centred
    at ``center``, facing down.  Each frame places one pyrender spot light of ``intensity``
    pointing straight down at a sampled point of it; the cone angles keep the whole visible
    ground inside the spot's full-intensity cone."""

    center: tuple[float, float, float]
    size: float
    intensity: float
    inner_cone: float
    outer_cone: float
    color: tuple[float, float, float] = (1.0, 1.0, 1.0)


@dataclass(frozen=True)
class SceneDesc:
    name: str
    meshes: tuple[MeshDesc, ...]
    camera: Camera
    background: tuple[float, float, float]
    ambient: tuple[float, float, float]
    directional: tuple[tuple[np.ndarray, float], ...] = ()   # (pose, intensity); light along pose's -z
    area_light: AreaLight | None = None
    doc: str = field(default="", compare=False)


def _translate(x: float, y: float, z: float) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def _rot_z(angle: float) -> np.ndarray:
    m = np.eye(4)
    c, s = math.cos(angle), math.sin(angle)
    m[:2, :2] = ((c, -s), (s, c))
    return m


def _look_at(eye: tuple[float, float, float], target: tuple[float, float, float],
             up: tuple[float, float, float] = (0.0, 0.0, 1.0)) -> np.ndarray:
    """Pose of a camera at ``eye`` looking at ``target`` (its -z towards the target)."""
    e, t, u = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    back = e - t
    back /= np.linalg.norm(back)
    right = np.cross(u, back)
    right /= np.linalg.norm(right)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = right, np.cross(back, right), back, e
    return pose


def _edges() -> SceneDesc:
    meshes = (
        MeshDesc("box", trimesh.creation.box((1.0, 0.7, 0.5)), (0.9, 0.9, 0.85),
                 _translate(-0.75, 0.45, 0.0) @ _rot_z(math.radians(30))),
        MeshDesc("sphere", trimesh.creation.icosphere(subdivisions=3, radius=0.5), (0.95, 0.55, 0.15),
                 _translate(0.75, 0.55, 0.0)),
        MeshDesc("bar", trimesh.creation.box((2.6, 0.04, 0.04)), (1.0, 1.0, 1.0),
                 _translate(0.0, -0.75, 0.0) @ _rot_z(math.radians(8))),
    )
    light = _look_at((1.0, 1.5, 4.0), (0.0, 0.0, 0.0))
    return SceneDesc("edges", meshes, Camera(_translate(0.0, 0.0, 5.0), math.radians(40)),
                     background=(0.05, 0.05, 0.1), ambient=(0.15, 0.15, 0.15), directional=((light, 3.0),),
                     doc="box, sphere and a sub-pixel bar against a dark background")


def _shadow() -> SceneDesc:
    meshes = (
        MeshDesc("ground", trimesh.creation.box((8.0, 8.0, 0.02)), (0.8, 0.8, 0.8),
                 _translate(0.0, 0.0, -0.01)),
        MeshDesc("slab", trimesh.creation.box((0.8, 0.8, 0.1)), (0.7, 0.2, 0.2), _translate(0.0, 0.0, 1.2)),
    )
    camera = Camera(_look_at((0.0, -3.2, 4.2), (0.0, 0.0, 0.0)), math.radians(40))
    light = AreaLight(center=(0.0, 0.0, 3.0), size=1.0, intensity=16.0,
                      inner_cone=math.radians(62), outer_cone=math.radians(68))
    return SceneDesc("shadow", meshes, camera, background=(0.0, 0.0, 0.0), ambient=(0.1, 0.1, 0.1),
                     area_light=light, doc="ground, floating slab and a square area light above it")


SCENES = {"edges": _edges, "shadow": _shadow}


def scene(name: str) -> SceneDesc:
    """The built-in scene ``name`` (one of ``SCENES``)."""
    return SCENES[name]()


def build(desc: SceneDesc, width: int, height: int):
    """A fresh ``pyrender.Scene`` for ``desc`` and its camera node, camera and spot-light node
    (None without an area light; it starts at the light's centre).  Fresh per renderer:
    pyrender ties a mesh's GPU buffers to the one GL context that first drew it."""
    os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")   # as the adapter does, if imported first here
    import pyrender

    sc = pyrender.Scene(bg_color=(*desc.background, 1.0), ambient_light=desc.ambient)
    for m in desc.meshes:
        material = pyrender.MetallicRoughnessMaterial(baseColorFactor=(*m.color, 1.0), metallicFactor=0.0,
                                                      roughnessFactor=1.0)
        mesh = pyrender.Mesh.from_trimesh(m.mesh, material=material, smooth=False)
        # pyrender 0.1.45 computes Mesh.bounds with np.infty, gone in numpy 2; shadow maps need
        # the scene's bounds, so give the mesh its (exact) bounds up front.
        mesh._bounds = np.array(m.mesh.bounds, dtype=np.float64)
        sc.add(mesh, name=m.name, pose=m.pose)
    f = desc.camera.focal(height)
    cam = pyrender.IntrinsicsCamera(fx=f, fy=f, cx=0.5 * width, cy=0.5 * height, znear=desc.camera.znear,
                                    zfar=desc.camera.zfar)
    cam_node = sc.add(cam, pose=desc.camera.pose)
    for pose, intensity in desc.directional:
        sc.add(pyrender.DirectionalLight(color=np.ones(3), intensity=intensity), pose=pose)
    spot_node = None
    if desc.area_light is not None:
        a = desc.area_light
        spot = pyrender.SpotLight(color=np.asarray(a.color), intensity=a.intensity,
                                  innerConeAngle=a.inner_cone, outerConeAngle=a.outer_cone)
        spot_node = sc.add(spot, pose=_translate(*a.center))
    return sc, cam_node, cam, spot_node


def digest(desc: SceneDesc) -> str:
    """SHA-256 (hex, 16 digits) of every number of the scene that reaches the image."""
    h = hashlib.sha256()

    def put(*arrays) -> None:
        for a in arrays:
            b = np.ascontiguousarray(np.asarray(a, dtype=np.float64))
            h.update(str(b.shape).encode())
            h.update(b.tobytes())

    h.update(desc.name.encode())
    for m in desc.meshes:
        h.update(m.name.encode())
        put(m.mesh.vertices, m.mesh.faces, m.color, m.pose)
    c = desc.camera
    put(c.pose, (c.yfov, c.znear, c.zfar), desc.background, desc.ambient)
    for pose, intensity in desc.directional:
        put(pose, (intensity,))
    if desc.area_light is not None:
        a = desc.area_light
        put(a.center, (a.size, a.intensity, a.inner_cone, a.outer_cone), a.color)
    return h.hexdigest()[:16]
