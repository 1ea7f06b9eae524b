"""How the transform's CDF tables refine: coarse pieces across the axis where they agree with the fine
ones, and leaves graded toward singular ends."""
from __future__ import annotations

import math

import numpy as np
import pytest

import harness.samplers.cdf_tables as cdf_tables
from harness.samplers.cdf_tables import _split
from harness.samplers.transform import Transform


def _marginal_with(monkeypatch, coarse: int, q) -> tuple:
    """The marginal of q (a function on the square) at 1e6 samples, refined with ``coarse``
    pieces across s1 where they agree with the 32 fine ones, and q's evaluation count in the
    marginal's tabulation alone."""
    import harness.samplers.transform as tr

    monkeypatch.setattr(tr, "_COARSE_PIECES", coarse)
    calls = []
    tabulate = getattr(tr.tabulate, "__wrapped__", tr.tabulate)   # not an earlier call's wrapper

    def marginal_only(q, k, axis, *args, **kwargs):
        if axis == 0:
            before = len(calls)
            table = tabulate(counted, k, axis, *args, **kwargs)
            calls[before:] = [sum(calls[before:])]
            return table
        return tabulate(q, k, axis, *args, **kwargs)

    def counted(sp: np.ndarray) -> np.ndarray:
        calls.append(sp.shape[0])
        return q(sp)

    marginal_only.__wrapped__ = tabulate
    monkeypatch.setattr(tr, "tabulate", marginal_only)
    return Transform.build(q, 2, 1_000_000).marginal, sum(calls)


def test_the_marginal_refines_with_coarse_pieces_only_where_they_agree_with_the_fine_ones(monkeypatch):
    """A density flat across s1 (q = 2 s0, the cosine hemisphere in its parameters) is refined
    with 4 pieces across s1 instead of 32: the same leaves, a bound as small and within it of
    the exact CDF s0^2, for an eighth of the marginal's pdf calls past its first pass.  A
    density with a step across s1 (2 s0, ten times as dense on a band of s1) keeps the 32:
    its table is the fine one's bit for bit, and within its bound of the exact CDF too."""
    def flat(sp):
        return 2 * sp[:, 0]

    fine, fine_calls = _marginal_with(monkeypatch, 32, flat)   # 32 "coarse" pieces: the fine ones
    coarse, coarse_calls = _marginal_with(monkeypatch, 4, flat)
    # 2.4 -> 0.8 million calls: the first pass is the fine pieces' in both, the refinement's fall 8x
    assert coarse_calls <= fine_calls / 2.4, (coarse_calls, fine_calls)
    assert np.array_equal(coarse.lo, fine.lo) and coarse.error <= 1.01 * fine.error
    c = np.append(coarse.lo, 1.0)
    assert np.max(np.abs(np.append(coarse.start, 1.0) - c * c)) <= coarse.error + 1e-12

    def stepped(sp):   # ten times as dense for s1 in [0.3, 0.33), a step no box resolves
        return 2 * sp[:, 0] * np.where((sp[:, 1] >= 0.3) & (sp[:, 1] < 0.33), 10.0, 1.0) / 1.27

    fine, _ = _marginal_with(monkeypatch, 32, stepped)
    kept, _ = _marginal_with(monkeypatch, 4, stepped)
    assert all(np.array_equal(getattr(kept, f), getattr(fine, f)) for f in ("lo", "start", "mass"))
    assert kept.error == fine.error
    c = np.append(kept.lo, 1.0)
    assert np.max(np.abs(np.append(kept.start, 1.0) - c * c)) <= kept.error + 1e-12


