"""The MCMC cross-check: a sampler against its claimed pdf without quadrature.

Two emcee runs draw from the claimed density in the equal-measure parameter space s in
[0, 1]^k of the domain (:mod:`harness.samplers.domains`), and two-sample tests compare those
draws with the sampler's:

1. Exploration.  An ensemble whose moves (Goodman & Weare's 2010 affine-invariant stretch move
   and an independence move from a kernel density estimate of the other half of the ensemble,
   acceptance vectorised) find where q lives, sharp lobes and singularities included.  Its
   draws are not tested: each walker's proposal is built from the others, so walkers end up
   near one another and their draws are dependent in a way no per-walker autocorrelation time
   shows (measured: 11 false alarms in 390 checks at alpha = 0.01 when they were tested).
2. Independent chains.  Every walker then runs a Metropolis-Hastings chain of its own with a
   independence proposal frozen from the exploration (an adaptive kernel density estimate of
   its thinned draws mixed with the uniform density, :class:`_FrozenProposal`).
   Nothing couples the walkers, so draws of different walkers are independent once each has
   forgotten its start; the draws tested are those of this run.

An independent check of the cubature-based
:func:`harness.samplers.check.check_sampler`, and one for pdfs where cubature is impractical.

The target is q(s) = pdf(x(s)) |dx/ds| (``Domain.jacobian``): a constant |D| on the
interval, square, disk, hemisphere and sphere, 1 / (1 - s)^2 on the half line.  The chain
needs q only up to a constant factor, so it draws from pdf / P where the pdf integrates to P:
it cannot see a normalisation fault (check_sampler's deterministic check does), and the
samples a sampler produces when it fails to produce some (NaN rows) follow the same pdf / P.

Chain length.  Each run grows in rounds, each at least 1.5 times as long as the last (or as
long as the current estimate of tau asks for, with 10 % to spare), until emcee's integrated
autocorrelation time tau (Sokal's window, c = 5; the largest over the coordinates and log q)
is estimated from a post-burn-in chain at least ``tol`` tau long (emcee's own check,
``emcee.autocorr.integrated_time``; 20 for the exploration, 50 for the independent chains) and
the thinned chain holds the draws wanted (512 kernel centres; the sample count), or until the
step cap: then the result is inconclusive ("chain too short: ...", with tau and the steps run).
"""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy import special, stats

import reference_estimators as rest

from harness.samplers.calls import checked_pdf, checked_sample_count, drawn_points, uniforms
from harness.samplers.check import histogram
from harness.samplers.domains import Domain, as_domain
from harness.samplers.reported import reported_pdf_failure
from harness.samplers.result import SamplerCheck
from harness.stats import holm
from harness.stats.results import Failure
from harness.stats.validate import count, integer_in, level

__all__ = ["MCMC_CASE", "mcmc_crosscheck"]

#: The stream (case id) the cross-check draws the sampler's canonical uniforms from.
MCMC_CASE = 0x3C3C
#: emcee's default: the chain the draws come from must be at least TOL integrated
#: autocorrelation times long.
TOL = 50
#: The exploring ensemble's chain must be at least EXPLORE_TOL autocorrelation times long.
EXPLORE_TOL = 20
#: Share of the exploring ensemble's steps that are stretch moves (the rest: kernel-density
#: independence moves).
STRETCH = 0.25
#: At most this many kernel centres (thinned draws of the exploring ensemble) in the frozen proposal.
CENTRES = 512
#: Share of the frozen proposal that is uniform on [0, 1]^k: a mode the exploring ensemble
#: missed is still proposed, at this rate times its share of the parameter space.
DEFENSIVE = 0.1
#: The frozen proposal's kernel at a centre is as wide as the distance to its NEIGHBOURS-th
#: nearest other centre.
NEIGHBOURS = 8
COLUMNS = ["test", "statistic", "df", "pvalue", "detects"]


