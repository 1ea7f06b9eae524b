"""Render images -> what a person compares: tone-mapped PNGs and a false-colour error map.

Tone mapping is the plainest one: linear radiance clamped to [0, 1] and encoded with the
sRGB transfer curve (no exposure change, no operator), so a value above 1 is white and the
reference and estimate are mapped identically.  The error map is the per-pixel relative
squared error (est - ref)^2 / (ref^2 + 0.01), averaged over the colour channels (the 0.01
keeps black reference pixels from dividing by zero, as in the relMSE of the rendering
literature; the harness's one definition, ``harness.stats.images.relative_squared_error``),
shown on a log10 colour scale spanning four decades below the decade that holds the map's
99.5th percentile.  Non-finite estimate pixels are drawn magenta and counted.
"""
from __future__ import annotations

import base64
import io
import math
from dataclasses import dataclass

import numpy as np
from PIL import Image

from harness.stats.images import relative_squared_error

__all__ = ["ErrorMap", "tonemap", "relmse_map", "error_map", "t_map_rgb", "colorbar_png", "png_bytes",
           "data_uri", "DECADES"]

DECADES = 4        # the colour scale spans this many powers of ten
_MAGENTA = np.array([255, 0, 255], dtype=np.uint8)


def _rgb(image: np.ndarray) -> np.ndarray:
    """(h, w, c) float -> (h, w, 3): grey replicated, alpha and extra channels dropped."""
    a = np.asarray(image, dtype=np.float32)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.shape[2] == 1:
        return np.repeat(a, 3, axis=2)
    return a[:, :, :3]


def tonemap(image: np.ndarray) -> np.ndarray:
    """Linear radiance (h, w, c) -> sRGB uint8 (h, w, 3), clamped to [0, 1] first; NaN -> magenta."""
    a = _rgb(image)
    bad = ~np.all(np.isfinite(a), axis=2)
    x = np.clip(np.nan_to_num(a, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    out = np.round(srgb * 255).astype(np.uint8)
    out[bad] = _MAGENTA
    return out


def relmse_map(reference: np.ndarray, estimate: np.ndarray) -> np.ndarray:
    """Per-pixel relative squared error, mean over RGB: (h, w) float64, NaN where not finite."""
    ref, est = _rgb(reference).astype(np.float64), _rgb(estimate).astype(np.float64)
    if ref.shape != est.shape:
        raise ValueError(f"reference and estimate must have the same shape, got {ref.shape} and {est.shape}")
    with np.errstate(invalid="ignore", over="ignore"):
        e = np.mean(relative_squared_error(est, ref), axis=2)
    return np.where(np.isfinite(e), e, np.nan)


@dataclass(frozen=True)
class ErrorMap:
    """A false-colour relMSE map and the numbers its caption states."""

    rgb: np.ndarray        # (h, w, 3) uint8
    vmin: float            # colour scale: log10 from vmin to vmax
    vmax: float
    mean: float            # mean over the finite pixels
    stderr: float          # standard error of that mean over pixels (pixels taken as independent)
    pixels: int            # finite pixels
    nonfinite: int         # pixels where the estimate is NaN or infinite


def lut(name: str = "inferno") -> np.ndarray:
    import matplotlib

    return (matplotlib.colormaps[name](np.linspace(0, 1, 256))[:, :3] * 255).round().astype(np.uint8)


def t_map_rgb(t_map: np.ndarray) -> tuple[np.ndarray, float]:
    """A bias test's |t| map (h, w) in false colour (inferno, linear from 0 to the larger of its
    maximum and 4, untested pixels black) and that top value."""
    t = np.nan_to_num(np.abs(np.asarray(t_map, dtype=np.float64)), nan=0.0)
    top = max(float(t.max()) if t.size else 0.0, 4.0)
    return lut()[np.round(np.clip(t / top, 0, 1) * 255).astype(np.int64)], top


def scale_top(maps: list[np.ndarray]) -> float:
    """The top of a shared colour scale for relMSE maps: the decade above the 99.5th
    percentile of all their finite pixels together (so maps of one scene compare by colour)."""
    vals = np.concatenate([m[np.isfinite(m)] for m in maps]) if maps else np.zeros(0)
    top = float(np.quantile(vals, 0.995)) if vals.size else 0.0
    return 10.0 ** math.ceil(math.log10(top)) if top > 0 else 1e-4


def error_map(reference: np.ndarray, estimate: np.ndarray, *, vmax: float | None = None) -> ErrorMap:
    """The relMSE map in false colour on a log10 scale (see the module docstring); ``vmax``:
    the top of a colour scale shared with other maps (default: this map's, ``scale_top``)."""
    e = relmse_map(reference, estimate)
    finite = np.isfinite(e)
    vals = e[finite]
    vmax = scale_top([e]) if vmax is None else vmax
    vmin = vmax / 10**DECADES
    t = (np.log10(np.clip(np.nan_to_num(e, nan=vmin), vmin, vmax)) - math.log10(vmin)) / DECADES
    rgb = lut()[np.round(t * 255).astype(np.int64)]
    rgb[~finite] = _MAGENTA
    n = int(vals.size)
    mean = float(vals.mean()) if n else math.nan
    se = float(vals.std(ddof=1) / math.sqrt(n)) if n > 1 else math.nan
    return ErrorMap(rgb, vmin, vmax, mean, se, n, int((~finite).sum()))


def colorbar_png(width: int = 256, height: int = 14) -> bytes:
    """The error map's colour scale, left (vmin) to right (vmax), as a PNG strip."""
    strip = np.repeat(lut()[np.linspace(0, 255, width).round().astype(np.int64)][None], height, axis=0)
    return png_bytes(strip)


def png_bytes(rgb: np.ndarray) -> bytes:
    """uint8 (h, w, 3) -> PNG file bytes."""
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb)).save(buf, format="PNG", optimize=False)
    return buf.getvalue()


def data_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")
