"""Measurements of rendered images: per-pixel bias with a controlled false-alarm rate,
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
from scipy import stats as sps

from harness import stats
from harness.stats.results import ConfidenceInterval, Failure, check_confidence_level
from harness.stats.timing import median_time
from harness.stats.validate import level

__all__ = ["RELMSE_EPSILON", "relative_squared_error", "Reference", "ImageBias", "pixel_bias_test", "relmse",
           "as_replicates", "image_efficiency", "pixel_variance", "normal_enough", "t_summary",
           "excluded_pixels", "PixelVerdict", "ROUNDING"]

RELMSE_EPSILON = 1e-2   # relMSE = mean over pixels of (x - ref)^2 / (ref^2 + eps): keeps black pixels finite
ROUNDING = 2.0**-20     # relative float32 rounding floor of an accumulated render (8 ulp of 2^-23)
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
    """The value each pixel must have: ``mean`` (h, w, c) and the variance of that mean
    (zero for an exact answer), ``parts`` independent renders it was averaged from (0 if exact)
    and the variance of the image-average of the reference (zero if exact)."""

    mean: np.ndarray
    variance: np.ndarray
    parts: int
    image_mean_variance: float

    @classmethod
    def exact(cls, image: np.ndarray) -> Reference:
        a = np.asarray(image, dtype=np.float64)
        return cls(a, np.zeros_like(a), 0, 0.0)

    @classmethod
    def from_parts(cls, parts: np.ndarray) -> Reference:
        """From K >= 2 independent renders (K, h, w, c) of equal budget."""
        p = np.asarray(parts, dtype=np.float64)
        k = p.shape[0]
        if k < 2:
            raise ValueError(f"a rendered reference needs >= 2 independent parts to know its own error, "
                             f"got {k}")
        means = p.reshape(k, -1).mean(axis=1)
        return cls(p.mean(axis=0), p.var(axis=0, ddof=1) / k, k, float(np.var(means, ddof=1) / k))

    def noise_relmse(self, valid: np.ndarray | None = None) -> float:
        """The reference's own contribution to a relMSE measured against it."""
        share = self.variance / _relmse_scale(self.mean)
        return float(np.mean(share if valid is None else share[valid]))


def t_summary(t: np.ndarray, testable: np.ndarray,
              valid: np.ndarray) -> tuple[np.ndarray, tuple[int, int, int], float]:
    """From per pixel-channel t (m, c) over the ``valid`` pixels (h, w): the (h, w) map of the
    largest tested |t| (NaN elsewhere), the worst tested (row, col, channel) and its t."""
    t_map = np.full(valid.shape, np.nan)
    if t.size:
        t_map[valid] = np.where(testable, np.abs(t), np.nan).max(axis=-1)
    if not testable.any():
        return t_map, (-1, -1, -1), math.nan
    pix, ch = np.unravel_index(int(np.argmax(np.where(testable, np.abs(t), -1.0))), t.shape)
    rows, cols = np.nonzero(valid)
    return t_map, (int(rows[pix]), int(cols[pix]), int(ch)), float(t[pix, ch])


def excluded_pixels(valid: np.ndarray, detail: str) -> list[Failure]:
    """The "excluded_pixels" failure (count, first positions) where ``valid`` is False."""
    excluded = int((~valid).sum())
    return [Failure("excluded_pixels", excluded, detail,
                    tuple({"row": int(i), "col": int(j)} for i, j in np.argwhere(~valid)[:_MAX_EXAMPLES]))
            ] if excluded else []


class PixelVerdict:
    """The verdict of a per-pixel test result (``pvalue``, ``alpha``, ``failures``): "invalid"
    where pixels were excluded, ``reject`` when pvalue <= alpha, else "consistent"."""

    reject = "biased"
    pvalue: float
    alpha: float
    failures: list[Failure]

    @property
    def verdict(self) -> str:
        if self.failures:
            return "invalid"
        return self.reject if self.pvalue <= self.alpha else "consistent"

    @property
    def passed(self) -> bool:
        return self.verdict == "consistent"

    @property
    def statistic(self) -> float:
        """NaN: the p-value combines several tests."""
        return math.nan


