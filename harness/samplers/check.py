"""The chi-square sampler check: does a sampler draw what its pdf claims?

Deterministic checks first (samples outside the domain, zero, NaN or negative pdf values, a
pdf that does not integrate to 1), then statistical tests of the histogram of the samples on
equal-measure cells (:mod:`harness.samplers.domains`) against expected counts from adaptive
cubature of the claimed pdf (:mod:`harness.samplers.cubature`): chi-square on a coarse and a
fine grid, fine 1-D marginals and a pdf moment, combined by Holm.  :class:`SamplerTest` does
the sample-independent part (the cubature) once, for any number of samplers or seeds.

Missing samples.  A sampler may fail to produce a sample for some u (absorption, a direction
below the horizon): a NaN row.  Its samples then form a defective distribution whose pdf
integrates to P <= 1 (``total``, given or from the cubature), and the question splits in two,
both exact under the null: the failure count is Binomial(N, 1 - P) (an exact binomial test;
with P from the cubature its p-value is maximised over P's error bound: conservative), and
the samples produced follow pdf / P (the tests above, the cubature reused with its integrals
divided by P).  All p-values are combined by Holm.

A user's sample or pdf that raises, or returns the wrong shape, is a
:class:`~harness.usercode.UserCodeError` naming it, its input's shape and dtype, and the shape
expected back (:mod:`harness.samplers.calls`).
"""
from __future__ import annotations

import copy
import dataclasses
import math
import numbers
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

import reference_estimators as rest

from harness.samplers.calls import MAX_SAMPLES, checked_pdf, checked_sample_count, drawn_points, uniforms
from harness.samplers.cramer_von_mises import cramer_von_mises_from_sums
from harness.samplers.cubature import cell_integrals
from harness.samplers.domains import Domain, MomentColumns, ParamDensity, as_domain, checked_breaks, pdf_floor
from harness.samplers.reported import reported_pdf_failure
from harness.samplers.result import SamplerCheck
from harness.samplers.transform import STRIPS, Transform
from harness.stats import distributions, holm
from harness.stats.results import Failure
from harness.stats.validate import level

__all__ = ["MAX_SAMPLES", "SAMPLE_CASE", "SamplerTest", "check_sampler", "check_with_missing",
           "failure_pvalue", "histogram"]

#: The stream (case id) the sampler check draws its canonical uniforms from.
SAMPLE_CASE = 0x5A3F

#: The stream (case id) of the uniforms that dither float32 points (SamplerTest.check_points):
#: ``reference_estimators.points(N, coordinates, seed=seed, case_id=DITHER_CASE)``, each
#: coordinate moved uniformly within its float32 rounding interval (up to half way to each
#: float32 neighbour; non-finite ones kept), drawn and applied inside the core's pass
#: (:meth:`Domain.dithered_params` with ``stream``): numpy's dithering took 0.1-0.13 s a
#: million directions, more than the rest of the check.
DITHER_CASE = 0xD17E

#: pdf evaluations the base grid's cubature may spend (SamplerTest)
_MOMENT_EVALS = 12_000_000


