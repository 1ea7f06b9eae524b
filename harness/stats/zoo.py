"""A calibration zoo: correct and subtly wrong estimators with exact answers, written as
users write theirs (``contributions(u) -> Y`` over numpy arrays), to measure how often
:func:`harness.stats.check_unbiased` cries wolf and how often it catches a real bias.

    >>> table = measure(zoo(), seeds=range(200), sample_count=100_000)

gives, per estimator, the counts of "biased", "inconclusive" and "consistent" verdicts over
the seeds and the rate of "biased" with a Clopper-Pearson interval: the false-alarm rate for
correct estimators, the power for wrong ones.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import special
from scipy import stats as sps

import reference_estimators as rest

from harness.stats import batch_points, check_unbiased

__all__ = ["ZooEstimator", "zoo", "measure"]


@dataclass(frozen=True)
class ZooEstimator:
    name: str
    dim: int
    reference: float
    contributions: Callable[[np.ndarray], np.ndarray]
    fault: str = ""           # what is wrong; "" for a correct estimator
    heavy: bool = False       # heavy-tailed or rare-event contributions: "inconclusive" is acceptable

    @property
    def correct(self) -> bool:
        return not self.fault


def _gauss(x: np.ndarray) -> np.ndarray:
    return np.exp(-x * x)


def zoo() -> list[ZooEstimator]:
    """Estimators of I = integral of exp(-x^2) over [0, 1] (and a few heavy-tailed cases),
    each correct one beside a subtly wrong twin."""
    i_gauss = rest.integrand("gaussian").reference
    lin = rest.sampler("linear", a=1.0, b=0.37)
    cos = rest.sampler("cosine_hemisphere")
    ggx = rest.integrand("ggx_lobe")
    strata = 64

    def linear_is(scale: float) -> Callable[[np.ndarray], np.ndarray]:
        def y(u):
            x, p = lin.sample(u[:, 0])
            return _gauss(x) / (p * scale)
        return y

    def roulette(q: float, reweight: bool) -> Callable[[np.ndarray], np.ndarray]:
        def y(u):
            live = u[:, 1] < q
            return np.where(live, _gauss(u[:, 0]) / (q if reweight else 1.0), 0.0)
        return y

    def stratified(twice: bool) -> Callable[[np.ndarray], np.ndarray]:
        def y(u):
            x = (np.arange(strata) + u) / strata
            f = _gauss(x)
            total = f.sum(axis=1) + (f[:, 0] if twice else 0.0)  # a stratum counted twice
            return total / strata
        return y

    def mis(weight_error: float) -> Callable[[np.ndarray], np.ndarray]:
        def y(u):
            x1 = u[:, 0]                       # from the uniform technique, p1 = 1
            x2, p2_at_x2 = lin.sample(u[:, 1])
            p2_at_x1 = lin.pdf(x1)
            w1 = 1.0 / (1.0 + p2_at_x1)
            w2 = p2_at_x2 / (1.0 + p2_at_x2) * (1.0 + weight_error)  # weights sum to 1 + error
            return w1 * _gauss(x1) + w2 * _gauss(x2) / p2_at_x2
        return y

    def snis(batch: int) -> Callable[[np.ndarray], np.ndarray]:
        def y(u):
            x, p = lin.sample(u.reshape(-1))
            num = (_gauss(x) / p).reshape(-1, batch).sum(axis=1)
            den = (1.0 / p).reshape(-1, batch).sum(axis=1)
            return num / den
        return y

    def ggx_cosine(u):
        w, p = cos.sample(u)
        return ggx.eval(w) / p

    def half_cauchy_exp(u):
        x = -np.log1p(-u[:, 0])
        return 2 / (math.pi * (1 + x * x)) * np.exp(x)

    peak_sigma = 1e-4
    peak_ref = sps.norm.cdf(0.7 / peak_sigma) - sps.norm.cdf(-0.3 / peak_sigma)

    def pareto(index: float, scale: float = 0.0) -> Callable[[np.ndarray], np.ndarray]:
        """Pareto(index) contributions, of mean 1 (or of minimum ``scale``)."""
        xm = scale or (index - 1) / index
        return lambda u: xm * u[:, 0] ** (-1 / index)

    def clamped(y: Callable[[np.ndarray], np.ndarray], c: float) -> Callable[[np.ndarray], np.ndarray]:
        return lambda u: np.minimum(y(u), c)

    def truncated(y: Callable[[np.ndarray], np.ndarray], c: float) -> Callable[[np.ndarray], np.ndarray]:
        def z(u):
            v = y(u)
            return np.where(v <= c, v, 0.0)
        return z

    def pareto_clamp(index: float, relative_bias: float) -> float:
        """The clamp of mean-1 Pareto(index) contributions that lowers their mean by ``relative_bias``:
        E[(Y - c)+] = xm^a c^(1-a) / (a - 1)."""
        xm = (index - 1) / index
        return (relative_bias * (index - 1) / xm ** index) ** (1 / (1 - index))

    def rare(p: float) -> Callable[[np.ndarray], np.ndarray]:
        return lambda u: (u[:, 0] < p) / p

    def lognormal(sigma: float) -> Callable[[np.ndarray], np.ndarray]:
        return lambda u: np.exp(sigma * special.ndtri(u[:, 0]) - sigma * sigma / 2)

    return [
        ZooEstimator("uniform", 1, i_gauss, lambda u: _gauss(u[:, 0])),
        ZooEstimator("importance:linear", 1, i_gauss, linear_is(1.0)),
        ZooEstimator("roulette(q=0.5)", 2, i_gauss, roulette(0.5, True)),
        ZooEstimator(f"stratified({strata})", strata, i_gauss, stratified(False)),
        ZooEstimator("mis_balance(uniform,linear)", 2, i_gauss, mis(0.0)),
        ZooEstimator("hit_or_miss(c=1)", 2, i_gauss,
                     lambda u: (u[:, 1] < _gauss(u[:, 0])).astype(float)),
        ZooEstimator("peak(sigma=1e-4)/uniform", 1, peak_ref,
                     lambda u: sps.norm.pdf(u[:, 0], 0.3, peak_sigma)),
        ZooEstimator("ggx(alpha=0.01)/cosine", 2, 1.0, ggx_cosine),
        ZooEstimator("singularity/uniform", 1, 1.0, lambda u: 0.5 / np.sqrt(u[:, 0]), heavy=True),
        ZooEstimator("pareto(3/2)/uniform", 1, 1.0, lambda u: u[:, 0] ** (-2 / 3) / 3, heavy=True),
        ZooEstimator("half_cauchy/exponential", 1, 1.0, half_cauchy_exp, heavy=True),
        ZooEstimator("pareto(1.1)", 1, 1.0, pareto(1.1), heavy=True),
        ZooEstimator("pareto(2.5)", 1, 1.0, pareto(2.5), heavy=True),
        ZooEstimator("lognormal(sigma=3)", 1, 1.0, lognormal(3.0), heavy=True),
        ZooEstimator("rare(p=3e-5)", 1, 1.0, rare(3e-5), heavy=True),   # no hit in 5 % of runs at 1e5
        ZooEstimator("rare(p=3e-4)", 1, 1.0, rare(3e-4)),
        # heavy tails clamped or truncated by design: the reference is that of the clamped or truncated
        # integrand (E[min(Y, c)], E[Y 1{Y <= c}]), so "biased" is a false alarm
        ZooEstimator("pareto(1.5) clamped at 1e3 by design", 1, 3.0 - 2 / math.sqrt(1e3),
                     clamped(pareto(1.5, 1.0), 1e3), heavy=True),
        ZooEstimator("pareto(1.5) truncated at 1e3 by design", 1, 3.0 - 3 / math.sqrt(1e3),
                     truncated(pareto(1.5, 1.0), 1e3), heavy=True),
        ZooEstimator("lognormal(sigma=3) clamped at 1e3 by design", 1, lognormal_clamped_mean(3.0, 1e3),
                     clamped(lognormal(3.0), 1e3), heavy=True),
        # subtly wrong twins
        ZooEstimator("importance:linear, pdf 1% too large", 1, i_gauss, linear_is(1.01), "pdf off by 1 %"),
        ZooEstimator("importance:linear, pdf 0.1% too large", 1, i_gauss, linear_is(1.001),
                     "pdf off by 0.1 %"),
        ZooEstimator("roulette(q=0.99) without 1/q", 2, i_gauss, roulette(0.99, False), "missing 1/q"),
        ZooEstimator("roulette(q=0.999) without 1/q", 2, i_gauss, roulette(0.999, False), "missing 1/q"),
        ZooEstimator(f"stratified({strata}), a stratum twice", strata, i_gauss, stratified(True),
                     "stratum counted twice"),
        ZooEstimator("mis_balance, weights sum to 1.02", 2, i_gauss, mis(0.02),
                     "MIS weights do not sum to one"),
        ZooEstimator("uniform clamped at 0.99", 1, i_gauss, lambda u: np.minimum(_gauss(u[:, 0]), 0.99),
                     "clamping"),
        ZooEstimator("hit_or_miss(c=0.95), bound violated", 2, i_gauss,
                     lambda u: 0.95 * (u[:, 1] * 0.95 < _gauss(u[:, 0])), "rejection bound violated"),
        ZooEstimator("snis(b=16)", 16, i_gauss, snis(16), "self-normalised (ratio) estimator"),
        ZooEstimator("singularity/uniform x 1.01", 1, 1.0, lambda u: 0.505 / np.sqrt(u[:, 0]),
                     "1 % too large", heavy=True),
        *[ZooEstimator(f"pareto(2.5) clamped, bias -{b:g} %", 1, 1.0,
                       clamped(pareto(2.5), pareto_clamp(2.5, b / 100)), "firefly clamp", heavy=True)
          for b in (1.0, 0.25, 0.1)],
        ZooEstimator("pareto(1.5) truncated at 1e3", 1, 3.0, truncated(pareto(1.5, 1.0), 1e3),
                     "tail truncated", heavy=True),
        ZooEstimator("pareto(1.5) clamped at 1e3", 1, 3.0, clamped(pareto(1.5, 1.0), 1e3), "firefly clamp",
                     heavy=True),
        ZooEstimator("lognormal(sigma=3) clamped at 1e3", 1, 1.0, clamped(lognormal(3.0), 1e3),
                     "firefly clamp", heavy=True),
        ZooEstimator("rare(p=3e-4) x 1.1", 1, 1.0, lambda u: (u[:, 0] < 3e-4) / 3e-4 * 1.1, "10 % too large"),
    ]


def lognormal_clamped_mean(sigma: float, c: float) -> float:
    """E[min(Y, c)] for Y = exp(sigma Z - sigma^2 / 2), Z standard normal (so E[Y] = 1)."""
    z = (math.log(c) + sigma * sigma / 2) / sigma
    return float(sps.norm.cdf(z - sigma) + c * sps.norm.sf(z))


def measure(estimators: Iterable[ZooEstimator], seeds: Iterable[int], sample_count: int,
            alpha: float = 0.01, *, ttest: bool = False) -> pd.DataFrame:
    """Verdict counts of check_unbiased over ``seeds`` for each estimator, with the rate of
    "biased" and its 95 % Clopper-Pearson interval.  ``ttest`` adds, as "ttest", how often
    ``scipy.stats.ttest_1samp`` rejects at ``alpha`` on the same contributions (the peer:
    a plain t-test over all n of them)."""
    seeds = list(seeds)
    rows = []
    for e in estimators:
        verdicts = [check_unbiased(e.contributions, e.dim, e.reference, sample_count=sample_count, seed=s,
                                   alpha=alpha).verdict for s in seeds]
        k, n = verdicts.count("biased"), len(verdicts)
        ci = sps.binomtest(k, n).proportion_ci(0.95, method="exact")
        row = {"estimator": e.name, "fault": e.fault or "-", "heavy": e.heavy, "runs": n, "biased": k,
               "inconclusive": verdicts.count("inconclusive"), "consistent": verdicts.count("consistent"),
               "invalid": verdicts.count("invalid"), "rate": k / n, "rate_lo": ci.low, "rate_hi": ci.high}
        if ttest:
            row["ttest"] = sum(_ttest_rejects(e, sample_count, s, alpha) for s in seeds)
        rows.append(row)
    return pd.DataFrame(rows)


def _ttest_rejects(e: ZooEstimator, n: int, seed: int, alpha: float) -> bool:
    """scipy.stats.ttest_1samp at ``alpha`` on the contributions check_unbiased drew for ``seed``."""
    y = np.concatenate([e.contributions(u) for _, _, u in batch_points(n, e.dim, seed=seed, batches=64)])
    with np.errstate(all="ignore"):
        p = sps.ttest_1samp(y, e.reference).pvalue
    return bool(p < alpha)   # NaN (all contributions equal): no rejection
