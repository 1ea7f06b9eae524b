"""Two renderers compared without a converged reference: do their replica renders estimate
the same image?

H0: every pixel of A's renders has the expected value of B's.  The multi-scale test of
:mod:`harness.stats.scales` with both sides' variances (Jung, Hanika & Dachsbacher 2020 test
Welch per pixel; here Welch per pixel and per 2 to 16 pixel tile and on the whole image, each
scale at alpha / n_scales and Bonferroni within), so the false-alarm rate is at most alpha under
any dependence between pixels, channels and tiles.  Replicas are the unit of variance, which is
right for stratified and QMC samplers and for filters that share samples.  The skew gate
leaves a side of a tile untested where either set's block is skewed (a light tracer's sparse
pixels, fireflies); pixels NaN, infinite or negative in any replica are excluded and reported
with (replica, row, col).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from harness.stats.images import (
    PixelVerdict,
    faulty_values,
    mean_difference,
    relative_squared_error,
    valid_pixels,
)
from harness.stats.results import ConfidenceInterval, Failure, t_interval
from harness.stats.scales import Scale, combined, multiscale
from harness.stats.validate import count, level

__all__ = ["ImageComparison", "compare_images"]


@dataclass(frozen=True)
class ImageComparison(PixelVerdict):
    """Outcome of :func:`compare_images`, a member of the result family.

    ``verdict``: "invalid" when pixels had to be excluded (``failures``), "differ" when
    ``pvalue`` <= ``alpha``, "inconclusive" when a side of the whole image was untestable, else
    "consistent".  ``scales``: each scale's p-value, level and untested sides.  ``difference``
    is the image-average of mean(A) - mean(B) with its standard error and Welch-Satterthwaite
    df; ``relmse_ab`` / ``relmse_ba`` the relMSE of each set's mean against the other's.
    ``n`` = replicas of A + replicas of B.
    """

    pvalue: float
    scales: tuple[Scale, ...]
    difference: float
    difference_se: float
    difference_df: float
    replicas: tuple[int, int]
    relmse_ab: float
    relmse_ba: float
    excluded: int
    shape: tuple[int, int]
    alpha: float = 0.01
    failures: list[Failure] = field(default_factory=list)
    reject = "differ"

    @property
    def n(self) -> int:
        return sum(self.replicas)

    def confidence_interval(self, confidence_level: float = 0.95) -> ConfidenceInterval:
        """Student-t interval (``difference_df`` degrees of freedom) of mean(A) - mean(B)."""
        return t_interval(self.difference, self.difference_se, self.difference_df, confidence_level)

    def __str__(self) -> str:
        lo, hi = self.confidence_interval(1 - self.alpha)
        s = (f"{self.verdict}: p = {self.pvalue:.3g}, alpha = {self.alpha}, replicas {self.replicas[0]} and "
             f"{self.replicas[1]}; {self.scales_text()}; most significant {self.worst_scale.name} at (row, "
             f"col, channel) {self.worst_pixel} t = {self.worst_t:+.2f}; image-mean difference A - B "
             f"{self.difference:+.3g} ± {self.difference_se:.2g}, {100 * (1 - self.alpha):g} % CI "
             f"[{lo:+.3g}, {hi:+.3g}]; relMSE of A against mean B {self.relmse_ab:.3g}, of B against mean A "
             f"{self.relmse_ba:.3g}")
        if self.verdict == "inconclusive":
            s += f"; {self.inconclusive}"
        return s + "".join(f"; {f}" for f in self.failures)


def compare_images(a: np.ndarray, b: np.ndarray, *, alpha: float = 0.01,
                   spp: int | None = None) -> ImageComparison:
    """Tests whether replica renders ``a`` (Ra, h, w, c) and ``b`` (Rb, h, w, c), each set
    independent renders of one configuration, estimate the same image; see the module
    docstring.  Needs at least 4 replicas a set (8 for the pixel and small-tile scales);
    ``alpha`` is the verdict's family-wise level; ``spp``, the fewer samples per pixel of the two
    sets' replicas where known: scales whose tiles average fewer than 64 are then not tested."""
    level(alpha, "alpha")
    if spp is not None:
        spp = count(spp, "spp")
    x, y = (np.asarray(v, dtype=np.float64) for v in (a, b))
    x, y = (v[..., None] if v.ndim == 3 else v for v in (x, y))
    if x.ndim != 4 or y.ndim != 4 or x.shape[1:] != y.shape[1:]:
        raise ValueError(f"expected two sets of replica images (R, height, width, channels) of one size, got "
                         f"{x.shape} and {y.shape}")
    ra, rb = x.shape[0], y.shape[0]
    if min(ra, rb) < 4:
        raise ValueError(f"comparing two renderers needs at least 4 replicas of each, got {ra} and {rb}")
    valid = valid_pixels(x, y)
    scales = multiscale(x, y, valid, alpha, spp=spp)
    xv, yv = x[:, valid], y[:, valid]
    diff, se, df = mean_difference(xv, yv, False)
    ma, mb = xv.mean(axis=0), yv.mean(axis=0)
    rel_ab = float(relative_squared_error(ma, mb).mean()) if xv.size else float("nan")
    rel_ba = float(relative_squared_error(mb, ma).mean()) if xv.size else float("nan")
    failures = faulty_values(x, "set_a", "replica") + faulty_values(y, "set_b", "replica")
    return ImageComparison(combined(scales), scales, diff, se, df, (ra, rb), rel_ab, rel_ba,
                           int((~valid).sum()), valid.shape, alpha, failures)
