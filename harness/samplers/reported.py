"""Does the pdf a sampler reports with each sample equal its pdf() at the returned point?

MIS weights and path throughputs use the reported value, so a mismatch biases renders while
every test of where the samples go passes: the sampled lobe's pdf reported instead of the
mixture's, a mask's opacity factor left out.  The comparison is deterministic, per sample.

Tolerance: ``rtol`` relative (default 1e-4, about 800 float32 ulps: the reported value may be
computed along another path of float32 operations) plus what float32 rounding of the point
can explain, measured, not guessed: the largest change of pdf() when one coordinate of the
point moves by 4 float32 ulps either way (computed only for the samples beyond the relative
tolerance).  That term matters where the pdf is steep (a lobe's edge, a texel boundary, the
poles of a lat-long map); a mismatch by a factor off 1 by more than ``rtol`` is reported
wherever the pdf is not steep at that scale.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

import reference_estimators as rest

from harness.stats.results import Failure

__all__ = ["NUDGE_ULPS", "reported_pdf_failure", "rounding_spread"]

#: How many float32 ulps :func:`rounding_spread` moves each coordinate by.
NUDGE_ULPS = 4


def rounding_spread(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, at: np.ndarray) -> np.ndarray:
    """max |f(x') - at| over the 2 d copies x' of the points x ((N,) or (N, d)) rounded to
    float32 with one coordinate moved by NUDGE_ULPS float32 ulps up or down: what float32
    rounding of a point can change f(x) = ``at`` by (a non-finite change counts as infinite).
    f takes points of x's shape (and may return (N,) or (N, channels), as ``at``)."""
    flat = np.asarray(x, dtype=float)
    rows = flat.reshape(flat.shape[0], -1)
    spread = np.zeros_like(at, dtype=float)
    for c in range(rows.shape[1]):
        for steps in (NUDGE_ULPS, -NUDGE_ULPS):
            y = rest.float32_nudged(rows, c, steps)
            with np.errstate(all="ignore"):
                d = np.abs(np.asarray(f(y.reshape(flat.shape)), dtype=float) - at)
            spread = np.maximum(spread, np.where(np.isfinite(d), d, np.inf))
    return spread


def reported_pdf_failure(x: np.ndarray, reported: np.ndarray, pdf: Callable[[np.ndarray], np.ndarray], *,
                         rtol: float = 1e-4, max_examples: int = 5,
                         values: np.ndarray | None = None, all_finite: bool = False) -> Failure | None:
    """A "reported_pdf" Failure (count, largest relative difference, examples) where the pdf
    a sampler reported with its samples x differs from pdf(x) beyond the module's tolerance,
    else None.  Rows of x that are not finite (samples not produced) are skipped; a reported
    value that is NaN, infinite or negative at a produced sample is a mismatch.  ``values``:
    pdf(x) (N,) where the caller has it already (the sampler check does), so that pdf is
    called again only for the nudged copies of mismatching samples.  ``all_finite``: the
    caller knows every row of x is finite (the sampler check, where every point lies inside
    its domain), so that they are not tested again (1.2-1.9 ms a million directions)."""
    x = np.asarray(x, dtype=float)
    n = x.shape[0]
    rep = np.asarray(reported, dtype=float).reshape(-1)
    if rep.size != n:
        return Failure("reported_pdf", n, f"the sampler reported {rep.size} pdf values for {n} samples", ())
    finite = None if all_finite else rest.finite_rows(x)
    # every sample produced (the sampler check passes the produced ones): the arrays as they
    # are, where indexing them copied 40 MB a million directions
    every = all_finite or bool(finite.all())
    produced = None if every else np.flatnonzero(finite)    # the rows of x that xs holds
    if produced is not None and produced.size == 0:
        return None
    xs, rs = (x, rep) if every else (x[produced], rep[produced])
    if values is None:
        p = np.asarray(pdf(xs), dtype=float).reshape(-1)
    else:
        p = np.asarray(values, dtype=float).reshape(-1)
        if p.size != n:
            raise ValueError(f"'values' must hold pdf(x) at the {n} points, got {p.size} values")
        p = p if every else p[produced]
    bad = rest.pdf_mismatches(rs, p, rtol)    # rows of xs; the rest works on them alone
    rb, pb = rs[bad], p[bad]    # (0.8 million rows in the check of a GGX α = 0.01 lobe)
    with np.errstate(all="ignore"):
        diff = np.abs(rb - pb)
        nudge = np.isfinite(rb) & (rb >= 0) & np.isfinite(pb)
        if nudge.any():
            flat_pdf = lambda y: np.asarray(pdf(y), dtype=float).reshape(-1)  # noqa: E731
            spread = rounding_spread(flat_pdf, xs[bad[nudge]], pb[nudge])
            still = np.ones(bad.size, dtype=bool)
            still[nudge] = ~(diff[nudge] <= rtol * np.abs(pb[nudge]) + spread)
            bad, diff = bad[still], diff[still]
    if not bad.size:
        return None
    with np.errstate(all="ignore"):
        rel = np.where(p[bad] > 0, diff / p[bad], np.inf)
    worst = float(np.nanmax(rel)) if rel.size else float("nan")
    ex = tuple({"index": int(i if produced is None else produced[i]), "point": np.atleast_1d(xs[i]).tolist(),
                "reported": float(rs[i]), "pdf": float(p[i])} for i in bad[:max_examples])
    return Failure("reported_pdf", int(bad.size),
                   f"the pdf reported with the sample differs from pdf() at the sampled point beyond "
                   f"{rtol:g} relative + float32 rounding of the point (largest relative difference "
                   f"{worst:.3g})", ex)
