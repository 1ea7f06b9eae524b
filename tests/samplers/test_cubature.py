"""Grouped cubature (harness.samplers.cubature.grouped_integrals): boxes judged against their
parent's rule give the integrals box_integrals gives, within the bounds, for a quarter of the
pdf calls on a smooth density; a group that disagrees goes through box_integrals."""
from __future__ import annotations

import math

import numpy as np
import pytest

from harness.samplers.cubature import box_integrals, cell_integrals, grouped_integrals, split_points


def _lobe(x: np.ndarray) -> np.ndarray:
    """A smooth lobe on [0, 1]^2, narrow across (width 0.02 along s1), with a closed-form
    integral over any box."""
    return np.exp(-0.5 * ((x[:, 0] - 0.4) / 0.2) ** 2 - 0.5 * ((x[:, 1] - 0.55) / 0.02) ** 2)


def _lobe_box(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    def axis(a, b, mu, s):
        return s * math.sqrt(math.pi / 2) * np.array([math.erf((bb - mu) / (s * math.sqrt(2)))
                                                      - math.erf((aa - mu) / (s * math.sqrt(2)))
                                                      for aa, bb in zip(a, b)])
    return axis(lo[:, 0], hi[:, 0], 0.4, 0.2) * axis(lo[:, 1], hi[:, 1], 0.55, 0.02)


def _counted(f):
    calls = [0]

    def q(x):
        calls[0] += x.shape[0]
        return f(x)
    return q, calls


def test_a_grid_judged_in_blocks_matches_the_exact_integrals_for_fewer_calls():
    shape, tol = (64, 128), 1e-9
    idx = np.stack(np.meshgrid(np.arange(64), np.arange(128), indexing="ij"), axis=-1).reshape(-1, 2)
    lo, hi = idx / np.array(shape), (idx + 1) / np.array(shape)
    exact = _lobe_box(lo, hi)
    q, calls = _counted(_lobe)
    v, e = cell_integrals(q, shape, tol)
    grouped = calls[0]
    assert np.all(np.abs(v[:, 0] - exact) <= e[:, 0] + 1e-15)
    q, calls = _counted(_lobe)
    one_by_one, _ = box_integrals(q, lo, hi, tol)
    assert np.all(np.abs(one_by_one[:, 0] - exact) <= 1e-9)
    assert grouped * 3 <= calls[0], (grouped, calls[0])


def _leaf_quarters(across: bool):
    """Eight leaves along s0, each cut into four quarters along s0 and, if ``across``, halved
    along s1: (lo, hi, group, parent_lo, parent_hi)."""
    edges, quarter = np.linspace(0, 1, 9), np.linspace(0, 1, 5)
    plo, phi = np.column_stack([edges[:-1], np.zeros(8)]), np.column_stack([edges[1:], np.ones(8)])
    halves = ((0.0, 0.5), (0.5, 1.0)) if across else ((0.0, 1.0),)
    lo, hi, group = [], [], []
    for g in range(8):
        w = phi[g, 0] - plo[g, 0]
        for j in range(4):
            for a, b in halves:
                lo.append([plo[g, 0] + w * quarter[j], a])
                hi.append([plo[g, 0] + w * quarter[j + 1], b])
                group.append(g)
    return np.array(lo), np.array(hi), np.array(group), plo, phi


def test_children_must_cut_their_parent_along_every_axis():
    """Quarters along s0 alone of parents narrow across agree with the parent's rule on a lobe
    neither resolves across (1.6e-3 off with a bound of 1e-19, measured): refused.  Halved
    across too, as the transform's tables are, every integral is within its bound."""
    with pytest.raises(ValueError, match="every parent must be cut along every axis"):
        grouped_integrals(_lobe, *_leaf_quarters(False), 1e-10)
    lo, hi, group, plo, phi = _leaf_quarters(True)
    v, e = grouped_integrals(_lobe, lo, hi, group, plo, phi, 1e-10)
    assert np.all(np.abs(v[:, 0] - _lobe_box(lo, hi)) <= e[:, 0] + 1e-15)


def test_a_group_with_a_step_goes_through_box_integrals():
    def step(x):
        return np.where(x[:, 0] < 0.3, 1.0, 3.0)

    lo = np.array([[0.0, 0.0], [0.5, 0.0], [0.0, 0.5], [0.5, 0.5]])
    hi = lo + 0.5
    group = np.zeros(4, dtype=int)
    v, e = grouped_integrals(step, lo, hi, group, np.zeros((1, 2)), np.ones((1, 2)), 1e-10)
    left = 0.25 * (0.3 / 0.5 * 1 + 0.2 / 0.5 * 3)
    exact = np.array([left, 0.75, left, 0.75])
    assert np.all(np.abs(v[:, 0] - exact) <= e[:, 0] + 1e-12)
    alone, alone_err = box_integrals(step, lo, hi, 1e-10)
    assert np.array_equal(v, alone) and np.array_equal(e, alone_err)
    # the group's own rules are handed on: no box's rule over itself is computed twice
    calls = []

    def counted(x):
        calls.append(x.shape[0])
        return step(x)

    grouped_integrals(counted, lo, hi, group, np.zeros((1, 2)), np.ones((1, 2)), 1e-10)
    once = sum(calls)
    calls.clear()
    box_integrals(counted, lo, hi, 1e-10)
    assert once == 16 + sum(calls)      # the parent's rule, then box_integrals' own work


# --- box_integrals' refinement in the core, against its definition in numpy -------------------
def _reference_split_points(lo, hi, breaks):
    """split_points as numpy searches: the break strictly inside (1e-9 of the width from either
    end) nearest the middle, of the first at or above it and the one before, else the middle."""
    mid = (lo + hi) / 2
    if breaks is None or breaks.size == 0:
        return mid
    margin = 1e-9 * (hi - lo)
    first = np.searchsorted(breaks, lo + margin, side="right")
    last = np.searchsorted(breaks, hi - margin, side="left")
    near = np.clip(np.searchsorted(breaks, mid), first, np.maximum(last - 1, first))
    below = np.clip(near - 1, first, np.maximum(last - 1, first))
    top = breaks.size - 1
    a, b = breaks[np.minimum(near, top)], breaks[np.minimum(below, top)]
    return np.where(last > first, np.where(np.abs(b - mid) < np.abs(a - mid), b, a), mid)


def test_split_points_in_the_core_are_the_numpy_searches():
    """Breaks on the ends, within the 1e-9 margin, either side of the middle at equal distance
    (the tie goes to the one at or above), outside the interval, none inside."""
    rng = np.random.default_rng(8)
    for _ in range(200):
        dyadic = [0.25, 0.5, 0.625, 0.75][: rng.integers(0, 5)]
        breaks = np.unique(np.concatenate([rng.random(rng.integers(0, 12)), dyadic]))
        lo = rng.choice(np.concatenate([rng.random(40), breaks, np.arange(9) / 8]), 300)
        width = rng.choice([1e-12, 1e-9, 0.01, 0.125, 0.25, 0.5], 300)
        hi = np.minimum(lo + width, 1.0)
        lo = np.minimum(lo, hi - 1e-15)
        lo[:4], hi[:4] = [0.5 - 1e-10, 0.25, 0.5, 0.375], [0.75, 0.75, 0.75 + 1e-10, 0.875]
        want = _reference_split_points(lo, hi, breaks if breaks.size else None)
        np.testing.assert_array_equal(split_points(lo, hi, breaks if breaks.size else None), want)
    with pytest.raises(ValueError, match="sorted numbers"):
        split_points(np.zeros(2), np.ones(2), np.array([0.5, 0.25]))


def _halves(lo, hi, axis, cut):
    """Each box split in two along ``axis`` at ``cut`` (B,): rows 2i, 2i + 1 the parts of box i."""
    clo, chi = np.repeat(lo, 2, axis=0), np.repeat(hi, 2, axis=0)
    chi[0::2, axis] = cut
    clo[1::2, axis] = cut
    return clo, chi


def _reference_box_integrals(q, lo, hi, tol, *, max_depth=24, max_evals=40_000_000, floor=0.0,
                             extrapolate=True, breaks=None):
    """box_integrals as numpy arrays level by level (the algorithm the core's BoxRefinement
    runs): each box against its best split's halves, converged or halved along that axis."""
    from harness.samplers.cubature import _GL_W, _GL_X, tensor_rule

    def rule(a, b):
        w = _GL_W if a.shape[1] == 1 else np.outer(_GL_W, _GL_W).reshape(-1)
        return tensor_rule(q, a, b, _GL_X, w)

    def unconverged_factor(change, history):
        c1, c2 = history[:, 0], history[:, 1]
        pair, before = change + c1, c1 + c2
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(np.isnan(c2), change / c1, pair / before)
            base = np.where(np.isnan(c2), change, pair)
            ratio = np.clip(np.nan_to_num(ratio, nan=0.0, posinf=0.99), 0.0, 0.99)
            factor = base * ratio / (1 - ratio) / change
        factor = np.where(np.isnan(c1) | ~(change > 0), 1.0, factor)
        return np.maximum(np.nan_to_num(factor, nan=1.0), 1.0)

    ncell, k = lo.shape
    tol = np.broadcast_to(np.asarray(tol, dtype=float), (ncell,))
    owner, share, whole = np.arange(ncell), np.ones(ncell), rule(lo, hi)
    history = np.full((ncell, 2), np.nan)
    finished, evals = [], ncell * 4**k
    for depth in range(max_depth + 1):
        splits = []
        for axis in range(k):
            cut = _reference_split_points(lo[:, axis], hi[:, axis], None if breaks is None else breaks[axis])
            clo, chi = _halves(lo, hi, axis, cut)
            parts = rule(clo, chi).reshape(-1, 2, whole.shape[1])
            mid = (lo[:, axis] + hi[:, axis]) / 2
            first = np.where(cut == mid, 0.5, (cut - lo[:, axis]) / (hi[:, axis] - lo[:, axis]))
            splits.append((clo, chi, parts, first))
            evals += clo.shape[0] * 4**k
        sums = [p[:, 0] + p[:, 1] for _, _, p, _ in splits]
        change = np.stack([np.abs(t[:, 0] - whole[:, 0]) for t in sums], axis=1)
        best = np.argmax(change, axis=1)
        rows = np.arange(lo.shape[0])
        refined, moved = np.stack(sums, axis=1)[rows, best], change[rows, best]
        diff = np.abs(refined - whole)
        converged = moved <= np.maximum(tol[owner] * share, floor * np.abs(whole[:, 0]))
        done = converged | (depth == max_depth) | (evals > max_evals)
        stopped = done & ~converged
        if extrapolate and stopped.any():
            diff[stopped] *= unconverged_factor(moved[stopped], history[stopped])[:, None]
        finished.append((owner[done], refined[done], diff[done]))
        if done.all():
            break
        keep = np.flatnonzero(~done)
        parts_next = []
        for axis, (clo, chi, parts, first) in enumerate(splits):
            sel = keep[best[keep] == axis]
            pick = np.stack([2 * sel, 2 * sel + 1], axis=1).reshape(-1)
            shares = np.stack([share[sel] * first[sel], share[sel] * (1 - first[sel])], axis=1).reshape(-1)
            parts_next.append((clo[pick], chi[pick], parts[sel].reshape(-1, whole.shape[1]),
                               np.repeat(owner[sel], 2), shares,
                               np.repeat(np.stack([change[sel, axis], history[sel, 0]], axis=1), 2, axis=0)))
        lo, hi, whole, owner, share, history = (np.concatenate(v) for v in zip(*parts_next))
    owner, value, error = (np.concatenate(v) for v in zip(*finished))
    sums = [np.stack([np.bincount(owner, a[:, j], minlength=ncell) for j in range(a.shape[1])], axis=1)
            for a in (value, error)]
    return sums[0], sums[1]


def _step_and_singularity(x: np.ndarray) -> np.ndarray:
    """A 1:9 step at s0 = 0.41, an x^-0.9 singularity along s1 = 0 and a narrow lobe."""
    with np.errstate(divide="ignore"):
        return (1 + 8 * (x[:, 0] > 0.41)) * (0.1 + x[:, 1] ** -0.9) + np.exp(-((x[:, 0] - 0.3) ** 2) / 2e-5)


@pytest.mark.parametrize("k", [1, 2])
@pytest.mark.parametrize("options", [{}, {"extrapolate": False}, {"max_depth": 3}, {"max_evals": 30_000},
                                     {"floor": 1e-5}, {"breaks": "step"}, {"columns": 3}, {"tol": "per box"},
                                     {"max_depth": 0}, {"max_evals": 0}, {"bad": True}])
def test_box_integrals_refinement_in_the_core_is_its_numpy_definition_bit_for_bit(k, options):
    """Every decision of the refinement (the split axis, convergence at the tolerance or q's
    rounding floor, the depth and evaluation limits, the unconverged boxes' extrapolated error,
    splits at declared breaks, the sums in finishing order, NaN and infinite integrals,
    zero-width boxes) as the numpy algorithm makes it."""
    options = dict(options)
    columns, bad = options.pop("columns", 1), options.pop("bad", False)
    if options.get("breaks") == "step":
        options["breaks"] = [np.array([0.25, 0.41, 0.7]), None][:k]

    def q(x):
        v = _step_and_singularity(x if k == 2 else np.column_stack([x[:, 0], x[:, 0]]))
        if bad:   # NaN in a band, infinite on a line: boxes whose changes are NaN or infinite
            v = np.where(np.abs(x[:, 0] - 0.6) < 0.01, np.nan, np.where(x[:, 0] == 0.8125, np.inf, v))
        return v if columns == 1 else np.column_stack([v ** (j + 1) / 10**j for j in range(columns)])

    rng = np.random.default_rng(7)
    lo = np.floor(rng.random((40, k)) * 8) / 8             # boxes of the grid of eighths, some repeated
    lo[:3] = 0.0                                             # the singular corner
    hi = lo + 0.125
    hi[3] = lo[3]                                            # a box of zero width
    tol = rng.random(40) * 1e-5 if options.pop("tol", None) == "per box" else 1e-6
    with np.errstate(invalid="ignore"):
        want = _reference_box_integrals(q, lo, hi, tol, **options)
        got = box_integrals(q, lo, hi, tol, **options)
    for a, b in zip(want, got):
        np.testing.assert_array_equal(a.view(np.uint64), b.view(np.uint64))
    assert bad or np.all(np.isfinite(got[0]))


def _reference_agreement(own, parent, group, tol, floor):
    """grouped_integrals' judgement in numpy (what the core's grouped_agreement does): the
    boxes' sums per parent by bincount, the change, agreement, the shared errors."""
    ngroup = parent.shape[0]
    sums = np.stack([np.bincount(group, own[:, j], minlength=ngroup) for j in range(own.shape[1])], axis=1)
    change = np.abs(sums - parent)
    group_tol = np.bincount(group, tol, minlength=ngroup)
    with np.errstate(invalid="ignore"):
        agreed = (np.all(np.isfinite(change), axis=1)
                  & (change[:, 0] <= np.maximum(group_tol, floor * np.abs(parent[:, 0]))))
    taken = agreed[group]
    value, error = own.copy(), np.zeros_like(own)
    share = tol / np.maximum(group_tol[group], 1e-300)
    error[taken] = change[group[taken]] * share[taken, None]
    return value, error, np.flatnonzero(~taken)


@pytest.mark.parametrize("columns", [1, 3])
@pytest.mark.parametrize("floor", [0.0, 1e-3])
def test_grouped_agreement_in_the_core_is_its_numpy_definition_bit_for_bit(columns, floor):
    """Parents agreeing within the tolerance, within q's rounding floor only, by a hair either
    side, with NaN or infinite integrals in a box or the parent, a zero tolerance, parents
    without boxes; boxes in any order of their parents."""
    from reference_estimators import grouped_agreement

    rng = np.random.default_rng(11)
    for _ in range(20):
        nparent = int(rng.integers(1, 60))
        group = rng.integers(0, nparent, int(rng.integers(1, 400)))
        own = rng.random((group.size, columns)) * 10.0 ** rng.integers(-8, 2)
        parent = np.stack([np.bincount(group, own[:, j], minlength=nparent) for j in range(columns)], axis=1)
        parent *= 1 + rng.choice([0.0, 1e-12, 1e-6, 1e-3, -1e-3], parent.shape)
        tol = rng.choice([0.0, 1e-9, 1e-6, 1e-4], group.size) * rng.random(group.size)
        own[rng.random(own.shape) < 0.01] = rng.choice([np.nan, np.inf, -np.inf])
        parent[rng.random(parent.shape) < 0.02] = np.nan
        want = _reference_agreement(own, parent, group, tol, floor)
        got = grouped_agreement(own, parent, group, tol, floor)
        for a, b in zip(want, got):
            np.testing.assert_array_equal(np.asarray(a).view(np.uint64), np.asarray(b).view(np.uint64))
    with pytest.raises(ValueError, match="parent index 1 outside"):
        grouped_agreement(np.ones((2, 1)), np.ones((1, 1)), np.array([0, 1]), np.ones(2), 0.0)
    with pytest.raises(ValueError, match="integer indices"):    # not truncated to parent 0
        grouped_agreement(np.ones((2, 1)), np.ones((1, 1)), np.array([0.0, 0.7]), np.ones(2), 0.0)


# --- a float32 renderer's pdf (Float32DirectionPdf) and the pdf's batch ----------------------
def _vmf32(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """A von Mises-Fisher lobe (kappa 20) about a tilted axis, evaluated in float32 as a float32
    renderer would."""
    k = np.float32(20.0)
    axis = np.array([0.6, 0.0, 0.8], dtype=np.float32)
    cos = x * axis[0] + y * axis[1] + z * axis[2]
    return k / np.float32(2 * math.pi * (1 - math.exp(-40.0))) * np.exp(k * (cos - np.float32(1)))


class _Renderer:
    """The lobe as a float32 renderer's adapter offers it: pdf on float64 directions (rounded to
    float32 first), float32_columns on float32 columns; the points each was called on counted."""

    def __init__(self):
        self.calls = {"pdf": [], "columns": []}

    def pdf(self, x: np.ndarray) -> np.ndarray:
        self.calls["pdf"].append(x.shape[0])
        c = x.astype(np.float32)
        return _vmf32(c[:, 0], c[:, 1], c[:, 2])

    def float32_columns(self, c: np.ndarray) -> np.ndarray:
        assert c.dtype == np.float32 and c.shape[0] == 3
        self.calls["columns"].append(c.shape[1])
        return _vmf32(c[0], c[1], c[2])


@pytest.mark.parametrize("pole", ["z", "y"])
def test_a_float32_direction_pdf_integrates_to_the_plain_pdfs_bits(pole):
    """Float32DirectionPdf: the transform's table nodes reach the pdf as float32 columns (no
    float64 directions), and the base grid's integrals, their errors and the transform's tables
    are the plain pdf's bits; a larger pdf_batch changes no bit, only how many calls it takes."""
    from harness.samplers import Float32DirectionPdf, SamplerTest
    from harness.samplers.domains import Domain

    dom = Domain("sphere", pole=pole)
    plain = _Renderer()
    ref = SamplerTest(plain.pdf, dom, sample_count=100_000)
    results = []
    for batch in (None, 2**19):
        r = _Renderer()
        test = SamplerTest(Float32DirectionPdf(r.pdf, r.float32_columns), dom, sample_count=100_000,
                           pdf_batch=batch)
        moments = np.array(ref.h_moments), np.array(test.h_moments)
        pairs = [(ref.mass, test.mass), (ref.err, test.err), moments]
        for a, b in pairs:
            np.testing.assert_array_equal(a.view(np.uint64), b.view(np.uint64))
        for t, u in [(ref.transform.marginal, test.transform.marginal),
                     (ref.transform.conditional, test.transform.conditional)]:
            for field in ("lo", "hi", "start", "mass", "strip_mass"):
                a, b = getattr(t, field), getattr(u, field)
                np.testing.assert_array_equal(a.view(np.uint64), b.view(np.uint64))
            assert t.error == u.error
        # the same evaluations: the transform's tables' and the base grid's moment columns
        # through the float32 columns, the pre-grid's square columns through pdf; the plain
        # pdf's rounding was judged at the pre-grid's 32 x 64 centres first, the declared
        # float32 pdf's is the float32 floor without a call
        assert plain.calls["pdf"][0] == 32 * 64 and test.floor == ref.floor
        assert sum(r.calls["columns"]) + sum(r.calls["pdf"]) == sum(plain.calls["pdf"]) - 32 * 64
        assert sum(r.calls["columns"]) > sum(r.calls["pdf"])
        results.append(r.calls["columns"])
    assert max(results[0]) <= 2**16 < max(results[1]) and len(results[1]) < len(results[0])


def test_a_float32_direction_pdf_that_returns_the_wrong_count_is_named():
    from harness.samplers import Float32DirectionPdf, SamplerTest
    from harness.usercode import UserCodeError

    r = _Renderer()
    with pytest.raises(UserCodeError, match=r"_Renderer\.pdf returned shape \(3,\) for float32 direction "
                                            r"columns of shape \(3, \d+\); expected shape \(\d+,\)"):
        SamplerTest(Float32DirectionPdf(r.pdf, lambda c: r.float32_columns(c)[:3]), "sphere",
                    sample_count=10_000)


def test_a_float32_direction_pdfs_own_directions_are_checked_and_may_decline():
    """Float32DirectionPdf.directions: None declines a call (pdf gets the float64 points: the
    same bits); an exception, a result of another shape or dtype, or not a pair, is a
    UserCodeError naming it."""
    import reference_estimators as rest

    from harness.samplers import Float32DirectionPdf, SamplerTest
    from harness.usercode import UserCodeError

    r = _Renderer()
    ref = SamplerTest(r.pdf, "sphere", sample_count=10_000)

    def own(lo, hi, nodes):   # the domain's own directions, as the core gives them
        return rest.cubature_float32_directions("sphere", lo, hi, nodes)

    for directions in (own, lambda lo, hi, nodes: None):
        test = SamplerTest(Float32DirectionPdf(r.pdf, r.float32_columns, directions), "sphere",
                           sample_count=10_000)
        np.testing.assert_array_equal(test.mass.view(np.uint64), ref.mass.view(np.uint64))
        np.testing.assert_array_equal(test.transform.marginal.start, ref.transform.marginal.start)

    def raises(lo, hi, nodes):
        raise RuntimeError("planted")

    bad = {"raises": (raises, "raised RuntimeError: planted"),
           "float64": (lambda lo, hi, nodes: (own(lo, hi, nodes)[0].astype(float), own(lo, hi, nodes)[1]),
                       r"returned columns \(3, \d+\) float64"),
           "short": (lambda lo, hi, nodes: (own(lo, hi, nodes)[0][:, :5], own(lo, hi, nodes)[1]),
                     "expected None or"),
           "not a pair": (lambda lo, hi, nodes: own(lo, hi, nodes)[0], "returned ndarray"),
           "ragged": (lambda lo, hi, nodes: ([[1.0], [1.0, 2.0]], own(lo, hi, nodes)[1]), "not two arrays"),
           "float ok": (lambda lo, hi, nodes: (own(lo, hi, nodes)[0], own(lo, hi, nodes)[1].astype(float)),
                        r"ok \(\d+,\) float64"),
           "no ok": (lambda lo, hi, nodes: (own(lo, hi, nodes)[0], None), r"ok \(\) object")}
    for what, (directions, match) in bad.items():
        with pytest.raises(UserCodeError, match=match):
            SamplerTest(Float32DirectionPdf(r.pdf, r.float32_columns, directions), "sphere",
                        sample_count=10_000)


@pytest.mark.parametrize("batch", [0, -5, 2.5, "big", True])
def test_pdf_batch_must_be_a_positive_count(batch):
    from harness.samplers import SamplerTest

    with pytest.raises(ValueError, match="'pdf_batch' must be a positive number of points"):
        SamplerTest(_Renderer().pdf, "sphere", sample_count=10_000, pdf_batch=batch)