@dataclass(frozen=True)
class ImageBias(PixelVerdict):
    """Per-pixel bias test of one render configuration, a member of the result family
    (:mod:`harness.stats.results`).

    H0: every pixel's expected value equals the reference.  Two tests at alpha/2 each,
    Bonferroni-combined, so the false-alarm rate is at most alpha under any dependence between
    pixels and channels (pixel filters that share samples included):

    * pixels: Welch t per pixel and channel over R replicas (reference error included), the
      smallest p times the number of pixel-channels tested.  Detects a bias confined to few
      pixels of about t_{alpha/2m} pixel standard errors (roughly 5 to 6 for a 32 x 32 image).
    * image mean: Student t of the replicas' image averages against the reference's.  Detects
      a small bias spread over the image: about 3 standard errors of the image average at 80 %
      power.

    The pixel test uses only pixel-channels whose replicas are close enough to normal for the
    t law to hold at its Bonferroni level (an Edgeworth bound on the sample skewness); the
    rest (a light tracer's sparse hits, fireflies) are counted in ``untestable`` and covered
    by the image-mean test only.  ``gate_alpha`` is the family-wise level that bound is set for.

    ``verdict``: "invalid" when pixels had to be excluded (NaN, infinite or negative in a
    replica or the reference: ``failures`` has their count and first positions), else "biased"
    when ``pvalue`` <= ``alpha``, else "consistent".  A suite judges many renders together
    (Holm) and takes its own verdict from ``pvalue``.  ``statistic`` is NaN: the p-value
    combines two tests (see ``worst_t`` and ``bias_mean`` / ``bias_mean_se``).  ``n`` =
    ``replicas`` x ``spp``, the samples per pixel behind the figures.
    """

    pvalue: float
    pvalue_pixels: float
    pvalue_mean: float
    bias_mean: float            # image-average bias and its standard error
    bias_mean_se: float
    worst_pixel: tuple[int, int, int]
    worst_t: float
    tested: int                 # pixel-channels the pixel test trusted
    untestable: int             # pixel-channels too skewed (or constant off the reference) to test
    excluded: int               # pixels excluded for faults
    replicas: int
    spp: int
    t_map: np.ndarray           # (h, w) largest |t| over channels, NaN where excluded
    alpha: float = 0.01
    failures: list[Failure] = field(default_factory=list)

    @property
    def n(self) -> int:
        return self.replicas * self.spp

    def confidence_interval(self, confidence_level: float = 0.95) -> ConfidenceInterval:
        """Student-t interval (``replicas`` - 1 degrees of freedom, the image-mean test's) of the
        image-average bias, replicas' and reference's errors included."""
        check_confidence_level(confidence_level)
        half = float(sps.t.ppf(0.5 + confidence_level / 2, self.replicas - 1)) * self.bias_mean_se
        return ConfidenceInterval(self.bias_mean - half, self.bias_mean + half)

    def __str__(self) -> str:
        lo, hi = self.confidence_interval(1 - self.alpha)
        s = (f"{self.verdict}: p = {self.pvalue:.3g} (pixels {self.pvalue_pixels:.3g}, image mean "
             f"{self.pvalue_mean:.3g}), alpha = {self.alpha}, {self.replicas} replicas x {self.spp} spp, "
             f"{self.tested} pixel-channels tested ({self.untestable} too skewed to test); worst pixel "
             f"(row, col, channel) {self.worst_pixel} t = {self.worst_t:+.2f}; image-mean bias "
             f"{self.bias_mean:+.3g} ± {self.bias_mean_se:.2g}, "
             f"{100 * (1 - self.alpha):g} % CI [{lo:+.3g}, {hi:+.3g}]")
        return s + "".join(f"; {f}" for f in self.failures)


def _valid(images: np.ndarray, reference: Reference) -> np.ndarray:
    """(h, w) mask of pixels that are finite and non-negative in every replica and the reference."""
    def ok(a: np.ndarray) -> np.ndarray:
        return (np.isfinite(a) & (a >= 0)).all(axis=-1)

    return ok(images).all(axis=0) & ok(reference.mean) & ok(reference.variance)