def test_the_conditional_takes_the_strips_own_pieces_only_in_strips_where_they_agree(monkeypatch):
    """The conditional's strips refine with one piece across each (its own cuts: steps, a
    pole's grading) where that agrees with its SUBSTRIPS pieces on the starting leaves, strip
    by strip.  q = 1 + 0.9 sin(2 pi s1), its sign flipped on a band of s0 inside strip 5
    (between the nodes of one piece's halves, on nodes of the substrips' halves), and flat
    along s0 on average, so the strips are the 32 equal ones: strip 5 keeps its substrips,
    which see the band, the other 31 take one piece, for half the pdf calls of the substrips
    everywhere; both strips' tables are within their bound of the exact conditional CDF."""
    band = (5 / 32 + 0.4 / 64, 5 / 32 + 0.6 / 64)

    def q(sp):
        flipped = (sp[:, 0] >= band[0]) & (sp[:, 0] < band[1])
        return 1 + np.where(flipped, -0.9, 0.9) * np.sin(2 * np.pi * sp[:, 1])

    def built(mixed) -> tuple[Transform, int, list]:
        calls, takes = [0], []

        def recorded(take, *args):
            takes.append(take.copy())
            return mixed(take, *args)

        def counted(sp):
            calls[0] += sp.shape[0]
            return q(sp)

        monkeypatch.setattr(cdf_tables, "_mixed", recorded)
        return Transform.build(counted, 2, 1_000_000, total=1.0), calls[0], takes

    t, calls, takes = built(cdf_tables._mixed)
    fine, fine_calls, _ = built(lambda take, coarse, fine, fine_used: (fine, fine_used))
    assert len(takes) == 1 and np.flatnonzero(~takes[0]).tolist() == [5]   # the marginal is flat: not tried
    assert calls <= 0.6 * fine_calls, (calls, fine_calls)
    assert np.allclose(t.edges * 32, np.arange(33))
    # the strips' masses as the substrips everywhere find them, the bound no looser
    assert np.allclose(t.conditional.strip_mass, fine.conditional.strip_mass, rtol=1e-7, atol=0)
    assert t.conditional.error <= 1.01 * fine.conditional.error

    def exact(s1: np.ndarray, g: int) -> np.ndarray:   # the CDF of s1 over strip g's s0
        lo, hi = t.edges[g], t.edges[g + 1]
        flipped = max(0.0, min(hi, band[1]) - max(lo, band[0]))
        ramp = 0.9 * (1 - np.cos(2 * np.pi * s1)) / (2 * np.pi)
        return s1 + ramp * ((hi - lo) - 2 * flipped) / (hi - lo)

    s1 = np.linspace(0, 1, 1001)
    for g in (4, 5):
        u = t(np.column_stack([np.full_like(s1, (t.edges[g] + t.edges[g + 1]) / 2), s1]))
        assert np.max(np.abs(u[:, 1] - exact(s1, g))) <= t.conditional.error, g


def test_coarse_pieces_are_tried_only_in_strips_that_refine(monkeypatch):
    """tabulate with two strips: strip 0 a lobe along s1 (it refines; one piece across agrees
    with its four), strip 1 flat (fine on its starting leaves: not tried).  Strip 0's table is
    the one it gets tabulated alone with the same pieces, strip 1's pdf calls are its own
    without coarse pieces: the two add up to the pair's, no coarse pass over strip 1."""
    def q(sp):
        lobe = np.exp(-0.5 * ((sp[:, 1] - 0.4) / 0.05) ** 2) * (1 + sp[:, 0])
        return np.where(sp[:, 0] < 0.5, lobe, 1.0)

    fine = np.array([[[0, .125], [.125, .25], [.25, .375], [.375, .5]],
                     [[.5, .625], [.625, .75], [.75, .875], [.875, 1]]])
    coarse = np.array([[[0, .5]], [[.5, 1]]])

    def tabulated(pieces, coarse_pieces):
        calls = [0]

        def counted(sp):
            calls[0] += sp.shape[0]
            return q(sp)

        return cdf_tables.tabulate(counted, 2, 1, pieces, 16, 2e-5, coarse=coarse_pieces), calls[0]

    takes = []
    mixed = cdf_tables._mixed

    def recorded(take, *args):
        takes.append(take.copy())
        return mixed(take, *args)

    monkeypatch.setattr(cdf_tables, "_mixed", recorded)
    both, both_calls = tabulated(fine, coarse)
    assert [t.tolist() for t in takes] == [[True, False]]
    alone, alone_calls = tabulated(fine[:1], coarse[:1])
    flat, flat_calls = tabulated(fine[1:], None)
    _, fine_calls = tabulated(fine[:1], None)
    assert alone_calls <= 0.6 * fine_calls, (alone_calls, fine_calls)   # the one piece taken
    assert both_calls == alone_calls + flat_calls
    first = both.strip == 0
    assert np.array_equal(both.lo[first], alone.lo) and np.array_equal(both.mass[first], alone.mass)
    assert both.lo[~first].size == 4 * 16 and flat.error < 1e-12
    with pytest.raises(ValueError, match="square"):
        cdf_tables.tabulate(q, 1, 0, np.zeros((1, 1, 2)), 16, 2e-5, coarse=np.zeros((1, 1, 2)))