# --- the check -------------------------------------------------------------------------------
class SamplerTest:
    """The sample-independent part of check_sampler: cubature of the claimed pdf on the base
    grid, done once and reused for any number of samplers or seeds (false-alarm runs)."""

    def __init__(self, pdf: Callable[[np.ndarray], np.ndarray], domain: str | tuple | Domain, *,
                 sample_count: int = 1_000_000, alpha: float = 0.01, breaks: Sequence[Any] | None = None,
                 pdf_batch: int | None = None):
        self.dom = dom = as_domain(domain)
        _checked_batch(pdf_batch)
        self.breaks = breaks = checked_breaks(breaks, dom)
        self.pdf = self.claimed_pdf = checked_pdf(pdf)   # claimed_pdf: the pdf as given (for_total keeps it)
        self.total = 1.0    # pdf = claimed_pdf / total (for_total)
        self.n = n = checked_sample_count(sample_count)
        self.alpha = alpha = level(alpha, "alpha")
        self.base = base = (4096,) if dom.k == 1 else (128, 256)
        pre_shape = (64,) if dom.k == 1 else (32, 64)
        # the pdf's rounding (judged on the pre-grid where not declared): a float32 pdf's own
        # noise is where the cubature stops refining
        self.floor = floor = pdf_floor(self.pdf, dom, pre_shape)

        density = ParamDensity(dom, self.pdf, pdf_batch=pdf_batch)
        squares = dataclasses.replace(density, columns=lambda v: np.column_stack([v, v * v]))

        # the pre-pass sets only the moment test's constant c (any fixed c gives a valid test)
        # and the tolerances below (a few per cent would do): six halvings of a cell are
        # plenty, where twelve had spent 34 million pdf calls along a bitmap light's texel edges
        pre, _ = cell_integrals(squares, pre_shape, 1e-8, max_depth=6, floor=floor, breaks=breaks)
        self.c = c = float(pre[:, 1].sum() / max(pre[:, 0].sum(), 1e-300))  # E_q[q], in units of q

        # tolerance: 1 % of each base cell's Poisson noise, from the pre-pass's expected counts
        per = [b // p for b, p in zip(base, pre_shape)]
        expect = np.maximum(pre[:, 0], 0).reshape(pre_shape)
        for axis, r in enumerate(per):
            expect = np.repeat(expect, r, axis=axis)
        expect = n * expect / int(np.prod(per))
        tol = 0.01 * np.sqrt(np.maximum(expect.reshape(-1), 1.0)) / n / (4 if dom.k == 2 else 2)
        # steps of the density (texel edges) never meet a per-box tolerance: every box on an
        # edge is halved to the depth limit.  The evaluation budget stops that: what error is
        # left is carried into the chi-square's variance (power lost on the edges' cells, never
        # level).  The zoo's samplers spend at most 8.2 million here (envmap 16x32), a bitmap
        # area light in Mitsuba's cap map spent 48 million
        mass3, err3 = cell_integrals(dataclasses.replace(density, columns=MomentColumns(c)), base, tol,
                                     floor=floor, max_evals=_MOMENT_EVALS, breaks=breaks)
        self.quadrature_faults = int((~np.all(np.isfinite(mass3), axis=1)).sum())
        mass3, err3 = np.nan_to_num(mass3), np.nan_to_num(err3)
        self.mass, self.err = mass3[:, 0].reshape(base), err3[:, 0].reshape(base)
        self.h_moments = (float(mass3[:, 1].sum()), float(mass3[:, 2].sum()), float(err3[:, 1].sum()))
        self.normalization = (float(self.mass.sum()), float(self.err.sum()))
        self.transform = Transform.build(density, dom.k, n, floor=floor, breaks=breaks,
                                         total=self.normalization[0])

    def for_total(self, total: float) -> SamplerTest:
        """This test for the density pdf / ``total``, without a new cubature: the integrals
        are linear in the pdf, and the moment test's h(p) = p / (p + c) is invariant when p
        and c scale together.  For a sampler that fails to produce some samples: its pdf
        integrates to total = P < 1, and the samples it produced follow pdf / P."""
        if not total > 0:
            raise ValueError(f"'total' must be a positive integral of the pdf, got {total!r}")
        t = copy.copy(self)
        claimed = self.claimed_pdf
        t.total = self.total * total
        t.pdf = lambda x: claimed(x) / t.total
        t.mass, t.err = self.mass / total, self.err / total
        t.c = self.c / total
        t.h_moments = tuple(v / total for v in self.h_moments)
        t.normalization = (self.normalization[0] / total, self.normalization[1] / total)
        return t

    def check(self, sample: Callable[[np.ndarray], Any], *, seed: int = 0,
              udim: int | None = None) -> SamplerCheck:
        """Draws ``sample_count`` points from ``sample`` (uniforms of stream ``seed``,
        :data:`SAMPLE_CASE`) and runs the checks of :func:`check_sampler` on them."""
        _, x, reported = _draw(sample, self.dom, self.n, seed, udim)
        return self.check_points(x, reported, seed=seed)

    def check_points(self, x: np.ndarray, reported: np.ndarray | None = None, *,
                     seed: int = 0) -> SamplerCheck:
        """The checks of :func:`check_sampler` on ``sample_count`` points already drawn, (N,)
        on an interval or (N, point_dim); ``reported``: the pdf values the sampler returned
        with them, if it did (checked against the claimed pdf, :mod:`harness.samplers.reported`);
        ``seed``: the stream that dithers float32 points (below)."""
        dom, n, base = self.dom, self.n, self.base
        if x.shape[0] != n:
            raise ValueError(f"expected the {n} points this test was built for, got {x.shape[0]}")
        failures: list[Failure] = []

        def fail(check: str, mask: np.ndarray, detail: str, values: np.ndarray | None = None) -> None:
            where = np.flatnonzero(mask)[:5]
            ex = [{"index": int(i), "point": np.atleast_1d(x[i]).tolist(),
                   **({"value": float(values[i])} if values is not None else {})} for i in where]
            failures.append(Failure(check, int(mask.sum()), detail, tuple(ex)))

        # float32 points (a renderer's) are quantised: near a narrow lobe's peak a float32
        # direction's z takes ~1700 values across the lobe, and cells of equal claimed
        # probability hold whole steps of that grid, 1 % too many or too few.  The statistical
        # tests see each such point moved uniformly within its float32 rounding interval
        # (stream ``seed``, DITHER_CASE), which under H0 follows the pdf smoothed over that
        # interval: the same law to O(ulp^2) (without it GGX alpha 0.01 from Mitsuba failed the
        # equiprobable chi-square at p = 1e-6).  No check reads the parameters of the points
        # as drawn but pdf_summary on the half line, so elsewhere the dithered parameters and
        # the domain mask of the points as drawn come from one pass.
        float32 = _float32_points(x)
        dither_now = float32 and dom.kind != "half_line"
        s, inside = dom.dithered_params(x, stream=(seed, DITHER_CASE)) if dither_now else dom.to_params(x)
        all_inside = bool(inside.all())
        if not all_inside:
            fail("outside_domain", ~inside, f"points outside the {dom.kind}")
        # the claimed pdf once: the density tested is it over the total (for_total, divided
        # in pdf_summary), and the reported pdf is checked against it as given (a second call
        # had cost a Mitsuba sampler's check a tenth of its time)
        claimed = self.claimed_pdf(x)
        measure = 1.0 if dom.kind == "half_line" else float(dom.jacobian(s))
        n_bad, n_zero, used, h_sum = rest.pdf_summary(dom.kind, measure, s, inside, claimed, self.c,
                                                      self.total)
        if n_bad or n_zero:
            p = claimed if self.total == 1 else claimed / self.total
            if n_bad:
                fail("bad_pdf", ~np.isfinite(p) | (p < 0), "pdf NaN, infinite or negative at sampled points",
                     p)
            if n_zero:
                fail("zero_pdf", (p == 0) & inside, "sampled points where the pdf is 0", p)
        if reported is not None:
            mismatch = reported_pdf_failure(x, reported, self.claimed_pdf, values=claimed,
                                            all_finite=all_inside)
            if mismatch is not None:
                failures.append(mismatch)
        if self.quadrature_faults:
            failures.append(Failure("bad_pdf_quadrature", self.quadrature_faults,
                                    "pdf NaN or infinite inside cells (cubature)"))
        total, total_err = self.normalization
        if abs(total - 1) > max(1e-3, 10 * total_err):
            failures.append(Failure("normalization", 1, f"pdf integrates to {total:.6f} ± {total_err:.1e} "
                                                        f"over the {dom.kind}, not 1"))

        if float32 and not dither_now:     # dithered as above, on the half line
            s = dom.dithered_params(x, stream=(seed, DITHER_CASE))[0]
        counts = rest.grid_histogram(s, inside, base)
        grids = {"coarse": (16,) if dom.k == 1 else (16, 32), "fine": (512,) if dom.k == 1 else (64, 128)}
        tests, residuals = [], {}
        for name, shape in grids.items():
            o, e, r = (_coarsen(a, shape) for a in (counts, self.mass, self.err))
            stat, df, resid = _chi_square(o.reshape(-1), n * e.reshape(-1), n * r.reshape(-1))
            residuals[name] = np.where(n * e >= 5, resid.reshape(shape), np.nan)  # pooled cells: NaN
            detects = "large-scale misfit" if name == "coarse" else "narrow features: lobes, bands, steps"
            tests.append((f"chi-square {'x'.join(map(str, shape))}", stat, df,
                          distributions.chi2_sf(stat, df) if df > 0 else 1.0, detects))
        marginals = {}
        for axis in range(dom.k):  # for the report's plots: observed and expected counts per axis
            shape = tuple(base[a] if a == axis else 1 for a in range(dom.k))
            o, e = (_coarsen(a, shape) for a in (counts, self.mass))
            bins = min(base[axis], 128)
            marginals[f"s{axis}"] = {"observed": o.reshape(bins, -1).sum(axis=1),
                                     "expected": n * e.reshape(bins, -1).sum(axis=1)}
        tests += self._transform_tests(s if all_inside else s[inside])
        # pdf moment: sample mean of h(p(X)) against its cubature value (h summed over the
        # inside points with a good pdf above 0 by pdf_summary above, a zero pdf failing on its
        # own; 0 where there are none or c = 0);
        # the variance adds the cubature error and a rounding floor (a constant pdf makes h constant)
        e1, e2, e1_err = self.h_moments
        h_mean = h_sum / used if self.c > 0 and used else 0.0
        denom = math.sqrt(max(e2 - e1 * e1, 0.0) / max(used if self.c > 0 else 1, 1) + e1_err**2 + 1e-24)
        z = (h_mean - e1) / denom
        tests.append(("pdf moment", z * z, 1, float(distributions.chi2_sf(z * z, 1)),
                      "density wrong where it is high or low"))

        import pandas as pd  # deferred, as in harness.suite.kind.Outcome.frame
        table = pd.DataFrame(tests, columns=["test", "statistic", "df", "pvalue", "detects"])
        rejected, adjusted = holm(np.nan_to_num(table["pvalue"].to_numpy(), nan=0.0), self.alpha)
        table["adjusted"] = adjusted
        passed = not failures and not rejected.any()
        return SamplerCheck(passed, float(adjusted.min()), self.alpha, n, table, failures, self.normalization,
                            residuals, marginals)

    def _transform_tests(self, s: np.ndarray) -> list[tuple]:
        """Tests on the Rosenblatt transform u of the parameter points s inside the domain
        (:mod:`harness.samplers.transform`): Cramer-von Mises on u0 and, on the square, on u1
        given the strip of s0 (each carrying the tabulation's error bound), and a chi-square on
        cells of equal claimed probability (bins of u0; strips x bins of u1), the tabulation's
        error in each cell's variance."""
        t, m = self.transform, s.shape[0]
        if m == 0:
            return []
        bins = min(1024, max(m // 50, 16)) if t.conditional is None else 64
        sums, observed, prob, prob_err = t.statistics(s, bins)
        tables = [t.marginal] if t.conditional is None else [t.marginal, t.conditional]
        names = ["u0 = F(s0)", "u1 = F(s1 | strip of s0)"]
        tests = []
        cvm = cramer_von_mises_from_sums(sums, m, [table.error for table in tables])
        for axis, (table, (w2, p)) in enumerate(zip(tables, cvm)):
            tests.append((f"Cramer-von Mises {names[axis]}", w2, 0, p,
                          f"smooth warps below the bin width (CDF error bound {table.error:.1e} carried)"))
        stat, df, _ = _chi_square(observed, m * prob, m * prob_err)
        cells = "x".join(map(str, (bins,) if t.conditional is None else (STRIPS, bins)))
        p = distributions.chi2_sf(stat, df) if df > 0 else 1.0
        tests.append((f"chi-square equiprobable {cells}", stat, df, p,
                      "narrow lobes: as many cells where the density is high as elsewhere"))
        return tests


def check_sampler(sample: Callable[[np.ndarray], Any], pdf: Callable[[np.ndarray], np.ndarray],
                  domain: str | tuple | Domain, *, sample_count: int = 1_000_000, seed: int = 0,
                  alpha: float = 0.01, udim: int | None = None, total: float | None = None,
                  breaks: Sequence[Any] | None = None, pdf_batch: int | None = None) -> SamplerCheck:
    """Test that ``sample`` draws points with the density ``pdf`` claims.

    ``sample`` maps canonical uniforms of shape (N, udim) (default: 1 for intervals, 2 else)
    to points; it may return (points, pdf values), as the core's samplers do, and then the
    pdf values it reports must equal ``pdf`` at the points (a deterministic "reported_pdf"
    failure otherwise: :mod:`harness.samplers.reported` states the float32 tolerance).  ``pdf`` maps
    points to the claimed density (per unit length, area, or solid angle; 0 outside its
    support).  Points: (N,) on an interval, (N, 2) on the square and disk, unit vectors
    (N, 3) on the hemisphere and sphere; ``domain`` is one of "interval" ([0, 1]), ("interval",
    a, b), "half_line", "square", "disk", "hemisphere", "sphere".

    Deterministic checks first, each failure with counts and examples: samples outside the
    domain; samples where the pdf is 0; NaN, infinite or negative pdf values; the pdf not
    integrating to 1 (adaptive cubature, |integral - 1| above 1e-3 and above 10 times the
    quadrature error: a pdf 0.5 % too large fails here, deterministically).

    Then statistical tests, combined by Holm at ``alpha`` (the false-alarm rate;
    tests/samplers/test_sampler_check_verdicts.py measures it over 200 seeds per correct sampler):
      chi-square, coarse grid   what a sampler gets wrong over large regions;
      chi-square, fine grid     narrow features: a wrong lobe width, a band 10 % too dense;
      marginals (1-D, fine)     along each axis at 128/256 bins (4096 on an interval), what
                                2-D cells average away;
      pdf moment                E[h(pdf(X))] with h(p) = p / (p + c) bounded, against its
                                cubature value: a density wrong where it is high or low.
    Expected counts below 5 are pooled; residual cubature error enters the variance.

    A sampler that fails to produce some samples returns NaN rows for them; its pdf then
    integrates to ``total`` < 1 (give it, or it is taken from the cubature and reported as
    ``normalization``), and the check becomes :func:`check_with_missing`'s: the tests above on
    the samples produced against pdf / total, plus an exact binomial test of the count of
    missing ones against N (1 - total), all Holm-combined at ``alpha``.

    ``breaks``: where the pdf may step or kink (texel edges, a lobe's cut-off), per parameter
    axis of the domain (:meth:`Domain.breaks` maps natural coordinates there; a lat-long map
    whose rows are cones about +y wants ``Domain("sphere", pole="y")``).  The cubature then
    splits its boxes there rather than halving toward each step to its depth limit: on the
    zoo's 16 x 32 envmap 62 % of the setup's pdf calls (22.6 million against 36.7), and its
    mass exact to its bound (undeclared, a texel edge within 3.5 % of a box's width from its
    end or middle escapes every rule judging the box, and the mass is 1.7e-4 off, 26 times its
    bound: :func:`harness.samplers.cubature.box_integrals`).  A needless break costs time only.

    ``pdf_batch``: the points the cubature passes ``pdf`` in one call (None: 65536, where a
    numpy pdf's temporaries stay in the caches).  A renderer whose every call has a fixed cost
    (a JIT kernel's compilation lookup and launch) wants more: Mitsuba's adapter passes 2^19
    (:class:`harness.adapters.mitsuba.batch.MitsubaSampler`).  The integrals are the same
    bits whatever the batch.
    """
    dom = as_domain(domain)
    n = checked_sample_count(sample_count)
    _checked_batch(pdf_batch)
    u, x, reported = _draw(sample, dom, n, seed, udim)
    if total is None and np.isfinite(x).all():
        test = SamplerTest(pdf, dom, sample_count=n, alpha=alpha, breaks=breaks, pdf_batch=pdf_batch)
        return test.check_points(x, reported, seed=seed)
    return _check_drawn(u, x, reported, pdf, dom, alpha, total, seed, breaks, pdf_batch)


def _checked_batch(pdf_batch: Any) -> None:
    """Raises ValueError, naming 'pdf_batch', unless it is None or a positive whole number of
    points (not a bool)."""
    whole = isinstance(pdf_batch, (int, np.integer)) and not isinstance(pdf_batch, bool)
    if pdf_batch is not None and not (whole and pdf_batch >= 1):
        raise ValueError(f"'pdf_batch' must be a positive number of points (or None), got {pdf_batch!r}")


def failure_pvalue(failed: int, n: int, total: float, total_err: float) -> float:
    """Two-sided exact binomial test of ``failed`` of ``n`` against failure probability
    1 - P, P anywhere in total ± total_err: 1 where the observed rate lies in that interval,
    else the p-value at its end nearest the observed rate (conservative)."""
    lo, hi = min(max(1 - total - total_err, 0.0), 1.0), min(max(1 - total + total_err, 0.0), 1.0)
    rate = failed / n
    if lo <= rate <= hi:
        return 1.0
    q = lo if rate < lo else hi
    if q <= 0:
        return 0.0 if failed > 0 else 1.0
    if q >= 1:
        return 0.0 if failed < n else 1.0
    from scipy import stats  # here, not at the top: scipy.stats costs 0.8 s of import (distributions)

    return float(stats.binomtest(failed, n, q).pvalue)


def check_with_missing(sample: Callable[[np.ndarray], Any], pdf: Callable[[np.ndarray], np.ndarray],
                       domain: str | tuple | Domain, *, sample_count: int = 1_000_000, seed: int = 0,
                       alpha: float = 0.01, udim: int | None = None, total: float | None = None,
                       breaks: Sequence[Any] | None = None, pdf_batch: int | None = None) -> SamplerCheck:
    """check_sampler for a sampler that may fail to produce a sample (NaN rows), whether or
    not it does this time (see the module's "Missing samples").  Deterministic failures: fewer
    than 1000 samples produced; the pdf integrating to more than 1 (by more than 1e-3 and 10
    times the cubature error), or, with ``total`` given, to other than ``total``; and
    check_sampler's own on the samples produced (outside the domain, zero/NaN/negative pdf).
    The tests table holds a "failed samples" row (the count, and its binomial p-value);
    ``normalization`` the cubature's P and its error bound; ``breaks`` and ``pdf_batch`` as
    check_sampler's."""
    dom = as_domain(domain)
    _checked_batch(pdf_batch)
    u, x, reported = _draw(sample, dom, checked_sample_count(sample_count), seed, udim)
    return _check_drawn(u, x, reported, pdf, dom, alpha, total, seed, breaks, pdf_batch)


def _check_drawn(u: np.ndarray, x: np.ndarray, reported: np.ndarray | None,
                 pdf: Callable[[np.ndarray], np.ndarray], dom: Domain, alpha: float,
                 total: float | None, seed: int, breaks: Sequence[Any] | None = None,
                 pdf_batch: int | None = None) -> SamplerCheck:
    """check_with_missing on points x already drawn from uniforms u (``reported``: the pdf
    values the sampler returned with them, or None)."""
    if total is not None and (isinstance(total, bool) or not isinstance(total, numbers.Real)
                              or not 0 < total <= 1):
        raise ValueError(f"'total' must be the pdf's integral over the domain, in (0, 1], got {total!r}")
    n = x.shape[0]
    x = x.reshape(n, dom.point_dim)
    failed = ~rest.finite_rows(x)
    # (with none failed, x itself: indexing copied 24 MB a million directions; else the rows
    # taken in the core, into memory it reuses, where numpy's fresh array cost 10 ms of page
    # faults)
    any_failed = bool(failed.any())
    produced = (rest.take_rows(x, ~failed) if any_failed else x).reshape((-1,) if dom.point_dim == 1
                                                                        else (-1, dom.point_dim))
    m = produced.shape[0]
    if m < 1000:
        import pandas as pd  # deferred, as in harness.suite.kind.Outcome.frame
        table = pd.DataFrame([("failed samples", float(failed.sum()), 0, 0.0,
                               "samples the sampler did not produce")],
                             columns=["test", "statistic", "df", "pvalue", "detects"])
        table["adjusted"] = 0.0
        fail = Failure("too_few_samples", int(failed.sum()), f"only {m} of {n} samples produced",
                       tuple(_u_examples(u, failed)))
        return SamplerCheck(False, 0.0, alpha, n, table, [fail], (math.nan, math.nan))
    raw = SamplerTest(pdf, dom, sample_count=m, alpha=alpha, breaks=breaks, pdf_batch=pdf_batch)
    cubature, cubature_err = raw.normalization
    failures: list[Failure] = []
    if total is not None:
        p_total, p_err = float(total), 0.0
        if abs(cubature - p_total) > max(1e-3, 10 * cubature_err):
            failures.append(Failure("normalization", 1,
                                    f"pdf integrates to {cubature:.6f} ± {cubature_err:.1e} over the "
                                    f"{dom.kind}, not the given total {p_total:g}"))
    else:
        p_total, p_err = cubature, cubature_err
        if not cubature > 0:
            failures.append(Failure("normalization", 1,
                                    f"pdf integrates to {cubature:.6g} over the {dom.kind}"))
            p_total = 1.0
        elif cubature - 1 > max(1e-3, 10 * cubature_err):
            failures.append(Failure("normalization", 1,
                                    f"pdf integrates to {cubature:.6f} ± {cubature_err:.1e} over the "
                                    f"{dom.kind}, more than 1"))
    kept_reported = rest.take_rows(reported, ~failed) if reported is not None and any_failed else reported
    shape = raw.for_total(p_total).check_points(produced, kept_reported, seed=seed)
    index = np.flatnonzero(~failed)  # the shape check's examples index the produced samples
    for f in shape.failures:
        if f.check != "normalization":
            examples = tuple({**ex, "index": int(index[ex["index"]]), "u": u[index[ex["index"]]].tolist()}
                             for ex in f.examples)
            failures.append(dataclasses.replace(f, examples=examples))
    k = int(failed.sum())
    p_fail = failure_pvalue(k, n, min(p_total, 1.0), p_err)
    expected = n * max(1 - p_total, 0.0)
    table = shape.tests.drop(columns=["adjusted"])
    table.loc[len(table)] = ("failed samples", float(k), 1, p_fail,
                             f"failure count vs N(1-P) = {expected:.1f}: pdf mass where no samples go")
    rejected, adjusted = holm(np.nan_to_num(table["pvalue"].to_numpy(dtype=float), nan=0.0), alpha)
    table["adjusted"] = adjusted
    passed = not failures and not rejected.any()
    # the shape check's per-cell results (residuals, marginals) are kept: they describe the
    # produced samples, the only ones with a direction
    return dataclasses.replace(shape, passed=passed, pvalue=float(adjusted.min()), n=n, tests=table,
                               failures=failures, normalization=raw.normalization)


def _float32_points(x: np.ndarray) -> bool:
    """Whether x's coordinates are float32 (:func:`reference_estimators.all_float32`, which
    stops soon after a float64 sampler's first value that is not)."""
    return rest.all_float32(x)


def _u_examples(u: np.ndarray, mask: np.ndarray, k: int = 5) -> list[dict[str, Any]]:
    return [{"index": int(i), "u": u[i].tolist()} for i in np.flatnonzero(mask)[:k]]


def _draw(sample: Callable[[np.ndarray], Any], dom: Domain, n: int, seed: int,
          udim: int | None) -> tuple[np.ndarray, np.ndarray]:
    """The check's uniforms (stream ``seed``, :data:`SAMPLE_CASE`) and the points ``sample``
    draws from them."""
    u = uniforms(n, udim, dom, seed, SAMPLE_CASE)
    return (u, *drawn_points(sample, u, dom))


def histogram(s: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Counts of parameter points ``s`` (N, k), each in [0, 1), on the regular grid ``shape``
    over [0, 1]^k (cells of equal measure): an array of ``shape`` (float64).  One pass in the
    core (:func:`reference_estimators.grid_histogram`)."""
    return rest.grid_histogram(s, np.ones(s.shape[0], dtype=bool), shape)


def _coarsen(a: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Sums blocks of a base-grid array down to ``shape`` (each base size a multiple)."""
    if a.ndim == 1:
        return a.reshape(shape[0], -1).sum(axis=1)
    return a.reshape(shape[0], a.shape[0] // shape[0], shape[1], a.shape[1] // shape[1]).sum(axis=(1, 3))


def _chi_square(observed: np.ndarray, expected: np.ndarray,
                quad_err: np.ndarray) -> tuple[float, int, np.ndarray]:
    """Pearson's statistic with all cells of expectation < 5 pooled into one and the cubature
    error added to each cell's variance; standardised residuals per cell."""
    var = expected + quad_err**2
    resid = np.where(var > 0, (observed - expected) / np.sqrt(np.maximum(var, 1e-300)), 0.0)
    big = expected >= 5
    stat = float(np.sum((observed[big] - expected[big]) ** 2 / var[big]))
    cells = int(big.sum())
    small_e, small_o = float(expected[~big].sum()), float(observed[~big].sum())
    if small_e > 0 or small_o > 0:
        pooled_var = small_e + float(np.sum(quad_err[~big] ** 2))
        stat += (small_o - small_e) ** 2 / max(pooled_var, 5.0) if small_e >= 5 or small_o > 0 else 0.0
        cells += 1
    return stat, max(cells - 1, 0), resid
