"""Measurements of rendered images: bias at every scale with a controlled false-alarm rate,
relMSE, variance, convergence and efficiency, each from independent replica renders.

Pixels where any replica (or the reference) is NaN, infinite or negative are excluded from
every average; the bias test counts them as ``failures`` (with their first positions), and the
caller reports them per kind and image (``harness.adapters.base.image_faults``).

relMSE is defined here once (:func:`relative_squared_error`, :data:`RELMSE_EPSILON`); the
report's error maps (``reports.images``) use the same definition.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from harness import stats
from harness.stats.results import ConfidenceInterval, Failure, t_interval
from harness.stats.scales import ROUNDING, Scale, combined, multiscale
from harness.stats.timing import median_time, satterthwaite, time_blocks
from harness.stats.validate import level

__all__ = ["RELMSE_EPSILON", "relative_squared_error", "Reference", "ImageBias", "pixel_bias_test", "relmse",
           "as_replicates", "image_efficiency", "pixel_variance", "faulty_values",
           "valid_pixels", "mean_difference", "PixelVerdict", "ROUNDING"]

RELMSE_EPSILON = 1e-2   # relMSE = mean over pixels of (x - ref)^2 / (ref^2 + eps): keeps black pixels finite
_MAX_EXAMPLES = 8       # first excluded pixels listed in a failure


def relative_squared_error(estimate: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """(estimate - reference)^2 / (reference^2 + RELMSE_EPSILON), elementwise (broadcasting):
    the squared error relative to the reference's brightness, finite on black pixels.  Its mean
    over pixels and channels is the relMSE of the rendering literature."""
    return (estimate - reference) ** 2 / _relmse_scale(reference)


def _relmse_scale(reference: np.ndarray) -> np.ndarray:
    return reference**2 + RELMSE_EPSILON


@dataclass(frozen=True)
class Reference:
    """The value each pixel must have: ``mean`` (h, w, c), and the ``parts`` (K, h, w, c) it
    was averaged from: K >= 2 independent renders of equal budget, or None for an exact image.
    The tests form each scale's tiles from the parts themselves, so the reference's own error
    is counted at every scale, correlations between pixels included."""

    mean: np.ndarray
    parts: np.ndarray | None = None

    @classmethod
    def exact(cls, image: np.ndarray) -> Reference:
        return cls(np.asarray(image, dtype=np.float64))

    @classmethod
    def from_parts(cls, parts: np.ndarray) -> Reference:
        """From K >= 2 independent renders (K, h, w, c) of equal budget."""
        p = np.asarray(parts, dtype=np.float64)
        if p.ndim != 4 or p.shape[0] < 2:
            raise ValueError(f"a rendered reference needs >= 2 independent parts (K, h, w, c) to know its "
                             f"own error, got shape {p.shape}")
        return cls(p.mean(axis=0), p)

    @property
    def count(self) -> int:
        """Independent parts (0 for an exact image)."""
        return 0 if self.parts is None else int(self.parts.shape[0])

    @property
    def stack(self) -> np.ndarray:
        """(K, h, w, c): the parts, or the exact image as the one "part" it is."""
        return self.mean[None] if self.parts is None else self.parts

    @property
    def variance(self) -> np.ndarray:
        """Per pixel-channel variance of ``mean`` (zero for an exact image)."""
        if self.parts is None:
            return np.zeros_like(self.mean)
        return self.parts.var(axis=0, ddof=1) / self.count

    def noise_relmse(self, valid: np.ndarray | None = None) -> float:
        """The reference's own contribution to a relMSE measured against it."""
        share = self.variance / _relmse_scale(self.mean)
        return float(np.mean(share if valid is None else share[valid]))


def faulty_values(images: np.ndarray, what: str, index: str) -> list[Failure]:
    """One failure per kind of bad value in ``images`` (R, h, w, c): "<what>_nan", "_inf" and
    "_negative", each with its count of pixel-channels and first positions (``index``, row, col).
    The tests leave those pixels out of every average and report them, never average them."""
    out = []
    for kind, bad in (("nan", np.isnan(images)), ("inf", np.isinf(images)), ("negative", images < 0)):
        n = int(bad.sum())
        if n:
            where = np.argwhere(bad.any(axis=-1))[:_MAX_EXAMPLES]
            out.append(Failure(f"{what}_{kind}", n, f"{kind} values in the {what} (pixel-channels)",
                               tuple({index: int(k), "row": int(i), "col": int(j)} for k, i, j in where)))
    return out


