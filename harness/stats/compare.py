"""Two renderers compared without a converged reference: do their replica renders estimate
the same image?

H0: every pixel of A's renders has the expected value of B's.  Three two-sample tests, each
at alpha/3 and Bonferroni-combined, so the false-alarm rate is at most alpha under any
dependence between pixels, channels and tiles:

* pixels: Welch t per pixel and channel (Welch-Satterthwaite degrees of freedom), the
  smallest p times the number of pixel-channels tested: a difference confined to a few pixels;
* tiles: the same on the means of ``tile`` x ``tile`` pixel blocks, one per replica: a
  difference spread over a region, at about 1/tile the pixel test's detectable size;
* image mean: Welch t of the replicas' image averages: a small difference everywhere.

A pixel (or tile) is tested only where both sets look normal enough for the t law at its
Bonferroni level (harness.stats.images.normal_enough: an Edgeworth bound on the sample
skewness); the rest (a light tracer's sparse pixels, fireflies) are counted as ``untestable``
and left to the coarser tests.  Pixels constant in both sets are compared up to float32
rounding.  Pixels NaN, infinite or negative in any replica are excluded and reported.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import stats as sps

from harness.stats.images import (
    ROUNDING,
    PixelVerdict,
    excluded_pixels,
    normal_enough,
    relative_squared_error,
    t_summary,
)
from harness.stats.results import ConfidenceInterval, Failure, check_confidence_level
from harness.stats.validate import integer_in, level

__all__ = ["ImageComparison", "compare_images"]


@dataclass(frozen=True)
class ImageComparison(PixelVerdict):
    """Outcome of :func:`compare_images`, a member of the result family.

    ``verdict``: "invalid" when pixels had to be excluded (``failures``), "differ" when
    ``pvalue`` <= ``alpha``, else "consistent".  ``difference`` is the image-average of
    mean(A) - mean(B) with its standard error; ``relmse_ab`` / ``relmse_ba`` the relMSE of
    each set's mean against the other's.  ``t_map`` (h, w): the largest |t| over channels of
    the pixel test, NaN where not tested.  ``n`` = replicas of A + replicas of B.
    """

    pvalue: float
    pvalue_pixels: float
    pvalue_tiles: float
    pvalue_mean: float
    difference: float
    difference_se: float
    worst_pixel: tuple[int, int, int]
    worst_t: float
    tested: int                 # pixel-channels the pixel test trusted
    untestable: int
    tiles_tested: int
    tiles_untestable: int
    tile: int
    excluded: int
    replicas: tuple[int, int]
    relmse_ab: float
    relmse_ba: float
    t_map: np.ndarray
    alpha: float = 0.01
    failures: list[Failure] = field(default_factory=list)
    reject = "differ"

    @property
    def n(self) -> int:
        return sum(self.replicas)

    def confidence_interval(self, confidence_level: float = 0.95) -> ConfidenceInterval:
        """Normal interval of the image-average difference mean(A) - mean(B)."""
        check_confidence_level(confidence_level)
        half = float(sps.norm.ppf(0.5 + confidence_level / 2)) * self.difference_se
        return ConfidenceInterval(self.difference - half, self.difference + half)

    def __str__(self) -> str:
        lo, hi = self.confidence_interval(1 - self.alpha)
        s = (f"{self.verdict}: p = {self.pvalue:.3g} (pixels {self.pvalue_pixels:.3g}, "
             f"{self.tile}x{self.tile} tiles {self.pvalue_tiles:.3g}, image mean {self.pvalue_mean:.3g}), "
             f"alpha = {self.alpha}, "
             f"replicas {self.replicas[0]} and {self.replicas[1]}; {self.tested} pixel-channels tested "
             f"({self.untestable} too skewed), {self.tiles_tested} tiles "
             f"({self.tiles_untestable} too skewed); "
             f"worst pixel (row, col, channel) {self.worst_pixel} t = {self.worst_t:+.2f}; image-mean "
             f"difference A - B {self.difference:+.3g} ± {self.difference_se:.2g}, "
             f"{100 * (1 - self.alpha):g} % CI [{lo:+.3g}, {hi:+.3g}]; relMSE of A against mean B "
             f"{self.relmse_ab:.3g}, of B against mean A {self.relmse_ba:.3g}")
        return s + "".join(f"; {f}" for f in self.failures)


def _welch(a: np.ndarray, b: np.ndarray, family: int, gate_alpha: float) -> tuple[np.ndarray, np.ndarray,
                                                                                   np.ndarray]:
    """Welch t, two-sided p and testability of a (Ra, ...) against b (Rb, ...) per element."""
    ra, rb = a.shape[0], b.shape[0]
    ma, mb = a.mean(axis=0), b.mean(axis=0)
    va, vb = a.var(axis=0, ddof=1) / ra, b.var(axis=0, ddof=1) / rb
    floor = (ROUNDING * np.maximum(np.abs(ma), np.abs(mb))) ** 2
    se2 = va + vb + floor
    with np.errstate(divide="ignore", invalid="ignore"):
        df = np.where(va + vb > 0, (va + vb) ** 2 / (va**2 / (ra - 1) + vb**2 / (rb - 1)), 1.0)
        t = np.where(se2 > 0, (ma - mb) / np.sqrt(se2), 0.0)
    normal_a, const_a = normal_enough(a, family, gate_alpha)
    normal_b, const_b = normal_enough(b, family, gate_alpha)
    both_constant = const_a & const_b
    # a set that is constant has no skewness to fear; the other must pass the gate
    testable = np.where(both_constant, True, (normal_a | const_a) & (normal_b | const_b))
    p = np.where(both_constant, np.where(np.abs(ma - mb) <= np.sqrt(floor), 1.0, 0.0),
                 2 * sps.t.sf(np.abs(t), np.maximum(df, 1.0)))
    return t, np.where(testable, p, 1.0), testable


def compare_images(a: np.ndarray, b: np.ndarray, *, alpha: float = 0.01, tile: int = 8,
                   gate_alpha: float = 0.01) -> ImageComparison:
    """Tests whether replica renders ``a`` (Ra, h, w, c) and ``b`` (Rb, h, w, c), each set
    independent renders of one configuration, estimate the same image; see the module
    docstring.  Needs at least 4 replicas a set; ``alpha`` is the verdict's level."""
    level(alpha, "alpha")
    level(gate_alpha, "gate_alpha")
    integer_in(tile, "tile", 1)
    x, y = (np.asarray(v, dtype=np.float64) for v in (a, b))
    x, y = (v[..., None] if v.ndim == 3 else v for v in (x, y))
    if x.ndim != 4 or y.ndim != 4 or x.shape[1:] != y.shape[1:]:
        raise ValueError(f"expected two sets of replica images (R, height, width, channels) of one size, got "
                         f"{x.shape} and {y.shape}")
    ra, rb = x.shape[0], y.shape[0]
    if min(ra, rb) < 4:
        raise ValueError(f"comparing two renderers needs at least 4 replicas of each, got {ra} and {rb}")
    valid = ((np.isfinite(x) & (x >= 0)).all(axis=(0, 3)) & (np.isfinite(y) & (y >= 0)).all(axis=(0, 3)))
    xv, yv = x[:, valid], y[:, valid]
    family = max(int(xv[0].size), 1)
    t, p, testable = _welch(xv, yv, 3 * family, gate_alpha)
    tested = int(testable.sum())
    p_pix = min(1.0, float(p.min()) * tested) if tested else 1.0

    # tiles: per replica, the mean of each tile's valid pixels and channels
    h, w = valid.shape
    tiles_a, tiles_b = [], []
    for i in range(0, h, tile):
        for j in range(0, w, tile):
            block = valid[i:i + tile, j:j + tile]
            if block.any():
                tiles_a.append(x[:, i:i + tile, j:j + tile][:, block].mean(axis=(1, 2)))
                tiles_b.append(y[:, i:i + tile, j:j + tile][:, block].mean(axis=(1, 2)))
    if tiles_a:
        ta, tb = np.stack(tiles_a, axis=1), np.stack(tiles_b, axis=1)
        _, pt, tile_ok = _welch(ta, tb, 3 * ta.shape[1], gate_alpha)
        tiles_tested = int(tile_ok.sum())
        p_tiles = min(1.0, float(pt.min()) * tiles_tested) if tiles_tested else 1.0
    else:
        tiles_tested, tile_ok, p_tiles = 0, np.zeros(0, bool), 1.0

    mean_a, mean_b = xv.reshape(ra, -1).mean(axis=1), yv.reshape(rb, -1).mean(axis=1)
    _, pm, _ = _welch(mean_a[:, None], mean_b[:, None], 1, 1.0)   # the image mean: always tested
    diff = float(mean_a.mean() - mean_b.mean()) if xv.size else 0.0
    se = math.sqrt(float(np.var(mean_a, ddof=1)) / ra + float(np.var(mean_b, ddof=1)) / rb)

    t_map, worst, worst_t = t_summary(t, testable, valid)
    ma, mb = xv.mean(axis=0), yv.mean(axis=0)
    rel_ab = float(relative_squared_error(ma, mb).mean()) if xv.size else math.nan
    rel_ba = float(relative_squared_error(mb, ma).mean()) if xv.size else math.nan
    excluded = int((~valid).sum())
    failures = excluded_pixels(valid, "pixels NaN, infinite or negative in a replica of either set, left out "
                                      "of every test")
    pvalue = min(1.0, 3 * min(p_pix, p_tiles, float(pm[0])))
    return ImageComparison(pvalue, p_pix, p_tiles, float(pm[0]), diff, se, worst, worst_t, tested,
                           int(testable.size - tested), tiles_tested, int(tile_ok.size - tiles_tested),
                           tile, excluded, (ra, rb), rel_ab, rel_ba, t_map, alpha, failures)