def mcmc_crosscheck(sample: Callable[[np.ndarray], Any], pdf: Callable[[np.ndarray], np.ndarray],
                    domain: str | tuple | Domain, *, sample_count: int = 20_000, seed: int = 0,
                    alpha: float = 0.01, udim: int | None = None, max_steps: int = 10_000,
                    walkers: int | None = None) -> SamplerCheck:
    """Test that ``sample`` draws what ``pdf`` claims by comparing ``sample_count`` of its
    points with as many draws from the claimed pdf by MCMC, without quadrature.

    ``sample``, ``pdf``, ``domain``, ``udim``: as for :func:`harness.samplers.check_sampler`
    (points (N,) on an interval or half line, (N, 2) on the square and disk, unit vectors
    (N, 3) on the hemisphere and sphere; densities per unit length, area or solid angle; a
    sampler may return (points, pdf values)).  The chain runs on q(s) = pdf(x(s)) |dx/ds| in
    the domain's parameter space (see the module docstring), so only the shape of the pdf is
    tested, not its normalisation.

    Tests, combined by Holm at ``alpha`` (the false-alarm rate): a two-sample
    Kolmogorov-Smirnov test on each parameter axis (a marginal shifted or stretched) and a
    chi-square contingency test on an 8 x 8 grid (16 bins on a line) of equal-measure cells,
    cells with fewer than 10 points of both samples together pooled into one (a joint misfit).
    Their level rests on the tested draws being independent draws from q.  The exploring
    ensemble starts from q-weighted resampled uniform points; the independent chains start
    where it ended.  In each run the first max(5 tau, T / 5) of its T steps are burn-in and
    the rest is thinned by ceil(2 tau) (the lag-2 tau correlation of an AR(1)-like chain is
    about e^-4); the independent chains' walkers share nothing but the frozen proposal, so
    draws of different walkers are independent.  A mode neither run visits is not in tau (the
    proposal's uniform share still proposes it).  Measured (benchmarks/mcmc_calibration.py,
    2000 samples, alpha = 0.01, seeds 0..199 of each of the 15 correct zoo samplers on every
    domain): 26 false alarms in 3000 checks (0.87 %; at most 5 of 200 on one sampler), 4
    inconclusive; the exploring ensemble's own draws, tested before, gave 11 in 390.  Power is
    low (the zoo's mutants: at most 1 of 20 caught at 2000 samples): a second opinion beside
    check_sampler, not a replacement.

    Each run grows in rounds (at least 1.5 times longer each, see the module docstring); at
    ``max_steps`` steps per walker and run it stops: with at least min(sample_count, 1000)
    draws and 50 tau the test runs on what there is, else the result is inconclusive
    (``inconclusive`` = "chain too short: ...", ``pvalue`` 1, ``passed`` False).  ``walkers``
    (even, >= 8): default sample_count / 32, between 32 and 512.  pdf evaluations: walkers x
    steps of both runs (in ``tests.attrs``: the independent chains' tau, thin, steps, burn_in,
    walkers, draws; the exploration's as explore_tau, explore_steps, ...).

    Deterministic failures: sampler points outside the domain, where the pdf is 0, NaN or
    negative, a reported pdf that differs from ``pdf``, NaN or negative pdf values met by the
    chain, fewer than 1000 points produced.  A sampler that fails to produce some samples (NaN
    rows) is tested on the samples it produced (they follow pdf / P, as the chain's draws do);
    the tests table then has a "failed samples" row (its count; not a test here: the chain
    gives no P; :func:`harness.samplers.check_with_missing` tests it).
    """
    import emcee

    dom = as_domain(domain)
    n = checked_sample_count(sample_count)
    alpha = level(alpha, "alpha")
    max_steps = count(max_steps, "max_steps")
    nw = 2 * int(np.clip(-(-n // 64), 16, 256)) if walkers is None else integer_in(walkers, "walkers", 8)
    if nw % 2:
        raise ValueError(f"'walkers' must be an even number >= 8, got {walkers!r}")
    pdf = checked_pdf(pdf)
    rng = np.random.default_rng([seed, MCMC_CASE])
    log_q, bad_count = _log_target(pdf, dom)

    # the sampler's points first: a user error surfaces before the chain runs
    u = uniforms(n, udim, dom, seed, MCMC_CASE)
    x, reported = drawn_points(sample, u, dom)
    failures, s, missing = _sampler_failures(x, reported, u, pdf, dom)

    explore = _Chain(emcee, log_q, dom.k, nw, rng, [(_stretch_move(emcee, log_q), STRETCH),
                                                    (_kde_move(emcee, log_q), 1 - STRETCH)])
    explore.start(_initial(log_q, dom.k, nw, rng))
    centres, info = _grow(explore, CENTRES, EXPLORE_TOL, max_steps)
    draws = centres
    if not isinstance(centres, str):
        proposal = _FrozenProposal(centres)
        chains = _Chain(emcee, log_q, dom.k, nw, rng, [emcee.moves.MHMove(proposal.propose)])
        chains.start(explore.sampler.get_last_sample().coords)
        draws, chain_info = _grow(chains, n, TOL, max_steps)
        info = {**{f"explore_{k}": v for k, v in info.items()}, **chain_info,
                "pdf_evaluations": info["pdf_evaluations"] + chain_info["pdf_evaluations"]}
    if bad_count[0]:
        failures.append(Failure("bad_pdf", bad_count[0], "pdf NaN or negative where the chain evaluated it"))

    import pandas as pd  # deferred, as in harness.suite.kind.Outcome.frame
    if isinstance(draws, str):  # chain too short
        table = pd.DataFrame([], columns=COLUMNS + ["adjusted"])
        table.attrs.update(info)
        return SamplerCheck(False, 1.0, alpha, n, table, failures, (math.nan, math.nan), inconclusive=draws)
    if s.shape[0] < 1000:
        table = pd.DataFrame([], columns=COLUMNS + ["adjusted"])
        table.attrs.update(info)
        return SamplerCheck(False, 0.0 if failures else 1.0, alpha, n, table, failures, (math.nan, math.nan))
    tests = []
    for axis in range(dom.k):
        r = stats.ks_2samp(s[:, axis], draws[:, axis])
        tests.append((f"KS two-sample s{axis}", float(r.statistic), 0, float(r.pvalue), "marginal mismatch"))
    shape = (16,) if dom.k == 1 else (8, 8)
    top = np.nextafter(1.0, 0.0)
    a = histogram(np.clip(s, 0, top), shape).reshape(-1)
    b = histogram(np.clip(draws, 0, top), shape).reshape(-1)
    keep = (a + b) >= 10  # cells expecting < 5 a row are pooled into one
    a, b = np.append(a[keep], a[~keep].sum()), np.append(b[keep], b[~keep].sum())
    a, b = a[(a + b) > 0], b[(a + b) > 0]
    if a.size > 1:
        chi = stats.chi2_contingency(np.vstack([a, b]), correction=False)
        tests.append(("contingency chi-square", float(chi.statistic), int(chi.dof), float(chi.pvalue),
                      "joint mismatch on a coarse grid"))
    table = pd.DataFrame(tests, columns=COLUMNS)
    rejected, adjusted = holm(np.nan_to_num(table["pvalue"].to_numpy(dtype=float), nan=0.0), alpha)
    table["adjusted"] = adjusted
    if missing:
        table.loc[len(table)] = ("failed samples", float(missing), 0, 1.0,
                                 "NaN rows left out (not tested: MCMC gives no normalisation)", 1.0)
    table.attrs.update(info)
    passed = not failures and not rejected.any()
    return SamplerCheck(passed, float(adjusted.min()), alpha, n, table, failures, (math.nan, math.nan))


def _log_target(pdf: Callable[[np.ndarray], np.ndarray],
                dom: Domain) -> tuple[Callable[[np.ndarray], np.ndarray], list[int]]:
    """log q(s) = log pdf(x(s)) + log |dx/ds| (-inf outside [0, 1]^k, on the half line at
    s = 1, where the pdf is 0, infinite (an integrable singularity hit exactly) or bad), and
    a one-element counter of NaN or negative pdf values met."""
    bad = [0]

    def log_q(sp: np.ndarray) -> np.ndarray:
        sp = np.atleast_2d(sp)
        ok = np.all((sp >= 0) & (sp <= 1), axis=1)
        if dom.kind == "half_line":
            ok &= sp[:, 0] < 1
        out = np.full(sp.shape[0], -np.inf)
        if ok.any():
            si = sp[ok]
            v = pdf(dom.to_points(si))
            jac = np.broadcast_to(np.asarray(dom.jacobian(si), dtype=float), v.shape)
            bad[0] += int(np.sum(np.isnan(v) | (v < 0)))
            good = np.isfinite(v) & (v > 0) & np.isfinite(jac) & (jac > 0)
            with np.errstate(divide="ignore", invalid="ignore"):
                out[ok] = np.where(good, np.log(np.where(good, v, 1.0)) + np.log(np.where(good, jac, 1.0)),
                                   -np.inf)
        return out

    return log_q, bad


def _initial(log_q: Callable[[np.ndarray], np.ndarray], k: int, nw: int,
             rng: np.random.Generator) -> np.ndarray:
    """Starting walkers: uniform candidates resampled in proportion to q (with replacement),
    each nudged by 1e-6 so no two coincide (a stretch move between equal walkers is stuck);
    roughly distributed as q already, so burn-in is short.  Raises if q is 0 everywhere."""
    cand = rng.random((max(64 * nw, 1 << 15), k))
    lq = log_q(cand)
    fin = np.isfinite(lq)
    if not fin.any():
        raise ValueError("the pdf is 0 (or not finite) at all of 32768 uniform points of the domain; "
                         "the MCMC cross-check needs a pdf positive somewhere")
    w = np.where(fin, np.exp(lq - lq[fin].max()), 0.0)
    pick = cand[rng.choice(cand.shape[0], nw, p=w / w.sum())]
    for _ in range(100):
        moved = np.clip(pick + 1e-6 * rng.standard_normal(pick.shape), 0, 1)
        ok = np.isfinite(log_q(moved))
        pick[ok] = moved[ok]
        if ok.all():
            break
    return pick


_Proposal = Callable[[Any, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def _red_blue_move(emcee: Any, log_q: Callable[[np.ndarray], np.ndarray], half_proposal: _Proposal) -> Any:
    """An emcee move that updates the ensemble in two random halves, each from the other (held
    fixed, so every half-update leaves q invariant): ``half_proposal(random, s, c)`` proposes Y
    for the moving walkers s from the complement c and returns (Y, log of the proposal's
    Metropolis-Hastings factor); acceptance is vectorised over the walkers."""

    class RedBlue(emcee.moves.StretchMove):
        def propose(self, model: Any, state: Any) -> tuple[Any, np.ndarray]:
            nw = state.coords.shape[0]
            accepted = np.zeros(nw, dtype=bool)
            halves = np.arange(nw) % 2
            model.random.shuffle(halves)
            for half in (0, 1):
                mine = halves == half
                y, log_factor = half_proposal(model.random, state.coords[mine], state.coords[~mine])
                lq = log_q(y)
                with np.errstate(invalid="ignore"):
                    ratio = lq - state.log_prob[mine] + log_factor
                accepted[mine] = np.nan_to_num(ratio, nan=-np.inf) > np.log(model.random.rand(y.shape[0]))
                state = self.update(state, emcee.State(y, log_prob=lq), accepted, mine)
            return state, accepted

    return RedBlue()


def _stretch_move(emcee: Any, log_q: Callable[[np.ndarray], np.ndarray], a: float = 2.0) -> Any:
    """emcee's stretch move (a = 2, red-blue halves) with its acceptance vectorised: emcee's own
    loops over walkers in Python (15 us a walker step), this one costs the same for 1000
    walkers as for 32, so the ensemble can be large.  Same proposal and acceptance as
    ``emcee.moves.StretchMove``: Y = X_c + z (X_j - X_c), z ~ g(z) on [1/a, a], accepted with
    probability min(1, z^(k-1) q(Y) / q(X_j))."""
    def propose(random: Any, s: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        z = ((a - 1.0) * random.rand(s.shape[0]) + 1) ** 2 / a
        other = c[random.randint(c.shape[0], size=s.shape[0])]
        return other - (other - s) * z[:, None], (s.shape[1] - 1) * np.log(z)

    return _red_blue_move(emcee, log_q, propose)


def _kde_move(emcee: Any, log_q: Callable[[np.ndarray], np.ndarray]) -> Any:
    """An independence proposal from a Gaussian kernel density estimate of the complementary
    half of the ensemble (as ``emcee.moves.KDEMove``, with a diagonal bandwidth by Silverman's
    robust rule), its Metropolis-Hastings ratio q(Y) g(X) / (q(X) g(Y)) vectorised.  Where the
    ensemble already looks like q, it decorrelates a walker in a few steps (the stretch move
    alone needs 20-100)."""
    def propose(random: Any, s: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        h = _bandwidth(c)
        y = c[random.randint(c.shape[0], size=s.shape[0])] + h * random.randn(*s.shape)
        return y, _log_kernel_sum(s, c, h) - _log_kernel_sum(y, c, h)

    return _red_blue_move(emcee, log_q, propose)


def _grow(chain: _Chain, n: int, tol: float, max_steps: int) -> tuple[np.ndarray | str, dict[str, Any]]:
    """Run ``chain`` in rounds until :meth:`_Chain.draws` gives ``n`` draws from a chain ``tol``
    autocorrelation times long, or the step cap ``max_steps`` per walker: each round at least
    1.5 times as long as the last (or what the current estimate of tau asks for, with 10 % to
    spare).  Returns (draws, info) or ("chain too short: ...", info)."""
    steps, cap = 0, int(max_steps)
    target = min(cap, max(250, 4 * math.ceil(n / chain.nw)))
    while True:
        chain.run(target - steps)
        steps = target
        result = chain.draws(n, tol, final=steps >= cap)
        if isinstance(result, tuple):
            return result
        target = min(cap, max(3 * steps // 2, math.ceil(1.1 * result)))


class _FrozenProposal:
    """The independent chains' proposal, fixed before they start: a sample-point adaptive
    kernel density estimate of the exploring ensemble's thinned draws c_j (a Gaussian kernel
    at each, in coordinates scaled by each axis' robust spread, its width there the distance to
    the ``NEIGHBOURS``-th nearest other draw: narrow in a sharp lobe, wide in a sparse tail,
    where a fixed width leaves gaps in which q / g is large and a walker sticks), mixed with
    the uniform density on [0, 1]^k (weight ``DEFENSIVE``).  Fixed, so every walker is a
    Markov chain of its own: walkers that ran from different starts are independent, which the
    ensemble's moves (each walker's proposal built from the others) do not give."""

    def __init__(self, centres: np.ndarray):
        m, k = centres.shape
        self.scale = _bandwidth(centres) * m ** (1.0 / (k + 4)) / 0.9  # a robust spread per axis
        self.centres = centres / self.scale
        d2 = _squared_distances(self.centres, self.centres)
        nearest = np.sort(d2, axis=1)[:, min(NEIGHBOURS, m - 1)]
        self.h = np.sqrt(np.maximum(nearest, 1e-24))  # in units of the axes' spreads
        self.log_weight = (-0.5 * k * math.log(2 * math.pi) - k * np.log(self.h) - math.log(m)
                           - float(np.sum(np.log(self.scale))))

    def log_density(self, p: np.ndarray) -> np.ndarray:
        """log g(p) at points p (N, k) of [0, 1]^k (g integrates to 1 over R^k)."""
        d2 = _squared_distances(p / self.scale, self.centres)
        kde = special.logsumexp(self.log_weight[None, :] - 0.5 * d2 / (self.h * self.h)[None, :], axis=1)
        return np.logaddexp(math.log1p(-DEFENSIVE) + kde, math.log(DEFENSIVE))

    def propose(self, coords: np.ndarray, random: Any) -> tuple[np.ndarray, np.ndarray]:
        """emcee's ``MHMove`` proposal: Y ~ g for every walker, and log g(X) - log g(Y), the
        Metropolis-Hastings factor of an independence proposal."""
        nw, k = coords.shape
        j = random.randint(self.centres.shape[0], size=nw)
        y = (self.centres[j] + self.h[j, None] * random.randn(nw, k)) * self.scale
        uniform = random.rand(nw) < DEFENSIVE
        y[uniform] = random.rand(int(uniform.sum()), k)
        return y, self.log_density(coords) - self.log_density(y)


def _squared_distances(p: np.ndarray, c: np.ndarray) -> np.ndarray:
    """|p_i - c_j|^2 for points p (N, k) and c (M, k), as an (N, M) array (never negative)."""
    return np.maximum((p * p).sum(axis=1)[:, None] + (c * c).sum(axis=1)[None, :] - 2.0 * (p @ c.T), 0.0)


def _bandwidth(c: np.ndarray) -> np.ndarray:
    """A diagonal Gaussian kernel bandwidth for the points c (M, k): Silverman's robust rule."""
    iqr = np.subtract(*np.percentile(c, [75, 25], axis=0)) / 1.349
    spread = np.where(iqr > 0, np.minimum(c.std(axis=0), iqr), c.std(axis=0))
    return np.maximum(0.9 * spread * c.shape[0] ** (-1.0 / (c.shape[1] + 4)), 1e-12)


def _log_kernel_sum(p: np.ndarray, c: np.ndarray, h: np.ndarray) -> np.ndarray:
    """log sum_j exp(-|(p_i - c_j) / h|^2 / 2) for points p (N, k), centres c (M, k)."""
    ph, ch = p / h, c / h
    e = (ph @ ch.T) - 0.5 * (ch * ch).sum(axis=1)[None, :] - 0.5 * (ph * ph).sum(axis=1)[:, None]
    return special.logsumexp(e, axis=1)


class _Chain:
    """An emcee ensemble with the given moves, grown in rounds, and its draws once the chain is
    long enough."""

    def __init__(self, emcee: Any, log_q: Callable[[np.ndarray], np.ndarray], k: int, nw: int,
                 rng: np.random.Generator, moves: list[tuple[Any, float]]):
        self.emcee, self.nw = emcee, nw
        self.sampler = emcee.EnsembleSampler(nw, k, log_q, vectorize=True, moves=moves)
        self.sampler.random_state = np.random.RandomState(int(rng.integers(2**31))).get_state()
        self.state: Any = None

    def start(self, walkers: np.ndarray) -> None:
        self.state = walkers

    def run(self, steps: int) -> None:
        if steps > 0:
            self.state = self.sampler.run_mcmc(self.state, steps, progress=False)

    def _tau(self, chain: np.ndarray, logp: np.ndarray, tol: float) -> float:
        """emcee's integrated autocorrelation time, the largest over the coordinates and log q
        (log q left out where some walker's is constant: a walker moving inside a step of a
        piecewise-constant pdf); inf where some walker never moved (emcee's estimate would be
        NaN there, and a NaN read as 'no correlation' passed a stuck chain)."""
        if np.any(np.ptp(chain, axis=0) == 0):
            return math.inf
        if np.all(np.ptp(logp, axis=0) > 0):
            chain = np.concatenate([chain, logp[:, :, None]], axis=2)
        return float(np.max(self.emcee.autocorr.integrated_time(chain, tol=tol)))

    def draws(self, n: int, tol: float, *, final: bool) -> tuple[np.ndarray | str, dict[str, Any]] | int:
        """(draws (m, k), info) when the chain is long enough (its post-burn-in part at least
        ``tol`` tau, thinned by 2 tau, holds ``n`` draws), ("chain too short: ...", info) when it
        is not and ``final``, else the steps the current estimate of tau asks for."""
        chain, logp = self.sampler.get_chain(), self.sampler.get_log_prob()
        steps = chain.shape[0]
        burn = steps // 5
        info = {"steps": steps, "walkers": self.nw, "pdf_evaluations": steps * self.nw, "burn_in": burn}
        tau = self._tau(chain[burn:], logp[burn:], tol=0)
        if tau == math.inf:
            if not final:
                return 2 * steps
            info.update(tau=tau, thin=math.nan, draws=0)
            return (f"chain too short: a walker never moved in the last {steps - burn} of {steps} steps of "
                    f"{self.nw} walkers (every proposal rejected), the cap 'max_steps'"), info
        burn = max(burn, min(math.ceil(5 * tau), steps - 1))
        info["burn_in"] = burn
        try:
            tau = self._tau(chain[burn:], logp[burn:], tol=tol)
        except self.emcee.autocorr.AutocorrError as e:
            tau = float(np.nanmax(e.tau))
            if not final:
                return math.ceil(tol * tau * 1.25)
            info.update(tau=tau, thin=math.nan, draws=0)
            return (f"chain too short: integrated autocorrelation time tau ~ {tau:.3g} steps needs a "
                    f"post-burn-in chain of {tol:g} tau = {tol * tau:.0f} steps (emcee's check); ran {steps} "
                    f"steps of {self.nw} walkers ({steps - burn} after burn-in), the cap 'max_steps'"), info
        if tau == math.inf:  # a walker stuck after the longer burn-in: run longer
            return 2 * steps if not final else (f"chain too short: a walker never moved after burn-in "
                                                f"({steps} steps of {self.nw} walkers), the cap 'max_steps'",
                                                {**info, "tau": tau, "thin": math.nan, "draws": 0})
        thin = max(1, math.ceil(2 * tau))
        kept = chain[burn:][::-1][::thin][::-1]  # the last step always kept
        m = kept.shape[0] * self.nw
        info.update(tau=tau, thin=thin, draws=min(m, n))
        if m < n and not final:
            return math.ceil(1.25 * math.ceil(n / self.nw) * thin)
        if m < min(n, 1000):
            return (f"chain too short: {m} thinned draws (tau ~ {tau:.3g}, thinned by {thin}) from {steps} "
                    f"steps of {self.nw} walkers, fewer than {min(n, 1000)}, the cap 'max_steps'"), info
        return kept.reshape(-1, kept.shape[2])[-n:], info


def _sampler_failures(x: np.ndarray, reported: np.ndarray | None, u: np.ndarray,
                      pdf: Callable[[np.ndarray], np.ndarray],
                      dom: Domain) -> tuple[list[Failure], np.ndarray, int]:
    """Deterministic failures of the sampler's points x (rows of NaN: samples not produced,
    left out), the parameters s (m, k) of the points produced inside the domain, and the
    count of those not produced."""
    n = x.shape[0]
    produced = rest.finite_rows(x)
    missing = int(n - produced.sum())
    idx = np.flatnonzero(produced)
    xp = x[produced]
    failures: list[Failure] = []

    def fail(check: str, mask: np.ndarray, detail: str, values: np.ndarray | None = None) -> None:
        ex = tuple({"index": int(idx[i]), "point": np.atleast_1d(xp[i]).tolist(), "u": u[idx[i]].tolist(),
                    **({"value": float(values[i])} if values is not None else {})}
                   for i in np.flatnonzero(mask)[:5])
        failures.append(Failure(check, int(mask.sum()), detail, ex))

    if produced.sum() < 1000:
        ex = tuple({"index": int(i), "u": u[i].tolist()} for i in np.flatnonzero(~produced)[:5])
        said = f"only {int(produced.sum())} of {n} samples produced"
        failures.append(Failure("too_few_samples", missing, said, ex))
        return failures, np.zeros((0, dom.k)), missing
    s, inside = dom.to_params(xp)
    if not inside.all():
        fail("outside_domain", ~inside, f"points outside the {dom.kind}")
    p = pdf(xp)
    bad = np.isnan(p) | (p < 0)  # +inf: an integrable singularity hit exactly, not a fault
    if bad.any():
        fail("bad_pdf", bad, "pdf NaN or negative at sampled points", p)
    zero = (p == 0) & inside
    if zero.any():
        fail("zero_pdf", zero, "sampled points where the pdf is 0", p)
    if reported is not None:
        mismatch = reported_pdf_failure(xp, reported[produced], pdf)
        if mismatch is not None:
            failures.append(mismatch)
    return failures, s[inside], missing