def test_mixed_pieces_pad_only_where_strips_mix():
    coarse = np.array([[[0.0, 0.5]], [[0.5, 1.0]]])
    fine = np.array([[[0.0, 0.25], [0.25, 0.5]], [[0.5, 0.75], [0.75, 1.0]]])
    fine_used = np.array([2, 2])
    pieces, used = cdf_tables._mixed(np.array([True, True]), coarse, fine, fine_used)
    assert pieces is coarse and used.tolist() == [1, 1]
    pieces, used = cdf_tables._mixed(np.array([False, False]), coarse, fine, fine_used)
    assert pieces is fine and used is fine_used
    pieces, used = cdf_tables._mixed(np.array([True, False]), coarse, fine, fine_used)
    assert pieces.tolist() == [[[0.0, 0.5], [0.5, 0.5]], fine[1].tolist()] and used.tolist() == [1, 2]


@pytest.mark.parametrize("name, q, cdf, fewer", [
    # singular at both ends of s0, like a pole (uniform_theta_sphere) or the disk's centre
    ("arcsine", lambda sp: 1 / (math.pi * np.sqrt(sp[:, 0] * (1 - sp[:, 0]))),
     lambda x: 2 / math.pi * np.arcsin(np.sqrt(x)), 2.5),
    # a step along s0 inside a starting leaf, like the cone's rim
    ("step", lambda sp: np.where(sp[:, 0] < 0.3, 0.5, 1.5) / 1.2,
     lambda x: np.where(x < 0.3, 0.5 * x, 0.15 + 1.5 * (x - 0.3)) / 1.2, 1.5),
])
def test_a_singularity_or_step_along_the_axis_keeps_the_coarse_pieces(monkeypatch, name, q, cdf, fewer):
    """Where a density flat across s1 has a singularity or a step along s0, the fine pieces'
    own cubature misses its tolerance on those leaves, and the coarse ones miss it by as much
    (within 1 %): pieces across do not resolve structure along the axis.  The coarse pieces
    are then kept: the same leaves, a bound within 1 % of the fine one's and within it of the
    exact CDF, for fewer pdf calls (they were refused before, costing the pole sampler 25
    million pdf evaluations in its marginal where 5 do)."""
    fine, fine_calls = _marginal_with(monkeypatch, 32, q)
    coarse, coarse_calls = _marginal_with(monkeypatch, 4, q)
    # arcsine 8.5 -> 2.1 million calls, step 2.9 -> 1.0 (graded cuts at the poles, _split; halved,
    # the arcsine's were 12.7 -> 2.6)
    assert coarse_calls <= fine_calls / fewer, (coarse_calls, fine_calls)
    assert np.array_equal(coarse.lo, fine.lo) and coarse.error <= 1.01 * fine.error
    assert np.max(np.abs(np.append(coarse.start, 1.0) - cdf(np.append(coarse.lo, 1.0)))) <= coarse.error