def normal_enough(x: np.ndarray, family: int, gate_alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """Where replicas x (R, ...) are close enough to normal for a two-sided t test at the
    Bonferroni level gate_alpha / family, and where they are all equal (constant).

    The one-term Edgeworth correction of the tail at the critical value z,
    |skew| (2 z^2 + 1) / (6 sqrt(R)), must stay below half the nominal tail, up to one standard
    deviation sqrt(6 / R) of the sample skewness of R normal values (else a normal pixel is
    excluded by chance).  Sparse pixels (a light tracer's few hits, fireflies) fail it."""
    r = x.shape[0]
    m = x.mean(axis=0)
    dev = x - m
    m2 = (dev**2).mean(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        skew = (dev**3).mean(axis=0) / m2**1.5
    z = sps.norm.isf(gate_alpha / (2 * max(family, 1)))
    limit = 0.5 * 6 * math.sqrt(r) / (2 * z * z + 1) + math.sqrt(6 / r)
    constant = ~(m2 > 0)
    return ~constant & (np.abs(skew) <= limit), constant


def pixel_bias_test(images: np.ndarray, reference: Reference, spp: int, *, alpha: float = 0.01,
                    gate_alpha: float = 0.01) -> ImageBias:
    """Tests replica renders (R, h, w, c) against a reference; see ImageBias.  ``alpha`` is the
    level of the result's own verdict; it changes no figure (``gate_alpha`` sets the pixels'
    normality gate)."""
    level(alpha, "alpha")
    level(gate_alpha, "gate_alpha")
    x = np.asarray(images, dtype=np.float64)
    r = x.shape[0]
    if r < 2:
        raise ValueError(f"the per-pixel bias test needs >= 2 replicas, got {r}")
    valid = _valid(x, reference)
    xv, ref, ref_var = x[:, valid], reference.mean[valid], reference.variance[valid]   # (R, m, c), (m, c)
    m = xv.mean(axis=0)
    s2 = xv.var(axis=0, ddof=1) / r
    floor = (ROUNDING * np.maximum(np.abs(ref), np.abs(m))) ** 2
    se2 = s2 + ref_var + floor
    df = np.full_like(se2, r - 1.0)
    if reference.parts:  # Welch-Satterthwaite: replicas' and reference's errors together
        den = s2**2 / (r - 1) + ref_var**2 / (reference.parts - 1)
        np.divide((s2 + ref_var) ** 2, den, out=df, where=den > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(se2 > 0, (m - ref) / np.sqrt(se2), 0.0)
    # The t law is trusted in a pixel only where the replicas look normal enough at the
    # Bonferroni critical value z: the one-term Edgeworth correction of the tail,
    # |skew| (2 z^2 + 1) / (6 sqrt(R)), must stay below half the nominal tail, up to the noise
    # of the skewness estimate itself (else a normal pixel is excluded by chance).  Sparse pixels
    # (a light tracer's few hits, fireflies) are left to the image-mean test and counted.
    normal, constant = normal_enough(xv, 2 * m.size, gate_alpha)
    # Replicas that are all equal reveal nothing about the estimator's spread (a light tracer
    # may never reach a pixel in R renders): testable only if they agree with the reference.
    testable = np.where(constant, np.abs(m - ref) <= np.sqrt(floor), normal)
    p = np.where(testable, 2 * sps.t.sf(np.abs(t), np.maximum(df, 1.0)), 1.0)
    tested = int(testable.sum())
    p_pix = min(1.0, float(p.min()) * tested) if tested else 1.0

    means = xv.reshape(r, -1).mean(axis=1)
    bias = float(means.mean() - ref.mean()) if ref.size else 0.0
    se = math.sqrt(float(np.var(means, ddof=1)) / r + reference.image_mean_variance)
    if se > 0:
        df_mean = r - 1.0
        p_mean = float(2 * sps.t.sf(abs(bias) / se, df_mean))
    else:
        p_mean = 1.0 if bias == 0 else 0.0

    t_map, worst, worst_t = t_summary(t, testable, valid)
    excluded = int((~valid).sum())
    failures = excluded_pixels(valid, "pixels NaN, infinite or negative in a replica or the reference, "
                                      "left out of every average")
    return ImageBias(min(1.0, 2 * min(p_pix, p_mean)), p_pix, p_mean, bias, se, worst, worst_t, tested,
                     int(testable.size - tested), excluded, r, int(spp), t_map, alpha, failures)


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
    slopes come from the same bootstrap fit as the core's: RMSE there is sqrt(mean relMSE)."""
    e = np.sqrt(np.maximum(np.asarray(errors, dtype=np.float64), 0.0))
    return stats.Replicates(scene, label, int(spp), 0.0, e, np.asarray(seconds, dtype=np.float64), math.nan,
                            math.nan, False, 1)


def image_efficiency(label: str, spp: int, errors: np.ndarray, seconds: np.ndarray) -> stats.Efficiency:
    """1 / (relMSE T) (background eq. 5 with relMSE for V) of one render at ``spp``, with the
    standard error of its log from the replicas' relMSE spread and the median time's."""
    e = np.asarray(errors, dtype=np.float64)
    t = np.asarray(seconds, dtype=np.float64)
    r = e.size
    mse = float(e.mean())
    med, t_se = median_time(t)
    if not (mse > 0 and med > 0):
        return stats.Efficiency(label, math.nan, math.nan, spp, r, math.nan, med)
    rel = float(e.std(ddof=1)) / math.sqrt(r) / mse
    return stats.Efficiency(label, -math.log10(mse) - math.log10(med), math.hypot(rel, t_se / med), spp, r,
                            math.log10(mse), med)
