"""pbrt-style sampling triples over numpy arrays, one set per analytic sampler of the
registry: ``sample_<name>(u, **params)``, ``<name>_pdf(x, **params)``, ``invert_<name>(x,
**params)`` -- the same names as the C++ functions in src/sampling.h, so that a registry (or a
test) can find a complete set by name.  Parameters default to the registry's values.
Tabulated distributions are classes instead: ``sampler("piecewise_constant_1d", table=...)``.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from . import _core
from .api import sampler

__all__: list[str] = []


def _triple(name: str, defaults: dict[str, float], udim: int, dim: int) -> dict[str, Callable[..., Any]]:
    def make(**params: float):
        return sampler(name, **{**defaults, **params})

    def sample(u: Any, **params: float) -> np.ndarray:
        return make(**params).sample(u)[0]

    def pdf(x: Any, **params: float) -> np.ndarray:
        return make(**params).pdf(x)

    def invert(x: Any, **params: float) -> np.ndarray:
        return make(**params).invert(x)

    shape = lambda d: "(N,)" if d == 1 else f"(N, {d})"  # noqa: E731
    ps = ", ".join(f"{k}={v:g}" for k, v in defaults.items()) or "no parameters"
    docs = {
        f"sample_{name}": (sample, f"Points {shape(dim)} from canonical uniforms u {shape(udim)} ({ps})."),
        f"{name}_pdf": (pdf, f"Density of the {name} sampler at points {shape(dim)}; "
                             f"0 outside its support ({ps})."),
        f"invert_{name}": (invert, f"Canonical uniforms {shape(udim)} that map to points; "
                                   f"NaN outside the support ({ps})."),
    }
    out = {}
    for fname, (fn, doc) in docs.items():
        fn.__name__ = fn.__qualname__ = fname
        fn.__doc__ = doc
        out[fname] = fn
    return out


for _info in _core.sampler_registry():
    if _info["needs_table"]:
        continue
    _s = sampler(_info["name"])
    _fns = _triple(_info["name"], dict(_info["params"]), _s.udim, _s.dim)
    globals().update(_fns)
    __all__.extend(_fns)
del _info, _s, _fns