def valid_pixels(*sets: np.ndarray) -> np.ndarray:
    """(h, w) mask of pixels finite and non-negative in every channel of every image of every
    set (each (R, h, w, c))."""
    return np.logical_and.reduce([(np.isfinite(x) & (x >= 0)).all(axis=(0, 3)) for x in sets])


class PixelVerdict:
    """The verdict of a multi-scale image test (``pvalue``, ``alpha``, ``failures``,
    ``inconclusive``): "invalid" where pixels were excluded, ``reject`` when pvalue <= alpha,
    "inconclusive" when a side of the whole image could not be tested (the reason says why),
    else "consistent"."""

    reject = "biased"
    pvalue: float
    alpha: float
    failures: list[Failure]
    scales: tuple[Scale, ...]
    shape: tuple[int, int]

    @property
    def verdict(self) -> str:
        if self.failures:
            return "invalid"
        if self.pvalue <= self.alpha:
            return self.reject
        return "inconclusive" if self.inconclusive else "consistent"

    @property
    def inconclusive(self) -> str:
        """Why a "consistent" would be unfounded ("" if it is not): a side of the whole image
        untested (its replicas too skewed or constant to trust the t law)."""
        image = self.scales[-1]
        sides = [s for s, n in (("darker", image.low_untested), ("brighter", image.high_untested)) if n]
        if not sides:
            return ""
        return (f"whether the image is {' or '.join(sides)} than it should be is untested: its replicas are "
                "too skewed (or constant) for the t law at this replica count; render more replicas")

    @property
    def passed(self) -> bool:
        return self.verdict == "consistent"

    @property
    def statistic(self) -> float:
        """NaN: the p-value combines several tests."""
        return math.nan

    def scale(self, size: int) -> Scale | None:
        """The scale of tile edge ``size`` (1 pixels, 0 the whole image), None if not tested."""
        return next((s for s in self.scales if s.size == size), None)

    @property
    def pvalue_pixels(self) -> float:
        """The pixel scale's p-value (NaN where too few replicas to test pixels)."""
        s = self.scale(1)
        return math.nan if s is None else s.pvalue

    @property
    def pvalue_mean(self) -> float:
        return self.scales[-1].pvalue

    @property
    def worst_scale(self) -> Scale:
        """The scale with the smallest p-value: the one that rejected, if any did."""
        return min(self.scales, key=lambda s: s.pvalue)

    @property
    def worst_pixel(self) -> tuple[int, int, int]:
        """(row, col, channel) of the first pixel of the most significant tile."""
        return self.worst_scale.worst

    @property
    def worst_t(self) -> float:
        return self.worst_scale.worst_t

    @property
    def t_map(self) -> np.ndarray:
        """(h, w): the largest |t| over channels at the most significant scale, per pixel."""
        return self.worst_scale.expand(self.shape)

    def pvalue_counts(self, bins: int = 20) -> list[int]:
        """Histogram (``bins`` equal bins of [0, 1]) of the finest scale's tested tile-channel
        p-values: flat under H0 where the t law holds, so it shows a miscalibrated test or a
        diffuse bias at a glance."""
        p = self.scales[0].pvalues
        return np.histogram(p[p < 1], bins=bins, range=(0, 1))[0].tolist()

    def scales_text(self) -> str:
        return "; ".join(str(s) for s in self.scales)