def test_leaves_are_graded_toward_an_end_of_the_axis_that_holds_their_mass_and_halved_elsewhere():
    w = 0.125
    tiny = 2.0**-27    # graded, its first child would be 2^-31 wide: under _MIN_WIDTH, so halved
    strip = np.array([0, 0, 1, 1, 2, 3, 4])
    lo = np.array([0.0, 1 - w, 0.25, 0.0, 0.0, 1 - w, 0.0])
    hi = np.array([w, 1.0, 0.5, w, 0.25, 1.0, tiny])
    qs = np.array([[10, 1, 1, 1],      # singular at s = 0: graded toward 0
                   [1, 1, 1, 10],      # at s = 1: toward 1
                   [10, 1, 1, 1],      # not at an end: halved
                   [1.9, 1, 1, 1],     # at an end, its end quarter under twice its neighbour: halved
                   [10, 1, 1, 1],      # graded but for the break inside: cut there
                   [1, 1, 10, 1.0],    # its largest quarter not the end one: halved
                   [10, 1, 1, 1]])     # too narrow to grade: halved
    s, a, b = _split(strip, lo, hi, qs, np.array([0.2]))
    assert a.tolist() == [0, w / 16, w / 8, w / 4, w / 2, 1 - w, 1 - w / 2, 1 - w / 4, 1 - w / 8, 1 - w / 16,
                          0.25, 0.375, 0, w / 2, 0, 0.2, 1 - w, 1 - w / 2, 0, tiny / 2]
    count = [5, 5, 2, 2, 2, 2, 2]
    assert s.tolist() == np.repeat(strip, count).tolist()
    # the children tile their leaves, in order, the ends exactly
    first = np.cumsum([0] + count)
    for i, j, leaf_lo, leaf_hi in zip(first[:-1], first[1:], lo, hi):
        assert a[i] == leaf_lo and b[j - 1] == leaf_hi and np.array_equal(b[i:j - 1], a[i + 1:j])


def test_graded_cuts_keep_the_halved_tables_leaves_for_fewer_pdf_calls(monkeypatch):
    """The pole density (arcsine along s0): graded cuts skip the levels of refinement that
    halving spends reaching _MIN_WIDTH at each end (a pass each, the singular box refined to the
    cubature's depth limit again each time), and keep the same leaves: a quarter's integral is
    its own boxes' whatever level made it, so the table is the halved one's bit for bit."""

    def arcsine(sp):
        return 1 / (math.pi * np.sqrt(sp[:, 0] * (1 - sp[:, 0])))

    graded, graded_calls = _marginal_with(monkeypatch, 4, arcsine)
    monkeypatch.setattr(cdf_tables, "_GRADED", math.inf)
    halved, halved_calls = _marginal_with(monkeypatch, 4, arcsine)
    # 2.6 -> 2.1 million calls (with the fine pieces throughout, 12.7 -> 8.5)
    assert graded_calls <= halved_calls / 1.2, (graded_calls, halved_calls)
    assert all(np.array_equal(getattr(graded, f), getattr(halved, f)) for f in ("lo", "hi", "start", "mass"))
    assert graded.error == halved.error


def test_a_light_lobe_at_the_end_gets_finer_graded_leaves_within_their_bound(monkeypatch):
    """A lobe at s = 0 holding 3e-5 of the mass: graded cuts make leaves at the end that halving
    would have stopped short of (its leaf [0, w/2) was fine already), so the table differs from
    the halved one: finer, with a bound as small or smaller, and within it of the exact CDF."""

    def lobe(sp):
        return 1 + 30 * np.exp(-sp[:, 0] / 1e-6)

    def cdf(x):
        return (x + 30e-6 * -np.expm1(-x / 1e-6)) / (1 + 30e-6)

    graded = Transform.build(lobe, 1, 1_000_000).marginal
    monkeypatch.setattr(cdf_tables, "_GRADED", math.inf)
    halved = Transform.build(lobe, 1, 1_000_000).marginal
    assert graded.lo.size > halved.lo.size and graded.error <= halved.error   # 4144 and 4136 leaves
    for table in (graded, halved):
        edges = np.append(table.lo, 1.0)
        assert np.max(np.abs(np.append(table.start, 1.0) - cdf(edges))) <= table.error
