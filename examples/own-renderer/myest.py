"""A team's own estimators of the sky integral the renderer computes per pixel:
(1/pi) * integral over the hemisphere of (1 + cos theta) cos theta dw = 5/3.

``nee`` samples cosine-weighted directions (mysampler) and returns L(w) = 1 + cos theta per
sample; ``uniform`` samples the hemisphere uniformly (pdf 1 / (2 pi)); ``skewed`` uses the
wrong twin sampler with the right pdf: biased.  Each maps uniforms (N, 2) to (N,) values.
"""
from __future__ import annotations

import numpy as np
from mysampler import CosineHemisphere, SkewedCosine

EXACT = 5 / 3


def nee(u: np.ndarray) -> np.ndarray:
    return 1 + CosineHemisphere().sample(u)[:, 2]


def uniform(u: np.ndarray) -> np.ndarray:
    z = u[:, 0]                                   # uniform on the hemisphere: cos theta ~ U(0, 1)
    return (1 + z) * z / np.pi * 2 * np.pi        # f / pdf with f = (1 + z) z / pi, pdf = 1 / (2 pi)


def skewed(u: np.ndarray) -> np.ndarray:
    return 1 + SkewedCosine().sample(u)[:, 2]
