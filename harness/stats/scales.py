"""Multi-scale tests of replica images: does set A, pixel by pixel and tile by tile, have the
expected value of B (an exact image, the parts of a rendered reference, or another renderer's
replicas)?

At each scale (pixels, square tiles of 2, 4, 8 and 16 pixels, the whole image) every replica
is averaged over each tile's valid pixels, per channel (over all channels for the whole image,
where a bias everywhere, a wrong normalisation, is found with the most power).  A Welch t per
tile-channel compares the means (Student t with R - 1 degrees of freedom against an exact
image), with a float32 rounding floor in its standard error.  A scale's p-value is Bonferroni
over all its tile-channels (a count fixed by the image's shape, never by the data); the scales
share the family-wise level equally, so the combined p-value, n_scales times the smallest,
holds alpha under any dependence between pixels, channels and scales (filters that share
samples included).

Why the skew gate.  A t test at a Bonferroni level far in the tail (1e-6 for a 32 x 32 RGB
image) holds only for near-normal replicas.  For right-skewed ones (a light tracer's sparse
hits, fireflies) the low side of t is far heavier than the t law: a replica set that missed its
rare large values has a low mean *and* a small spread.  Measured (4e6 gamma tests, 16
replicas): skewness 0.4 makes the 1e-6 tail 2.5 times too heavy, skewness 1.6 175 times.  The
high side is lighter than the t law there, so it stays valid.  A tile's own sample
skewness cannot gate it (it is small exactly when the rare value is missing, i.e. it selects the
worst tiles), so the gate pools a *block* of 8 x 8 tiles: it counts the tile-channels whose
skewness lies beyond the 80 % quantile of |skewness| of normal replicas, on each side, and calls
the block right- (left-) skewed when that count exceeds the normal rate (10 % a side) at one-sided
level 0.01 (binomial).  In a right-skewed block of A (left-skewed of B) the low side of t is not
tested at that scale, and vice versa; the tile's pixels are still covered by coarser scales, where
averaging has shrunk the skewness.  A block holding fewer than 48 tile-channels pools the whole
scale.  A scale holding fewer than 48 in all (16 x 16 tiles and the whole image of a small
render) is judged from the last scale that could be: its mean skewness, shrunk by the square root
of the number of its tiles (and channels) a coarse tile averages, against 0.2 (the t law's 1e-5
tail is about 1.3 times too heavy at skewness 0.2 and 16 replicas); where the whole image's low
side is left untested that way, a verdict that is not "biased" is "inconclusive".  The gate
never reads t.

Replicas and samples.  Below 16 replicas a set the t law fails at fine scales: for sparse,
discrete pixels (Poisson hits at 1 to 3 a pixel: nearly equal tile means at 4 replicas give an
enormous t) and for real light-traced renders at 8 replicas (Mitsuba's particle tracer on the
Cornell box and a glossy sphere, 16 spp: 5 and 11 false alarms in 100 from 2 x 2 and 4 x 4
tiles).  So pixels and tiles under 8 are tested only from 16 replicas on, and below 16 the
coarser scales judge t by the t law with at most 3 degrees of freedom (heavier tailed than
R - 1 would give: at 8 replicas t_7 let skewed 8 x 8 and 16 x 16 tiles of the same renders
through 4 and 5 times in 100, t_3 holds; at 4 replicas it is the law anyway).  A scale is also
left out where a replica's tile mean averages fewer than 64 samples (``spp`` x edge^2, when
the caller knows spp): at 4 spp the pixels of an area light's edge are a few Bernoulli draws, and
16 replicas that missed the rare dark sample give a huge t (Mitsuba's path tracer on the Cornell
box at depth 4: 91 false alarms in 100 with pixels tested at 4 spp, none without).

Constant sets.  A tile-channel whose replicas are all equal reveals nothing about its spread (a
light tracer may miss a pixel in every replica): it is not tested at that scale unless the
whole set is deterministic (every replica the same image), in which case zero variance is the
truth and any difference beyond rounding is significant.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import special

__all__ = ["SIZES", "FINE_REPLICAS", "MIN_SAMPLES", "ROUNDING", "Scale", "sizes", "multiscale", "combined"]

SIZES = (1, 2, 4, 8, 16)       # tile edges tested below the whole image (0 stands for the whole image)
FINE_REPLICAS = 16             # pixels and tiles under 8 pixels need this many replicas a set ...
FEW_DF = 3.0                   # ... and with fewer, t is judged by the t law with at most 3 df
MIN_SAMPLES = 64               # a scale is tested where a replica's tile mean averages this many samples
ROUNDING = 2.0**-20            # relative float32 rounding floor of an accumulated render (8 ulp of 2^-23)
GATE_BLOCK = 8                 # a tile's skew gate pools the GATE_BLOCK x GATE_BLOCK tiles of its block
GATE_MINIMUM = 48              # ... or the whole scale where a block holds fewer tile-channels
GATE_LEVEL = 0.01              # one-sided binomial level at which a block is called skewed
SKEW_LIMIT = 0.2               # a scale too coarse to judge is skewed where its projected skewness passes it
_FLAG = 0.2                    # |skewness| beyond its normal (1 - _FLAG) quantile flags a tile-channel


@dataclass(frozen=True)
class Scale:
    """One scale of :func:`multiscale`: ``size`` the tile edge in pixels (0: the whole image),
    ``alpha`` its share of the family-wise level, ``pvalue`` = min(1, ``count`` x the smallest
    tile-channel p), ``count`` the tile-channels (the Bonferroni count).  ``low_untested`` /
    ``high_untested``: tile-channels whose low (A below B) or high side the skew gate or a
    constant set left out.  ``worst``: (row, col, channel) of the most significant tile's first
    pixel (channel -1 for the whole image's all-channel mean) and its t.  ``t_map`` (tile rows,
    tile cols): the largest tested |t| over channels (NaN
    where nothing was tested); ``pvalues`` (tile-channels): each one's p (1 where untested), which
    are uniform under H0 where the t law holds."""

    size: int
    alpha: float
    pvalue: float
    count: int
    low_untested: int
    high_untested: int
    worst: tuple[int, int, int]
    worst_t: float
    t_map: np.ndarray
    pvalues: np.ndarray

    @property
    def name(self) -> str:
        return "image" if self.size == 0 else "pixels" if self.size == 1 else f"{self.size}x{self.size} tiles"

    @property
    def rejected(self) -> bool:
        return self.pvalue <= self.alpha

    def expand(self, shape: tuple[int, int]) -> np.ndarray:
        """``t_map`` on the (h, w) pixel grid: each tile's value over its pixels."""
        h, w = shape
        s = _edge(self.size, shape)
        return np.repeat(np.repeat(self.t_map, s, axis=0), s, axis=1)[:h, :w]

    def __str__(self) -> str:
        untested = ""
        if self.low_untested or self.high_untested:
            untested = (f", skewed or constant: {self.low_untested} low / {self.high_untested} high sides "
                        "untested")
        return f"{self.name} p = {self.pvalue:.3g} ({self.count} tested at {self.alpha:.3g}{untested})"


