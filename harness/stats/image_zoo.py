"""A calibration zoo of replica images: the pixel populations real renderers produce (smooth
noise, a light tracer's sparse hits, fireflies, zero-variance and float32-rounded renders) with
their exact expected image, and the same with planted biases, to measure how often
:func:`harness.stats.images.pixel_bias_test` cries wolf and how often it finds a real bias,
side by side with the peer (a t test per pixel-channel, Bonferroni over all of them).

    >>> table = measure(nulls(), seeds=range(200), replicas=16)

Each case draws (R, 32, 32, 3) replicas from numpy's ``default_rng(seed)``.  A pixel's value in
a replica is its expected value times a unit-mean random factor: normal (sd 0.1), Poisson(k)/k
(k hits of equal weight), or a compound Poisson sum of k expected hits with lognormal weights
(sigma 1 or 1.5), scaled to unit mean.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats as sps

from harness.stats.images import Reference, pixel_bias_test

__all__ = ["SHAPE", "SPP", "ZooImage", "nulls", "faults", "measure", "expected_image", "detectable"]

SHAPE = (32, 32, 3)
SPP = 64            # samples a zoo replica's pixel averages: every scale is tested (scales.MIN_SAMPLES)
_NORMAL_SD = 0.1


def expected_image() -> np.ndarray:
    """The exact image every null estimates: a smooth ramp from 0.05 to 1.05, tinted per channel."""
    h, w, _ = SHAPE
    yy, xx = np.mgrid[0:h, 0:w]
    return (0.2 + 0.8 * (yy + xx) / (h + w - 2))[:, :, None] * np.array([1.0, 0.6, 0.3]) + 0.05


Draw = Callable[[np.random.Generator, int], np.ndarray]   # (rng, replicas) -> unit-mean factors (R, h, w, c)


def _normal(rng: np.random.Generator, r: int) -> np.ndarray:
    return 1.0 + _NORMAL_SD * rng.standard_normal((r, *SHAPE))


def _poisson(hits: float) -> Draw:
    def draw(rng: np.random.Generator, r: int) -> np.ndarray:
        return rng.poisson(hits, (r, *SHAPE)) / hits
    return draw


def _compound(hits: float, sigma: float) -> Draw:
    def draw(rng: np.random.Generator, r: int) -> np.ndarray:
        n = rng.poisson(hits, (r, *SHAPE))
        weights = rng.lognormal(0.0, sigma, int(n.sum()))
        sums = np.bincount(np.repeat(np.arange(n.size), n.ravel()), weights=weights, minlength=n.size)
        return sums.reshape(n.shape) / (hits * math.exp(sigma * sigma / 2))
    return draw


def _constant(rng: np.random.Generator, r: int) -> np.ndarray:
    return np.ones((r, *SHAPE))


@dataclass(frozen=True)
class ZooImage:
    """One zoo case: ``draw(rng, replicas)`` gives (replica images, reference); ``fault`` says
    what is wrong ("" for an unbiased render)."""

    name: str
    factors: Draw
    fault: str = ""
    planted: Callable[[np.ndarray, int], np.ndarray] | None = None   # (images, replicas) -> biased images
    rendered_reference: bool = False    # the reference is 8 parts of 16 replicas' budget each
    float32: bool = False               # zero-variance render rounded to float32, half its pixels 1 ulp low
    nan: bool = False                   # one replica's pixel NaN: the verdict must be "invalid"

    @property
    def correct(self) -> bool:
        return not self.fault

    def draw(self, rng: np.random.Generator, replicas: int) -> tuple[np.ndarray, Reference]:
        truth = expected_image()
        if self.float32:
            f = truth.astype(np.float32)
            low = np.where(rng.random(SHAPE) < 0.5, np.nextafter(f, np.float32(0)), f)
            return np.repeat(low[None], replicas, axis=0).astype(np.float64), Reference.exact(truth)
        images = truth * self.factors(rng, replicas)
        if self.nan:
            images[0, 5, 7, 1] = np.nan
        if self.planted is not None:
            images = self.planted(images, replicas)
        if self.rendered_reference:   # each part the mean of 16 replicas' worth of samples
            parts = truth * np.stack([self.factors(rng, 16).mean(axis=0) for _ in range(8)])
            return images, Reference.from_parts(parts)
        return images, Reference.exact(truth)


def nulls() -> list[ZooImage]:
    """Unbiased renders of :func:`expected_image`, from smooth to a light tracer's sparsest."""
    out = [ZooImage("normal", _normal),
           ZooImage("normal, rendered reference", _normal, rendered_reference=True)]
    out += [ZooImage(f"poisson {k:g} hits", _poisson(k)) for k in (1, 3, 10, 30, 100)]
    out += [ZooImage(f"compound {k:g} hits, lognormal {s:g}", _compound(k, s))
            for k, s in ((3, 1.0), (10, 1.5), (100, 1.5))]
    out += [ZooImage("compound 3 hits, lognormal 1, rendered reference", _compound(3, 1.0),
                     rendered_reference=True),
            ZooImage("constant", _constant), ZooImage("float32, half 1 ulp low", _constant, float32=True),
            ZooImage("normal, one NaN", _normal, nan=True)]
    return out


def _pixel_se(replicas: int) -> np.ndarray:
    """A normal pixel's standard error of its replica mean (h, w, c)."""
    return _NORMAL_SD * expected_image() / math.sqrt(replicas)


