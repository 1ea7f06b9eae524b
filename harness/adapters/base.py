"""The adapter protocol: a renderer renders a scene at a budget and seed.

    r = renderer("mitsuba", {"scene": "furnace", "integrator": "path", "variant": "scalar_rgb"})
    out = r.render(spp=16, seed=3)       # Render: image (height, width, channels) float64, seconds
    r.exact()                            # the exact image where the scene has one, else None
    r.fingerprint()                      # JSON-able dict of everything that fixes the images
                                         # (its "environment" key: see ENVIRONMENT)
    r.reference()                        # the renderer of the reference when exact() is None
    r.describe()                         # optional: (scene, configuration) for tables
    r.notes()                            # optional: lines a reader of the table must know

An adapter is a factory ``make_renderer(spec: dict, *, base: Path | None = None) -> Renderer``:
``spec`` holds the [[render]] table's adapter keys (everything but the runner's: spp,
replicas, budgets, ...), ``base`` the suite file's folder (where relative paths are resolved;
a factory that takes no ``base`` is called without it).  It validates ``spec`` and raises
``ValueError`` whose message starts with the offending key in quotes (``"'scene': ..."``), so
the suite error names its line.  ``render`` raises :class:`RenderError` when a render fails.
The harness's own adapters are named in ``ADAPTERS`` and imported on first use; a package
registers more under the entry-point group ``harness.adapters`` (name = the ``adapter`` value,
object = the factory)::

    [project.entry-points."harness.adapters"]
    myrenderer = "myrenderer.harness:make_renderer"
"""
from __future__ import annotations

import importlib
import inspect
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any, Callable, Protocol

import numpy as np

from harness.usercode import USER_ERRORS, raised, real_array

__all__ = ["Render", "Renderer", "RenderError", "ImageFaults", "image_faults", "read_image", "renderer",
           "checked_render", "image_array", "adapter_names", "check_spec", "file_digest", "ExactImage",
           "ADAPTERS", "ENTRY_POINTS", "ENVIRONMENT"]

# adapter name -> module that defines `make_renderer(spec: dict[, base=]) -> Renderer`
ADAPTERS = {"mitsuba": "harness.adapters.mitsuba.render", "pyrender": "harness.adapters.pyrender.render",
            "command": "harness.adapters.command", "python": "harness.adapters.python"}
ENTRY_POINTS = "harness.adapters"   # the entry-point group of third-party adapters
# A fingerprint's key for what renders rather than what is rendered: library versions, compiled
# builds, GL driver strings, digests of a team's renderer sources, file locations.  It is part of
# a stored render's key (a new version re-renders) but not of the render seeds, which derive from
# the rest and the suite seed: a suite draws the same seeds on every machine and build (a core
# built for AVX2 or AVX-512 hashes differently), and a fixed renderer is compared with the old
# one on common random numbers.
ENVIRONMENT = "environment"


class RenderError(RuntimeError):
    """A render that failed (a command's non-zero exit, a timeout, no image, a user's function
    raising); the message names what was run and why it failed."""


@dataclass
class Render:
    """One estimate of an image: ``image`` (height, width, channels) in the renderer's
    radiometric units (float64), the budget ``spp`` it used and its wall time in seconds."""

    image: np.ndarray
    spp: int
    seconds: float


class Renderer(Protocol):
    def render(self, spp: int, seed: int) -> Render: ...

    def exact(self) -> np.ndarray | None: ...

    def fingerprint(self) -> dict[str, Any]: ...

    def reference(self) -> "Renderer":
        """The renderer whose high-budget renders serve as this one's reference when
        ``exact()`` is None (e.g. path tracing of the same scene)."""
        ...


@dataclass
class ImageFaults:
    """Pixels that must not be averaged in: counts and the first positions, (row, col) in one
    image or (replica, row, col) over a case's renders (``position`` says which)."""

    nan: int = 0
    inf: int = 0
    negative: int = 0
    examples: dict[str, list[tuple[int, ...]]] = field(default_factory=dict)
    position: str = "row, col"

    @property
    def total(self) -> int:
        return self.nan + self.inf + self.negative

    def to_dict(self) -> dict[str, Any]:
        return {"nan": self.nan, "inf": self.inf, "negative": self.negative,
                "examples": {k: [list(p) for p in v] for k, v in self.examples.items()}}

    def __str__(self) -> str:
        parts = [f"{getattr(self, k)} {k} pixel(s) e.g. at ({self.position}) {self.examples[k][:3]}"
                 for k in ("nan", "inf", "negative") if getattr(self, k)]
        return "; ".join(parts) if parts else "no invalid pixels"