def sizes(replicas: int, shape: tuple[int, int], spp: int | None = None) -> tuple[int, ...]:
    """The scales tested for ``replicas`` (the smaller set's count), an (h, w) image and ``spp``
    samples per pixel a replica (None: unknown): tile edges under the image's shorter side,
    under 8 only from FINE_REPLICAS replicas, and only where a replica's tile mean averages at
    least MIN_SAMPLES samples (spp x edge^2), then 0 (the whole image)."""
    fine = [s for s in SIZES if s < min(shape) and (s >= 8 or replicas >= FINE_REPLICAS)
            and (spp is None or spp * s * s >= MIN_SAMPLES)]
    return (*fine, 0)


def _edge(size: int, shape: tuple[int, int]) -> int:
    """A scale's tile edge in pixels on an (h, w) image (``size`` 0, the whole image: one tile)."""
    return max(shape) if size == 0 else size


def _tile_means(x: np.ndarray, valid: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each replica's mean over each tile's valid pixels: (R, tiles, c), and the tiles' grid
    rows and cols (tiles with no valid pixel are left out)."""
    h, w = valid.shape
    s = _edge(size, valid.shape)
    rows, cols = np.arange(0, h, s), np.arange(0, w, s)
    kept = np.where(valid[None, :, :, None], x, 0.0)
    sums = np.add.reduceat(np.add.reduceat(kept, rows, axis=1), cols, axis=2)
    counts = np.add.reduceat(np.add.reduceat(valid.astype(np.float64), rows, axis=0), cols, axis=1)
    keep = counts > 0
    ti, tj = np.nonzero(keep)
    return sums[:, keep] / counts[keep][None, :, None], ti, tj


def _moments(m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Mean, variance of the mean (ddof 1), sample skewness and constancy over axis 0."""
    r = m.shape[0]
    constant = (m == m[:1]).all(axis=0)   # exactly: a float mean of equal values need not equal them
    mean = np.where(constant, m[0], m.mean(axis=0))
    dev = m - mean
    m2 = np.where(constant, 0.0, (dev**2).mean(axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        skew = np.where(constant, 0.0, (dev**3).mean(axis=0) / m2**1.5)
    return mean, m2 * r / (r - 1) / r, skew, constant


@lru_cache(maxsize=None)
def _flag_cut(r: int) -> float:
    """The (1 - _FLAG) quantile of |sample skewness| of r normal values (simulated once, fixed seed)."""
    g = []
    rng = np.random.default_rng(0)
    for _ in range(10):
        _, _, skew, _ = _moments(rng.standard_normal((r, 10_000)))
        g.append(np.abs(skew))
    return float(np.quantile(np.concatenate(g), 1 - _FLAG))


Judged = tuple[float, float]   # a set's mean skewness over the last judged scale's tile-channels, its edge


def _skewed_blocks(skew: np.ndarray, constant: np.ndarray, ti: np.ndarray, tj: np.ndarray,
                   r: int) -> tuple[np.ndarray, np.ndarray] | None:
    """(tiles, c) masks: tile-channels in a right-skewed block, in a left-skewed block; None
    where the whole scale holds fewer than GATE_MINIMUM live tile-channels (too few to judge)."""
    cut = _flag_cut(r)
    _, block = np.unique((ti // GATE_BLOCK) * (int(tj.max()) // GATE_BLOCK + 1) + tj // GATE_BLOCK,
                         return_inverse=True)
    live = ~constant
    sizes_ = np.bincount(block, weights=live.sum(axis=1))
    if sizes_.sum() < GATE_MINIMUM:
        return None
    if sizes_.min() < GATE_MINIMUM:
        block = np.zeros_like(block)
        sizes_ = sizes_.sum(keepdims=True)
    from scipy import stats as sps  # here: scipy.stats costs 0.8 s of import (harness.stats.distributions)

    right, left = np.zeros(skew.shape, bool), np.zeros(skew.shape, bool)
    for flags, out in (((skew > cut) & live, right), ((skew < -cut) & live, left)):
        k = np.bincount(block, weights=flags.sum(axis=1), minlength=sizes_.size)
        p = sps.binom.sf(k - 1, sizes_.astype(np.int64), _FLAG / 2)
        out[:] = (p < GATE_LEVEL)[block][:, None]
    return right, left


def _projected(finer: Judged, size: int, shape: tuple[int, int], channels: int) -> tuple[bool, bool]:
    """A coarse scale's skew flags (right, left) where it has too few tiles to judge: the finer scale's mean
    skewness, shrunk as a mean of independent parts shrinks it (by the square root of how many
    finer tiles, and channels for the whole image's all-channel mean, each coarse tile holds),
    compared with SKEW_LIMIT.  Pixels that share samples shrink it less; the zoo and the real
    renders (benchmarks/pixel_calibration.py, render_calibration.py) measure what that costs."""
    skew, edge = finer
    parts = (shape[0] * shape[1] * channels if size == 0 else size * size) / (edge * edge)
    g = skew / math.sqrt(parts)
    return g > SKEW_LIMIT, g < -SKEW_LIMIT


def _welch_df(var_a: np.ndarray, var_b: np.ndarray, ra: int, rb: int) -> float:
    """Welch-Satterthwaite degrees of freedom of a scale, from the median ratio of the two sets'
    variances over its tile-channels, within [min(ra, rb) - 1, ra + rb - 2].

    Why not each tile's own estimated ratio (the textbook): a tile whose A replicas happen to
    spread little gets a small variance *and* a large df, so its t is judged by a light-tailed
    law exactly when it is large.  Measured (4 replicas against 8 reference parts, normal
    pixels): the 1e-5 tail 55 times too heavy.  The median over a scale's tiles is stable and
    barely depends on any one tile."""
    both = (var_a > 0) & (var_b > 0)
    if not both.any():
        return float(min(ra, rb) - 1)
    ratio = float(np.median(var_a[both] / var_b[both]))
    df = (ratio + 1) ** 2 / (ratio**2 / (ra - 1) + 1 / (rb - 1))
    return float(np.clip(df, min(ra, rb) - 1, ra + rb - 2))


def multiscale(a: np.ndarray, b: np.ndarray, valid: np.ndarray, alpha: float, *,
               b_exact: bool = False, spp: int | None = None,
               replicas: int | None = None) -> tuple[Scale, ...]:
    """The scales of A (Ra, h, w, c) against B (Rb, h, w, c), or against the exact image
    b (1, h, w, c) when ``b_exact``, over the ``valid`` (h, w) pixels; see the module docstring.
    ``replicas``: the count the replica rules go by (default the smaller set's; a rendered
    reference's parts, each of many samples, are near normal and pass A's count).  Each scale
    holds ``alpha`` / n_scales; the combined p-value is :func:`combined`."""
    ra = a.shape[0]
    rb = b.shape[0]
    if replicas is None:
        replicas = ra if b_exact else min(ra, rb)
    scales = sizes(replicas, valid.shape, spp)
    few = replicas < FINE_REPLICAS
    share = alpha / len(scales)
    fixed_a = bool(np.all(a == a[:1]))
    fixed_b = b_exact or bool(np.all(b == b[:1]))
    out = []
    finer: list[Judged | None] = [None, None]   # each set's mean skewness at the last scale judged
    for size in scales:
        ma, ti, tj = _tile_means(a, valid, size)
        mb = _tile_means(b, valid, size)[0]
        if size == 0:   # the whole image: one mean over all channels, the most power for a bias everywhere
            ma, mb = ma.mean(axis=-1, keepdims=True), mb.mean(axis=-1, keepdims=True)
        mean_a, var_a, skew_a, const_a = _moments(ma)
        if fixed_b:
            mean_b, var_b = mb[0], np.zeros_like(mean_a)
            skew_b, const_b = np.zeros_like(mean_a), np.ones(mean_a.shape, bool)
        else:
            mean_b, var_b, skew_b, const_b = _moments(mb)
        floor = (ROUNDING * np.maximum(np.abs(mean_a), np.abs(mean_b))) ** 2
        se2 = var_a + var_b + floor
        diff = mean_a - mean_b
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(se2 > 0, diff / np.sqrt(se2), 0.0)
        df = ra - 1.0 if fixed_b else _welch_df(var_a, var_b, ra, rb)
        if few:
            df = min(df, FEW_DF)
        low_ok = np.ones(t.shape, bool)
        high_ok = np.ones(t.shape, bool)
        # a constant set (but not a deterministic one) hides its spread: nothing to test with
        blind = (const_a & ~np.bool_(fixed_a)) | (const_b & ~np.bool_(fixed_b))
        for side, (skew, const, r, fixed, sign) in enumerate(((skew_a, const_a, ra, fixed_a, 1),
                                                             (skew_b, const_b, rb, fixed_b, -1))):
            if fixed:
                continue
            gate = _skewed_blocks(skew, const, ti, tj, r) if (~const).any() else None
            if gate is not None:
                finer[side] = (float(skew[~const].mean()), size)
            elif finer[side] is not None:
                right, left = _projected(finer[side], size, valid.shape, a.shape[-1])
                gate = (np.full(t.shape, right), np.full(t.shape, left))
            if gate is None:
                continue
            right, left = gate
            # right skew of A makes t's low side heavy; of B (entering as -B) its high side
            low_ok &= ~(right if sign > 0 else left)
            high_ok &= ~(left if sign > 0 else right)
        agree = np.abs(diff) <= np.sqrt(floor)
        exact_tie = (var_a + var_b) == 0
        low_ok &= ~blind
        high_ok &= ~blind
        p_low = np.where(low_ok, 2 * special.stdtr(df, t), 1.0)      # Student t cdf, without scipy.stats'
        p_high = np.where(high_ok, 2 * special.stdtr(df, -t), 1.0)   # per-call overhead
        p = np.minimum(np.minimum(p_low, p_high), 1.0)
        # both sets deterministic here: equal up to rounding, or certainly different
        p = np.where(exact_tie & ~blind, np.where(agree, 1.0, 0.0), p)
        tested = low_ok | high_ok
        count = int(p.size)
        pvalue = min(1.0, float(p.min()) * count) if count else 1.0
        h_tiles = int(ti.max()) + 1 if ti.size else 0
        w_tiles = int(tj.max()) + 1 if tj.size else 0
        t_map = np.full((h_tiles, w_tiles), np.nan)
        t_map[ti, tj] = np.where(tested, np.abs(t), np.nan).max(axis=-1)
        worst, worst_t = (-1, -1, -1), math.nan
        if count and tested.any():
            k, ch = np.unravel_index(int(np.argmin(np.where(tested, p, 2.0))), p.shape)
            s = _edge(size, valid.shape)
            worst, worst_t = (int(ti[k]) * s, int(tj[k]) * s, -1 if size == 0 else int(ch)), float(t[k, ch])
        out.append(Scale(size, share, pvalue, count, int((~low_ok).sum()), int((~high_ok).sum()), worst,
                         worst_t, t_map, p.ravel()))
    return tuple(out)


def combined(scales: tuple[Scale, ...]) -> float:
    """The family's p-value: n_scales times the smallest scale p (Bonferroni across scales)."""
    return min(1.0, len(scales) * min(s.pvalue for s in scales))
