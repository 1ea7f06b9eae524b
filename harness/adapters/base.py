"""The adapter protocol: a renderer renders a scene at a budget and seed.

    r = renderer("mitsuba", {"scene": "furnace", "integrator": "path", "variant": "scalar_rgb"})
    out = r.render(spp=16, seed=3)       # Render: image (height, width, channels) float64, seconds
    r.exact()                            # the exact image where the scene has one, else None
    r.fingerprint()                      # JSON-able dict of everything that fixes the images
    r.reference()                        # the renderer of the reference when exact() is None

Adapters register a factory under a name; ``renderer`` imports the adapter's module on first
use.  A factory validates its spec and raises ``ValueError`` naming the offending key.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

import numpy as np

__all__ = ["Render", "Renderer", "ImageFaults", "image_faults", "renderer", "ADAPTERS"]

# adapter name -> module that defines `make_renderer(spec: dict) -> Renderer`
ADAPTERS = {"mitsuba": "harness.adapters.mitsuba.render", "pyrender": "harness.adapters.pyrender.render"}


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


def renderer(adapter: str, spec: dict[str, Any]) -> Renderer:
    """The renderer an adapter builds from ``spec`` (the keys of a suite's [[render]] table)."""
    if adapter not in ADAPTERS:
        raise ValueError(f"unknown adapter {adapter!r}; expected one of {sorted(ADAPTERS)}")
    make: Callable[[dict[str, Any]], Renderer] = importlib.import_module(ADAPTERS[adapter]).make_renderer
    return make(dict(spec))
