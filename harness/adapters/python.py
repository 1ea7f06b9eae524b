"""The python adapter: a team's render function, called in the harness's process.

    [[render]]
    adapter = "python"
    function = "myrenderer:render"    # module:attr or path/file.py:attr, next to the suite first
    params = { bounces = 3 }          # optional: passed on as keyword arguments
    exact = "ref.exr"                 # optional: an exact reference image (or reference_spp = N)
    scene = "cornell"                 # optional: what tables call the scene (default: the function)

``render(spp=, seed=, **params)`` returns an image (height, width[, channels]) in radiometric
units, or ``(image, seconds)`` with the renderer's own time; without one the call's wall
time is used.  An exception inside it, or a result that is not an image, is a
:class:`~harness.adapters.base.RenderError` naming the function and the call; nothing is
stored for that render.  The fingerprint holds the source hash of the function's module, so a
change of the code invalidates its stored renders.
"""
from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from harness.adapters.base import ENVIRONMENT, ExactImage, Render, RenderError, check_spec, image_array
from harness.usercode import USER_ERRORS, UserCodeError, load_attr, raised, source_fingerprint

__all__ = ["PythonRenderer", "make_renderer"]

_KEYS = {"function": str, "params": dict, "exact": str, "scene": str}


class PythonRenderer:
    """A renderer that is a Python function (see the module docstring)."""

    def __init__(self, spec: dict[str, Any], base: Path):
        check_spec(spec, _KEYS, "python")
        if "function" not in spec:
            raise ValueError("'function': missing key: module:attr of render(spp=, seed=, **params)")
        self.spec, self.base = dict(spec), base
        self.target = spec["function"]
        try:
            self.function = load_attr(self.target, base=base)
        except UserCodeError as e:
            raise ValueError(f"'function': {e}") from None
        if not callable(self.function):
            kind = type(self.function).__name__
            raise ValueError(f"'function': {self.target!r} is a {kind}, not a function")
        self.params = dict(spec.get("params", {}))
        self._exact = ExactImage(spec, base)

    def render(self, spp: int, seed: int) -> Render:
        call = f"{self.target}(spp={spp}, seed={seed}" + "".join(f", {k}={v!r}"
                                                                  for k, v in self.params.items())
        start = time.perf_counter()
        try:
            out = self.function(spp=spp, seed=seed, **self.params)
        except USER_ERRORS as e:
            raise RenderError(f"{call}) {raised(e)}") from e
        wall = time.perf_counter() - start
        image, seconds = (out if isinstance(out, tuple) and len(out) == 2 else (out, wall))
        try:
            a = image_array(image)
        except ValueError as e:
            raise RenderError(f"{call}) returned {e}; expected an image (height, width[, channels]) or "
                              "(image, seconds)") from None
        try:
            t = float(seconds)
        except (TypeError, ValueError):
            t = math.nan
        if not t >= 0:
            raise RenderError(f"{call}) returned a time of {seconds!r} s")
        return Render(a, spp, t)

    def exact(self) -> np.ndarray | None:
        return self._exact.image()

    def reference(self) -> PythonRenderer:
        return self

    def fingerprint(self) -> dict[str, Any]:
        """The function, its parameters and exact image; its source's digest is the environment
        (part of the store key, not of the seeds: an edited function is compared with the old one
        on the same seeds)."""
        return {"adapter": "python", "function": self.target, "params": self.params,
                "exact": self._exact.digest(), ENVIRONMENT: {"source": source_fingerprint(self.function)}}

    def describe(self) -> tuple[str, str]:
        params = ", ".join(f"{k}={v}" for k, v in self.params.items())
        return self.spec.get("scene") or self.target, self.target + (f"({params})" if params else "")


def make_renderer(spec: dict[str, Any], *, base: Path | None = None) -> PythonRenderer:
    """A renderer for a suite's ``[[render]] adapter = "python"`` table (see the module)."""
    return PythonRenderer(spec, (base or Path.cwd()).resolve())
