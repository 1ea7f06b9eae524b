"""Measurements of rendered images: per-pixel bias with a controlled false-alarm rate,
relMSE, variance, convergence and efficiency, each from independent replica renders.

Pixels where any replica (or the reference) is NaN, infinite or negative are excluded from
every average and reported with counts and positions by the caller (``adapters.image_faults``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats as sps

from harness import stats

__all__ = ["RELMSE_EPSILON", "Reference", "ImageBias", "pixel_bias_test", "relmse", "as_replicates",
           "image_efficiency", "pixel_variance"]

RELMSE_EPSILON = 1e-2   # relMSE = mean over pixels of (x - ref)^2 / (ref^2 + eps): keeps black pixels finite
_ROUNDING = 2.0**-20    # relative float32 rounding floor of an accumulated render (8 ulp of 2^-23)


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
    def exact(cls, image: np.ndarray) -> "Reference":
        a = np.asarray(image, dtype=np.float64)
        return cls(a, np.zeros_like(a), 0, 0.0)

    @classmethod
    def from_parts(cls, parts: np.ndarray) -> "Reference":
        """From K >= 2 independent renders (K, h, w, c) of equal budget."""
        p = np.asarray(parts, dtype=np.float64)
        k = p.shape[0]
        if k < 2:
            raise ValueError(f"a rendered reference needs >= 2 independent parts to know its own error, got {k}")
        means = p.reshape(k, -1).mean(axis=1)
        return cls(p.mean(axis=0), p.var(axis=0, ddof=1) / k, k, float(np.var(means, ddof=1) / k))

    def noise_relmse(self, valid: np.ndarray | None = None) -> float:
        """The reference's own contribution to a relMSE measured against it."""
        share = self.variance / (self.mean**2 + RELMSE_EPSILON)
        return float(np.mean(share if valid is None else share[valid]))


@dataclass(frozen=True)
class ImageBias:
    """Per-pixel bias test of one render configuration.

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

    def rejected(self, alpha: float) -> bool:
        return self.pvalue <= alpha


def _valid(images: np.ndarray, reference: Reference) -> np.ndarray:
    """(h, w) mask of pixels that are finite and non-negative in every replica and the reference."""
    def ok(a: np.ndarray) -> np.ndarray:
        return (np.isfinite(a) & (a >= 0)).all(axis=-1)

    return ok(images).all(axis=0) & ok(reference.mean) & ok(reference.variance)


def pixel_bias_test(images: np.ndarray, reference: Reference, spp: int, *, gate_alpha: float = 0.01) -> ImageBias:
    """Tests replica renders (R, h, w, c) against a reference; see ImageBias."""
    x = np.asarray(images, dtype=np.float64)
    r = x.shape[0]
    if r < 2:
        raise ValueError(f"the per-pixel bias test needs >= 2 replicas, got {r}")
    valid = _valid(x, reference)
    xv, ref, ref_var = x[:, valid], reference.mean[valid], reference.variance[valid]   # (R, m, c), (m, c)
    m = xv.mean(axis=0)
    s2 = xv.var(axis=0, ddof=1) / r
    floor = (_ROUNDING * np.maximum(np.abs(ref), np.abs(m))) ** 2
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
    dev = xv - m
    m2 = (dev**2).mean(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        skew = (dev**3).mean(axis=0) / m2**1.5
    z = sps.norm.isf(gate_alpha / (4 * max(m.size, 1)))
    # allowance: one standard deviation of the sample skewness of R normal values, sqrt(6 / R)
    limit = 0.5 * 6 * math.sqrt(r) / (2 * z * z + 1) + math.sqrt(6 / r)
    # Replicas that are all equal reveal nothing about the estimator's spread (a light tracer
    # may never reach a pixel in R renders): testable only if they agree with the reference.
    testable = np.where(m2 > 0, np.abs(skew) <= limit, np.abs(m - ref) <= np.sqrt(floor))
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

    t_map = np.full(valid.shape, np.nan)
    t_map[valid] = np.where(testable, np.abs(t), np.nan).max(axis=-1) if ref.size else np.nan
    if tested:
        flat = int(np.argmax(np.where(testable, np.abs(t), -1.0)))
        pix, ch = np.unravel_index(flat, t.shape)
        rows, cols = np.nonzero(valid)
        worst, worst_t = (int(rows[pix]), int(cols[pix]), int(ch)), float(t[pix, ch])
    else:
        worst, worst_t = (-1, -1, -1), math.nan
    return ImageBias(min(1.0, 2 * min(p_pix, p_mean)), p_pix, p_mean, bias, se, worst, worst_t, tested,
                     int(testable.size - tested), int((~valid).sum()), r, int(spp), t_map)


def relmse(images: np.ndarray, reference: Reference) -> np.ndarray:
    """relMSE of each replica (R,): the mean over valid pixels and channels of
    (x - ref)^2 / (ref^2 + RELMSE_EPSILON), minus the reference's own noise share."""
    x = np.asarray(images, dtype=np.float64)
    valid = _valid(x, reference)
    ref = reference.mean[valid]
    err = ((x[:, valid] - ref) ** 2 / (ref**2 + RELMSE_EPSILON)).reshape(x.shape[0], -1).mean(axis=1)
    return err - reference.noise_relmse(valid)


def pixel_variance(images: np.ndarray, reference: Reference, spp: int) -> tuple[float, float, int]:
    """Per-sample variance averaged over valid pixels and channels (the variance of one
    replica times spp), its standard error over pixels, and the sample count behind it."""
    x = np.asarray(images, dtype=np.float64)
    valid = _valid(x, reference)
    v = x[:, valid].var(axis=0, ddof=1).ravel() * spp
    if v.size == 0:
        return math.nan, math.nan, 0
    return float(v.mean()), float(v.std(ddof=1) / math.sqrt(v.size)) if v.size > 1 else math.nan, x.shape[0] * spp


def as_replicates(scene: str, label: str, spp: int, errors: np.ndarray, seconds: np.ndarray) -> stats.Replicates:
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
    med = float(np.median(t))
    t_se = 1.2533 * 1.4826 * float(np.median(np.abs(t - med))) / math.sqrt(r)
    if not (mse > 0 and med > 0):
        return stats.Efficiency(label, math.nan, math.nan, spp, r, math.nan, med)
    rel = float(e.std(ddof=1)) / math.sqrt(r) / mse
    return stats.Efficiency(label, -math.log10(mse) - math.log10(med), math.hypot(rel, t_se / med), spp, r,
                            math.log10(mse), med)
