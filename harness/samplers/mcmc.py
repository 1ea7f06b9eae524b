"""The MCMC cross-check: a sampler against its claimed pdf without quadrature.

emcee draws from the claimed pdf in the equal-measure parameter space of the domain, and
two-sample tests compare those draws with the sampler's.  An independent check of the
cubature-based :func:`harness.samplers.check.check_sampler`, and one for pdfs where cubature
is impractical.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

import reference_estimators as rest

from harness.samplers.check import SamplerCheck, histogram
from harness.samplers.domains import Domain, as_domain
from harness.stats import holm
from harness.stats.results import Failure

__all__ = ["mcmc_crosscheck"]


def mcmc_crosscheck(sample: Callable[[np.ndarray], Any], pdf: Callable[[np.ndarray], np.ndarray],
                    domain: str | tuple | Domain, *, sample_count: int = 20_000, seed: int = 0,
                    alpha: float = 0.01, udim: int | None = None) -> SamplerCheck:
    """An independent check of ``sample`` against ``pdf`` without quadrature: draws from the
    claimed pdf by MCMC (emcee's affine-invariant ensemble in the equal-measure parameter
    space, thinned by the integrated autocorrelation time) and compares them with the
    sampler's draws by two-sample tests: Kolmogorov-Smirnov on each axis and a chi-square
    contingency test on an 8 x 8 (or 16-bin) grid, combined by Holm at ``alpha``.

    Its false-alarm rate holds when the thinned chain is close to independent draws (the
    thinning is by 2 tau); use it where quadrature is impractical (rough pdfs, many modes
    inside one cell) and as an independent check of the quadrature-based test.
    """
    import emcee

    dom = as_domain(domain)
    n = int(sample_count)
    rng = np.random.default_rng(seed)
    k = dom.k

    def log_q(sp: np.ndarray) -> np.ndarray:
        sp = np.atleast_2d(sp)
        ok = np.all((sp >= 0) & (sp <= 1), axis=1)
        out = np.full(sp.shape[0], -np.inf)
        if ok.any():
            v = np.asarray(pdf(dom.to_points(np.clip(sp[ok], 0, 1))), dtype=float).reshape(-1)
            with np.errstate(divide="ignore"):
                out[ok] = np.where(v > 0, np.log(np.maximum(v, 1e-300)), -np.inf)
        return out

    walkers = 32
    start = rng.random((walkers, k))
    sampler = emcee.EnsembleSampler(walkers, k, log_q, vectorize=True)
    sampler.random_state = np.random.RandomState(int(rng.integers(2**31))).get_state()  # reproducible chains
    steps = 2000
    state = sampler.run_mcmc(start, steps, progress=False)
    tau = float(np.max(sampler.get_autocorr_time(tol=0, quiet=True)))
    thin = max(1, int(math.ceil(2 * tau)))
    need = n // walkers + 1
    sampler.reset()
    sampler.run_mcmc(state, need * thin, progress=False)
    chain = sampler.get_chain(thin=thin, flat=True)[:n]

    u = rest.points(n, udim or dom.udim, seed=seed, case_id=0x3C3C)
    out = sample(u)
    x = np.asarray(out[0] if isinstance(out, tuple) else out, dtype=float)
    s, inside = dom.to_params(x)
    failures = []
    if not inside.all():
        failures.append(Failure("outside_domain", int((~inside).sum()), "points outside the domain",
                                tuple({"index": int(i)} for i in np.flatnonzero(~inside)[:5])))
    s = s[inside]
    tests = []
    for axis in range(k):
        r = stats.ks_2samp(s[:, axis], chain[:, axis])
        tests.append((f"KS two-sample s{axis}", r.statistic, 0, r.pvalue, "marginal mismatch"))
    shape = (16,) if k == 1 else (8, 8)
    a = histogram(np.clip(s, 0, 0.999999), shape).reshape(-1)
    b = histogram(np.clip(chain, 0, 0.999999), shape).reshape(-1)
    keep = (a + b) > 0
    chi = stats.chi2_contingency(np.vstack([a[keep], b[keep]]))
    tests.append(("contingency chi-square", chi.statistic, chi.dof, chi.pvalue,
                  "joint mismatch on a coarse grid"))
    table = pd.DataFrame(tests, columns=["test", "statistic", "df", "pvalue", "detects"])
    rejected, adjusted = holm(table["pvalue"].to_numpy(), alpha)
    table["adjusted"] = adjusted
    table.attrs["tau"], table.attrs["thin"] = tau, thin
    return SamplerCheck(not failures and not rejected.any(), float(adjusted.min()), alpha, n, table, failures,
                        (math.nan, math.nan))