def image_faults(image: np.ndarray, *, max_examples: int = 8) -> ImageFaults:
    """Counts NaN, infinite and negative pixels (any channel) with their first positions."""
    a = np.asarray(image)
    if a.ndim == 2:
        a = a[:, :, None]
    faults = ImageFaults()
    for kind, mask in (("nan", np.isnan(a).any(axis=2)), ("inf", np.isinf(a).any(axis=2)),
                       ("negative", (a < 0).any(axis=2))):
        count = int(mask.sum())
        setattr(faults, kind, count)
        if count:
            rows, cols = np.nonzero(mask)
            faults.examples[kind] = [(int(r), int(c))
                                     for r, c in zip(rows[:max_examples], cols[:max_examples])]
    return faults


def adapter_names() -> list[str]:
    """The harness's adapters, then those registered under the ``harness.adapters`` group."""
    extra = sorted(ep.name for ep in entry_points(group=ENTRY_POINTS) if ep.name not in ADAPTERS)
    return list(ADAPTERS) + extra


def renderer(adapter: str, spec: dict[str, Any], *, base: Path | None = None) -> Renderer:
    """The renderer an adapter builds from ``spec`` (the keys of a suite's [[render]] table);
    ``base``: the suite file's folder, for adapters that resolve paths."""
    if adapter in ADAPTERS:
        make: Callable[..., Renderer] = importlib.import_module(ADAPTERS[adapter]).make_renderer
    else:
        found = [ep for ep in entry_points(group=ENTRY_POINTS) if ep.name == adapter]
        if not found:
            raise ValueError(f"unknown adapter {adapter!r}; expected one of: {', '.join(adapter_names())} "
                             f"(third-party adapters register under the entry-point group {ENTRY_POINTS!r})")
        try:
            make = found[0].load()
        except USER_ERRORS as e:
            raise ValueError(f"adapter {adapter!r}: loading its entry point {found[0].value!r} "
                             f"{raised(e)}") from None
        if not callable(make):
            raise ValueError(f"adapter {adapter!r}: entry point {found[0].value!r} is not a factory "
                             "make_renderer(spec, *, base=None)")
    try:
        takes_base = "base" in inspect.signature(make).parameters
    except (TypeError, ValueError):
        takes_base = False
    try:
        return make(dict(spec), base=base) if takes_base else make(dict(spec))
    except ValueError:
        raise
    except USER_ERRORS as e:   # a registered factory's own failure (a KeyError on a missing key) names it
        if adapter in ADAPTERS:
            raise
        raise ValueError(f"adapter {adapter!r}: its factory {found[0].value!r} {raised(e)}") from e


def image_array(image: Any) -> np.ndarray:
    """A renderer's image as float64 (height, width, channels), a (height, width) one with one
    channel; otherwise a ValueError saying what it is (:func:`harness.usercode.real_array`'s
    words, or "an image of shape (2,)"), for the caller to say what was expected."""
    a = real_array(image)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or 0 in a.shape:
        raise ValueError(f"an image of shape {a.shape}")
    return a


def checked_render(r: Renderer, adapter: str, spp: int, seed: int) -> Render:
    """``r.render(spp, seed)``, its image checked before anything stores it: a Render (or an
    object with its fields) whose image :func:`image_array` takes (a Dr.Jit tensor, a list and
    a (height, width) array too), of the exact image's shape where ``r`` has one (a render of
    another size, stored, had failed every later run of the suite).  A registered adapter's
    exception becomes a RenderError naming the call; the harness's own adapters raise
    RenderError for their renderers' failures, and anything else from them is a defect of the
    harness, left as it is."""
    what = f"adapter {adapter!r}: render(spp={spp}, seed={seed})"
    try:
        out = r.render(spp, seed)
    except RenderError:
        raise
    except USER_ERRORS as e:
        if adapter in ADAPTERS:
            raise
        raise RenderError(f"{what} {raised(e)}") from e
    if not all(hasattr(out, f) for f in ("image", "spp", "seconds")):
        raise RenderError(f"{what} returned a {type(out).__name__}; expected a Render (image, spp, seconds)")
    try:
        image = image_array(out.image)
    except ValueError as e:
        raise RenderError(f"{what} returned {e}; expected an image (height, width[, channels])") from None
    exact = r.exact()
    if exact is not None and image.shape != exact.shape:
        raise RenderError(f"{what} returned an image of shape {image.shape}; the exact image's is "
                          f"{exact.shape}")
    return Render(image, out.spp, out.seconds)