@dataclass(frozen=True)
class ImageBias(PixelVerdict):
    """Multi-scale bias test of one render configuration against a reference
    (:func:`pixel_bias_test`), a member of the result family (:mod:`harness.stats.results`).

    H0: every pixel's expected value equals the reference.  The scales of
    :mod:`harness.stats.scales` (pixels, 2 to 16 pixel tiles, the whole image; fine scales from 16
    replicas on), each at alpha / n_scales, Bonferroni within: the false-alarm rate is at most
    alpha under any dependence between pixels and channels.  A rendered reference enters each
    scale through its parts (Welch t, Welch-Satterthwaite df); an exact one as a constant.

    Detectable bias at 80 % power, measured (``benchmarks/pixel_calibration.py``,
    ``image_zoo.detectable``: alpha = 0.01, 32 x 32 RGB, normal replicas, 100 seeds, one aligned
    square of s pixels too bright in all channels), in standard errors of that square's mean
    (a pixel's SE / s):

    ========  ======  ====  ====  ====  ======  =====
    replicas  pixels  2x2   4x4   8x8   16x16   image
    ========  ======  ====  ====  ====  ======  =====
    16        8       7     7     6     5       3
    8         --      --    --    > 20  16      7
    ========  ======  ====  ====  ====  ======  =====

    So a region's bias is found at a fraction of a pixel's SE (an 8 x 8 region at 6 / 8 of it
    with 16 replicas), where a per-pixel test needs 8.  Under 16 replicas only the 8 x 8, 16 x 16
    and image scales are tested, with the t law at 3 degrees of freedom: that holds alpha on the
    real renders where R - 1 did not, at a steep price in power; render 16 replicas.

    ``verdict``: "invalid" when pixels had to be excluded (``failures``: counts and first
    positions, replicas and reference parts apart), "biased" when ``pvalue`` <= ``alpha``,
    "inconclusive" when a side of the whole image could not be tested (``inconclusive`` says
    why), else "consistent".  A suite judges many renders together (Holm) from ``pvalue``.
    ``bias_mean`` / ``bias_mean_se`` / ``bias_mean_df``: the image-average bias (all valid
    pixel-channels), its standard error and Welch-Satterthwaite degrees of freedom, both sets'
    errors and the rounding floor included.  ``n`` = ``replicas`` x ``spp``.
    """

    pvalue: float
    scales: tuple[Scale, ...]
    bias_mean: float
    bias_mean_se: float
    bias_mean_df: float
    replicas: int
    spp: int
    reference_parts: int
    excluded: int               # pixels excluded for faults
    shape: tuple[int, int]
    alpha: float = 0.01
    failures: list[Failure] = field(default_factory=list)

    @property
    def n(self) -> int:
        return self.replicas * self.spp

    def confidence_interval(self, confidence_level: float = 0.95) -> ConfidenceInterval:
        """Student-t interval (``bias_mean_df`` degrees of freedom) of the image-average bias."""
        return t_interval(self.bias_mean, self.bias_mean_se, self.bias_mean_df, confidence_level)

    def __str__(self) -> str:
        lo, hi = self.confidence_interval(1 - self.alpha)
        parts = self.reference_parts
        against = f"a reference of {parts} parts" if parts else "an exact reference"
        s = (f"{self.verdict}: p = {self.pvalue:.3g}, alpha = {self.alpha}, {self.replicas} replicas x "
             f"{self.spp} spp against {against}; "
             f"{self.scales_text()}; most significant {self.worst_scale.name} at (row, col, channel) "
             f"{self.worst_pixel} t = {self.worst_t:+.2f}; image-mean bias {self.bias_mean:+.3g} ± "
             f"{self.bias_mean_se:.2g}, {100 * (1 - self.alpha):g} % CI [{lo:+.3g}, {hi:+.3g}]")
        if self.verdict == "inconclusive":
            s += f"; {self.inconclusive}"
        return s + "".join(f"; {f}" for f in self.failures)


def mean_difference(a: np.ndarray, b: np.ndarray, b_exact: bool) -> tuple[float, float, float]:
    """Image-average of mean(A) - mean(B) over the pixel-channels given ((R, m) each), its
    standard error (both sets' errors and the float32 rounding floor) and Welch-Satterthwaite df."""
    if a.size == 0:   # no valid pixel-channel
        return 0.0, 0.0, math.inf
    ma = a.reshape(a.shape[0], -1).mean(axis=1)
    mb = b.reshape(b.shape[0], -1).mean(axis=1)
    va = float(np.var(ma, ddof=1)) / ma.size
    vb = 0.0 if b_exact else float(np.var(mb, ddof=1)) / mb.size
    diff = float(ma.mean() - mb.mean())
    floor = (ROUNDING * max(abs(float(ma.mean())), abs(float(mb.mean())))) ** 2
    df = satterthwaite([(math.sqrt(va), ma.size - 1), (math.sqrt(vb), max(mb.size - 1, 1))])
    return diff, math.sqrt(va + vb + floor), df