def _region(k: float) -> Callable[[np.ndarray, int], np.ndarray]:
    def plant(images: np.ndarray, r: int) -> np.ndarray:
        out = images.copy()
        out[:, 8:16, 8:16] += k * _pixel_se(r)[8:16, 8:16]
        return out
    return plant


def _one_pixel(images: np.ndarray, r: int) -> np.ndarray:
    out = images.copy()
    out[:, 20, 5] += 10 * _pixel_se(r)[20, 5]
    return out


def _scaled(factor: float, region: bool) -> Callable[[np.ndarray, int], np.ndarray]:
    def plant(images: np.ndarray, r: int) -> np.ndarray:
        out = images.copy()
        if region:
            out[:, 8:16, 8:16] *= factor
        else:
            out *= factor
        return out
    return plant


def faults() -> list[ZooImage]:
    """Biased renders: a region 0.5 and 1 pixel standard errors off, one pixel 10 off, the whole
    image 0.5 % bright, and a light tracer's 8 x 8 region 20 % too bright."""
    return [ZooImage("normal", _normal, "8x8 region +0.5 pixel-SE", _region(0.5)),
            ZooImage("normal", _normal, "8x8 region +1 pixel-SE", _region(1.0)),
            ZooImage("normal", _normal, "one pixel +10 SE", _one_pixel),
            ZooImage("normal", _normal, "image +0.5 %", _scaled(1.005, False)),
            ZooImage("compound 3 hits, lognormal 1", _compound(3, 1.0), "8x8 region +20 %",
                     _scaled(1.2, True))]


def _peer_rejects(images: np.ndarray, reference: Reference, alpha: float) -> bool:
    """The peer: a t test per pixel-channel (Welch against a rendered reference's parts, Student
    against an exact one), Bonferroni over all pixel-channels."""
    with np.errstate(all="ignore"):
        if reference.parts is None:
            p = sps.ttest_1samp(images, reference.mean, axis=0).pvalue
        else:
            p = sps.ttest_ind(images, reference.parts, axis=0, equal_var=False).pvalue
    p = np.nan_to_num(p, nan=1.0)   # constant pixels: no evidence either way
    return bool(p.min() * p.size <= alpha)


def measure(cases: Iterable[ZooImage], seeds: Iterable[int], replicas: int, alpha: float = 0.01, *,
            peer: bool = False) -> pd.DataFrame:
    """Verdict counts of pixel_bias_test over ``seeds`` for each case at ``replicas``, the rate
    of "biased" with its 95 % Clopper-Pearson interval and the scales that rejected; with
    ``peer``, how often the peer rejects on the same images ("peer")."""
    seeds = list(seeds)
    rows = []
    for case in cases:
        verdicts, peers, scales = [], 0, {}
        for s in seeds:
            images, reference = case.draw(np.random.default_rng(s), replicas)
            b = pixel_bias_test(images, reference, SPP, alpha=alpha)
            verdicts.append(b.verdict)
            if b.verdict == "biased":
                scales[b.worst_scale.name] = scales.get(b.worst_scale.name, 0) + 1
            peers += peer and _peer_rejects(images, reference, alpha)
        k, n = verdicts.count("biased"), len(verdicts)
        ci = sps.binomtest(k, n).proportion_ci(0.95, method="exact")
        rows.append({"case": case.name, "fault": case.fault or "-", "replicas": replicas, "runs": n,
                     "biased": k, "inconclusive": verdicts.count("inconclusive"),
                     "consistent": verdicts.count("consistent"), "invalid": verdicts.count("invalid"),
                     "rate": k / n, "rate_lo": ci.low, "rate_hi": ci.high,
                     "rejecting scales": ", ".join(f"{name} {c}" for name, c in sorted(scales.items())),
                     **({"peer": peers} if peer else {})})
    return pd.DataFrame(rows)


def detectable(replicas: int, sizes: Iterable[int] = (1, 2, 4, 8, 16, 32), seeds: Iterable[int] = range(100),
               alpha: float = 0.01,
               steps: Iterable[float] = (2, 3, 4, 5, 6, 7, 8, 9, 10, 12, 16, 20)) -> pd.DataFrame:
    """The bias each scale detects with 80 % power: on normal replicas, one aligned square of
    ``size`` pixels (at rows and cols 0 .. size, all channels; 32 is the whole image) made
    k tile standard errors too bright (the tile's SE: a pixel's over size, independent pixels),
    k over ``steps``; per size the power at each k over ``seeds`` and the smallest k whose
    power reaches 80 % ("k80", NaN if none does), with the power at that k."""
    seeds = list(seeds)
    rows = []
    for size in sizes:
        powers = {}
        for k in steps:
            found = 0
            for s in seeds:
                images, reference = ZooImage("normal", _normal).draw(np.random.default_rng(s), replicas)
                images[:, :size, :size] += k * _pixel_se(replicas)[:size, :size] / size
                found += pixel_bias_test(images, reference, SPP, alpha=alpha).verdict == "biased"
            powers[k] = found / len(seeds)
            if powers[k] >= 0.8:
                break
        k80 = next((k for k, p in powers.items() if p >= 0.8), math.nan)
        rows.append({"size": size, "replicas": replicas, "k80": k80,
                     "power at k80": powers.get(k80, math.nan),
                     "powers": ", ".join(f"{k:g}: {p:.2f}" for k, p in powers.items())})
    return pd.DataFrame(rows)