def check_spec(spec: dict[str, Any], keys: dict[str, Any], adapter: str) -> None:
    """Every key of ``spec`` is one of ``keys`` (name -> type or tuple of types; a bool is
    never a number), with a value of its type; ValueError naming the key otherwise."""
    for key, value in spec.items():
        want = keys.get(key)
        if want is None:
            raise ValueError(f"'{key}': unknown key for the {adapter} adapter; expected one of: "
                             f"{', '.join(keys)}")
        if isinstance(value, bool) or not isinstance(value, want):
            raise ValueError(f"'{key}': expected {getattr(want, '__name__', 'a number')}, got {value!r}")


def file_digest(path: Path) -> str:
    """SHA-256 (24 hex digits) of a file's bytes, for fingerprints: read in blocks, and once per
    process while the file's device, inode, size and modification and change times stay the
    same (a renderer's fingerprint is taken several times a run, and a scene's meshes can be
    gigabytes; the change time moves with any write, whatever a tool does to the others).
    A digest is kept only for a file last changed more than _RACY_NS before it was read: two
    writes within one tick of the file system's clock leave the same times (2 s on FAT, a
    jiffy of a few ms where Linux keeps coarse timestamps), so the times of a file changed just
    now do not yet tell its next write apart (git treats its "racily clean" entries so).  The
    file system's clock is taken to agree with this machine's within _RACY_NS (a local one
    does; a network server's running more than 3 s behind would bring the race back)."""
    st = Path(path).stat()
    key = (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)
    digest = _DIGESTS.get(key)
    if digest is None:
        import hashlib
        import time

        read_at = time.time_ns()
        with open(path, "rb") as f:
            digest = hashlib.file_digest(f, "sha256").hexdigest()[:24]
        if read_at - max(st.st_mtime_ns, st.st_ctime_ns) > _RACY_NS:
            _DIGESTS[key] = digest
    return digest


_DIGESTS: dict[tuple[int, ...], str] = {}   # file_digest's, by the file's stat identity
_RACY_NS = 3_000_000_000   # file_digest keeps no digest of a file changed this recently (ns)


class ExactImage:
    """An adapter's ``exact`` key: an image file resolved against the suite's folder, checked
    to exist when the renderer is built, read once (float64) when first asked for."""

    def __init__(self, spec: dict[str, Any], base: Path):
        self.path = (base / spec["exact"]).resolve() if "exact" in spec else None
        if self.path is not None and not self.path.is_file():
            raise ValueError(f"'exact': no image file {self.path}")
        self._image: np.ndarray | None = None

    def image(self) -> np.ndarray | None:
        """The exact image, or None where the spec gives none."""
        if self.path is not None and self._image is None:
            self._image = read_image(self.path).astype(np.float64)
        return self._image

    def digest(self) -> str | None:
        """The image file's digest for the renderer's fingerprint (None without one)."""
        return file_digest(self.path) if self.path is not None else None


def read_image(path: Path) -> np.ndarray:
    """An image file (EXR, PFM, HDR, or anything OpenImageIO reads) as float32 (height, width,
    channels); OSError naming the file when it is missing, truncated or not an image."""
    import OpenImageIO as oiio  # only runs that read images need it

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise OSError(f"cannot read image {path}: {oiio.geterror() or 'not an image'}")
    try:
        pixels = inp.read_image("float")
    finally:
        inp.close()
    if pixels is None:
        raise OSError(f"cannot read image {path}: {oiio.geterror() or 'truncated or damaged'}")
    a = np.asarray(pixels, dtype=np.float32)
    return a[:, :, None] if a.ndim == 2 else a