def pixel_bias_test(images: np.ndarray, reference: Reference, spp: int, *, alpha: float = 0.01) -> ImageBias:
    """Tests replica renders (R, h, w, c) against a reference; see ImageBias.  ``alpha`` is the
    family-wise level of the verdict, split equally across the scales."""
    level(alpha, "alpha")
    x = np.asarray(images, dtype=np.float64)
    if x.ndim != 4:
        raise ValueError(f"expected replica images (R, height, width, channels), got shape {x.shape}")
    r = x.shape[0]
    if r < 4:
        raise ValueError(f"the multi-scale bias test needs >= 4 replicas, got {r}")
    exact = reference.parts is None
    b = reference.stack
    if b.shape[1:] != x.shape[1:]:
        raise ValueError(f"replicas {x.shape[1:]} and reference {b.shape[1:]} differ in shape")
    valid = valid_pixels(x, b)
    scales = multiscale(x, b, valid, alpha, b_exact=exact, spp=int(spp), replicas=r)
    bias, se, df = mean_difference(x[:, valid], b[:, valid], exact)
    failures = faulty_values(x, "replicas", "replica") + faulty_values(b, "reference", "part")
    return ImageBias(combined(scales), scales, bias, se, df, r, int(spp), reference.count,
                     int((~valid).sum()), valid.shape, alpha, failures)


def _valid(x: np.ndarray, reference: Reference) -> np.ndarray:
    return valid_pixels(x, reference.stack)


def relmse(images: np.ndarray, reference: Reference) -> np.ndarray:
    """relMSE of each replica (R,): the mean over valid pixels and channels of
    (x - ref)^2 / (ref^2 + RELMSE_EPSILON), minus the reference's own noise share."""
    x = np.asarray(images, dtype=np.float64)
    valid = _valid(x, reference)
    ref = reference.mean[valid]
    err = relative_squared_error(x[:, valid], ref).reshape(x.shape[0], -1).mean(axis=1)
    return err - reference.noise_relmse(valid)


def pixel_variance(images: np.ndarray, reference: Reference, spp: int) -> tuple[float, float, int]:
    """Per-sample variance averaged over valid pixels and channels (the variance of one
    replica times spp), its standard error over pixels, and the sample count behind it."""
    x = np.asarray(images, dtype=np.float64)
    valid = _valid(x, reference)
    v = x[:, valid].var(axis=0, ddof=1).ravel() * spp
    if v.size == 0:
        return math.nan, math.nan, 0
    se = float(v.std(ddof=1) / math.sqrt(v.size)) if v.size > 1 else math.nan
    return float(v.mean()), se, x.shape[0] * spp


def as_replicates(scene: str, label: str, spp: int, errors: np.ndarray,
                  seconds: np.ndarray) -> stats.Replicates:
    """Replicas' relMSEs as stats.Replicates (error sqrt(relMSE) against 0), so convergence
    slopes come from the same permutation-tested fit as the core's: RMSE there is sqrt(mean relMSE)."""
    e = np.sqrt(np.maximum(np.asarray(errors, dtype=np.float64), 0.0))
    return stats.Replicates(scene, label, int(spp), 0.0, e, np.asarray(seconds, dtype=np.float64), math.nan,
                            math.nan, False, 1)


def image_efficiency(label: str, spp: int, errors: np.ndarray, seconds: np.ndarray) -> stats.Efficiency:
    """1 / (relMSE T) (background eq. 5 with relMSE for V) of one render at ``spp``, with the
    standard error of its log from the replicas' relMSE spread (R - 1 df) and the median time's
    (blocks - 1 df), and their Welch-Satterthwaite degrees of freedom: its interval is Student t,
    as the estimators' are."""
    e = np.asarray(errors, dtype=np.float64)
    t = np.asarray(seconds, dtype=np.float64)
    r = e.size
    mse = float(e.mean())
    med, t_se = median_time(t)
    if not (mse > 0 and med > 0):
        return stats.Efficiency(label, math.nan, math.nan, spp, r, math.nan, med)
    rel = float(e.std(ddof=1)) / math.sqrt(r) / mse
    return stats.Efficiency.from_errors(label, -math.log10(mse) - math.log10(med),
                                        [(rel, r - 1), (t_se / med, time_blocks(r) - 1)], spp, r,
                                        math.log10(mse), med)
