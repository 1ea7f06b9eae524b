"""The table samplers (piecewise_constant_1d/2d): bins, breakpoints, empty bins, refused uniforms, vector
lanes against one at a time."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import reference_estimators as rest

from tests.core.sampler_cases import CASES, breakpoint_u, canonical, fmt, table_cdf


@pytest.mark.parametrize("case", [c for c in CASES if c.name == "piecewise_constant_1d"], ids=str)
def test_points_near_table_breakpoints_stay_in_their_bin(case):
    """u within a few 2^-52 of a CDF value (and the largest canonical uniforms, 1 - 2^-53)
    used to round x onto the edge of the neighbouring bin, where pdf(x) is that bin's
    density, possibly 0; the sampler must keep x inside the bin u selected."""
    s = case.make()
    t = np.asarray(case.table, dtype=float)
    u = np.concatenate([breakpoint_u(table_cdf(t)[1:-1]), canonical(2**52 - 1 - np.arange(64))])
    x, p = s.sample(u)
    q = s.pdf(x)
    bad = (p != q) | (p <= 0)
    assert not bad.any(), f"{case}: (u, x, sample pdf, pdf(x)):\n  {fmt(u[bad], x[bad], p[bad], q[bad])}"
    np.testing.assert_allclose(s.invert(x), u, atol=1e-9)


def neumaier_cdf(values: np.ndarray) -> np.ndarray:
    """A table's CDF as the core builds it: running compensated (Neumaier) sums over the
    values in order, each divided by the total, the last entry set to 1."""
    sums, total, comp = [0.0], 0.0, 0.0
    for v in map(float, values):
        t = total + v
        comp += (total - t) + v if abs(total) >= abs(v) else (v - t) + total
        total = t
        sums.append(total + comp)
    cdf = np.array(sums) / sums[-1]
    cdf[-1] = 1.0
    return cdf


@pytest.mark.parametrize("bins", [1, 2, 3, 7, 8, 15, 16, 17, 31, 32, 33, 63, 64, 65, 80, 200, 512, 513,
                                  4096, 4097, 40_000])
def test_table_bins_are_the_last_with_cdf_at_or_below_u(bins):
    """The bin a table sampler picks for u is pbrt's, the last o with cdf[o] <= u moved down
    past empty bins, for tables counted in one level (up to 16, 32 or 64 bins by ISA) and in
    two to five, with empty bins and u at, just below and just above every CDF value."""
    rng = np.random.default_rng(bins)
    t = rng.random(bins) ** 4
    t[rng.random(bins) < 0.3] = 0.0
    t[rng.integers(bins)] = 1.0
    s = rest.sampler("piecewise_constant_1d", table=t, a=0.0, b=1.0)
    cdf = neumaier_cdf(t)
    u = np.concatenate([rng.random(20_000), cdf, np.nextafter(cdf, 0.0), np.nextafter(cdf, 1.0)])
    u = u[(u >= 0) & (u <= 1)]
    want = np.minimum(np.searchsorted(cdf, u, side="right") - 1, bins - 1)
    full = cdf[1:] > cdf[:-1]
    below = np.maximum.accumulate(np.where(full, np.arange(bins), 0))   # last non-empty bin <= o, or 0
    want = below[want]
    x, p = s.sample(u)
    got = np.minimum(np.floor(x * bins), bins - 1).astype(int)
    bad = got != want
    assert not bad.any(), f"(u, bin, pbrt's bin):\n  {fmt(u[bad], got[bad], want[bad])}"


@pytest.mark.parametrize("shape", [(1, 1), (3, 5), (16, 16), (8, 64), (64, 8), (128, 256)])
def test_table_2d_pdf_in_batches_equals_pdf_point_by_point(shape):
    """pdf of many points (vector lanes) and of one point at a time (the scalar path) agree
    bit for bit, on cell edges, the square's boundary, just outside it and inside empty rows."""
    rng = np.random.default_rng(shape[0] * 1000 + shape[1])
    t = rng.random(shape)
    t[rng.random(shape) < 0.2] = 0.0
    t[rng.integers(shape[0])] = 0.0
    t[0, 0] = 1.0
    s = rest.sampler("piecewise_constant_2d", table=t)
    edges = np.stack([rng.integers(0, shape[1] + 1, 3000) / shape[1],
                      rng.integers(0, shape[0] + 1, 3000) / shape[0]], axis=1)
    x = np.concatenate([rng.random((3000, 2)) * 1.2 - 0.1, edges,
                        np.nextafter(edges, rng.choice([-1.0, 2.0], edges.shape))])
    batch = s.pdf(x)
    one = np.array([s.pdf(x[i:i + 1])[0] for i in range(len(x))])
    bad = batch.view(np.uint64) != one.view(np.uint64)
    assert not bad.any(), f"(x, batch pdf, one point's pdf):\n  {fmt(x[bad], batch[bad], one[bad])}"
    assert (batch[(x < 0).any(axis=1) | (x > 1).any(axis=1)] == 0).all()


def test_a_bin_edge_near_zero_ends_the_move_into_the_bin():
    """Over [-0.3, 1.1] in 14 bins, u = 3/14 puts x at -2.8e-17 + rounding, just above bin 3's
    edge near 0 in x but in bin 2 by bin_of_x; the sampler moves x into bin 3.  Stepping one ulp
    at a time, it took ~10^15 steps there (the ulps near 0 are tiny): sample() never returned.
    Run in a subprocess so that a regression fails in a minute instead of hanging the suite."""
    code = ("import numpy as np, reference_estimators as rest\n"
            "a = -3 * 0.1\n"
            "s = rest.sampler('piecewise_constant_1d', table=np.ones(14), a=a, b=a + 14 * 0.1)\n"
            "x, p = s.sample(np.array([3 / 14]))\n"
            "print(repr(float(x[0])))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    x = float(r.stdout)
    a, b = -3 * 0.1, -3 * 0.1 + 14 * 0.1

    def bin_of_x(v):   # the sampler's bin_of_x, the same double operations
        return min(int((v - a) / (b - a) * 14), 13)

    # the first double of bin 3: the nearest to where rounding left x
    assert bin_of_x(x) == 3 and bin_of_x(np.nextafter(x, -1.0)) == 2, x
    assert abs(x) < 1e-15


@pytest.mark.parametrize("u", [np.nan, -0.25, 1.5, np.inf])
@pytest.mark.parametrize("name", ["piecewise_constant_1d", "piecewise_constant_2d", "ggx", "linear"])
def test_sample_refuses_uniforms_outside_the_unit_interval(name, u):
    """Canonical uniforms outside [0, 1] (or NaN) are refused with the count and an example
    (a table sampler's search has no bin for them: it used to hang)."""
    s = rest.sampler(name, table=np.ones((3, 4)) if name.endswith("2d") else np.ones(4)) \
        if name.startswith("piecewise") else rest.sampler(name)
    us = np.full((5, s.udim), 0.5)
    us[3, -1] = u
    refusal = r"canonical uniforms in \[0, 1\]; 1 of \d+ values are not \(u\[3\] = "
    with pytest.raises(ValueError, match=refusal):
        s.sample(us if s.udim > 1 else us[:, 0])
    x, p = s.sample(np.zeros((2, s.udim)) if s.udim > 1 else np.array([0.0, 1.0]))   # the ends are valid
    assert np.all(np.isfinite(p))


@pytest.mark.parametrize("case", [c for c in CASES if c.table is not None and 0 in np.ravel(c.table)],
                         ids=str)
def test_pdf_is_zero_inside_empty_table_bins(case):
    s = case.make()
    t = np.asarray(case.table, dtype=float)
    if t.ndim == 1:
        a, b = case.p["a"], case.p["b"]
        centres = a + (b - a) * (np.flatnonzero(t == 0) + 0.5) / t.size
        x = centres
    else:
        rows, cols = t.shape
        r = np.flatnonzero(t.sum(axis=1) == 0)
        yy, xx = np.meshgrid((r + 0.5) / rows, (np.arange(cols) + 0.5) / cols, indexing="ij")
        x = np.column_stack([xx.ravel(), yy.ravel()])
    p = s.pdf(x)
    assert np.all(p == 0), f"{case}: pdf != 0 inside empty bins (x, pdf):\n  {fmt(x[p != 0], p[p != 0])}"


@pytest.mark.parametrize("a, b", [(0.0, 1.0), (-0.3, 1.1), (2.0, 6.0), (1.0, 1.0 + 6 * 2.0**-52)])
@pytest.mark.parametrize("table", [np.arange(1.0, 17.0), np.array([0, 3, 0, 0, 1, 5, 0, 2, 2, 0, 1, 4, 0.0])],
                         ids=["16 bins", "13 bins, empty ones"])
def test_table_samplers_agree_in_vector_lanes_and_one_at_a_time(table, a, b):
    """The table samplers check in vector lanes that a block's points landed in their bins and
    send the rest through the scalar step into the bin: a batch against the same uniforms
    passed one at a time (the scalar path alone) gives the same points, pdfs and bins bit for
    bit, on intervals whose width is a power of two or not and on one whose bins hold no double
    ([1, 1 + 6 ulp] in 16 or 13 bins), u at every CDF value and its neighbours included."""
    s = rest.sampler("piecewise_constant_1d", table=table, a=a, b=b)
    cdf = neumaier_cdf(table)
    u = np.concatenate([[0.0, np.nextafter(1.0, 0.0), 1.0], cdf, np.nextafter(cdf, 0.0),
                        np.nextafter(cdf, 1.0), np.random.default_rng(5).random(1000)])
    u = u[(u >= 0) & (u <= 1)]
    x, p = s.sample(u)
    one = [s.sample(u[i:i + 1]) for i in range(u.size)]
    np.testing.assert_array_equal(x.view(np.uint64), np.concatenate([o[0] for o in one]).view(np.uint64))
    np.testing.assert_array_equal(p, np.concatenate([o[1] for o in one]))
    assert np.all((x >= a) & (x <= b))


def test_the_2d_table_sampler_agrees_in_vector_lanes_and_one_at_a_time():
    """The 2-D table sampler reads each point's density off its cells for the row and column
    the point landed in: a batch equals the same uniforms one at a time bit for bit, and each
    density is the marginal's times the row's conditional's, as the tables give them."""
    t = np.random.default_rng(6).gamma(0.7, 1.0, (7, 13))
    t[2] = 0.0
    t[4, 3:6] = 0.0
    s = rest.sampler("piecewise_constant_2d", table=t)
    u = np.random.default_rng(7).random((2003, 2))
    u[:3] = [[0.0, 0.0], [np.nextafter(1.0, 0.0), np.nextafter(1.0, 0.0)], [1.0, 1.0]]
    x, p = s.sample(u)
    one = [s.sample(u[i:i + 1]) for i in range(u.shape[0])]
    np.testing.assert_array_equal(x, np.concatenate([o[0] for o in one]))
    np.testing.assert_array_equal(p, np.concatenate([o[1] for o in one]))
    rows = np.minimum(np.floor(x[:, 1] * 7), 6).astype(int)
    cols = np.minimum(np.floor(x[:, 0] * 13), 12).astype(int)
    marginal = t.mean(axis=1) / t.mean()                     # the rows' densities in y
    with np.errstate(invalid="ignore"):                      # the empty row: never drawn
        conditional = t / t.mean(axis=1, keepdims=True)      # each row's density in x
    np.testing.assert_allclose(p, marginal[rows] * conditional[rows, cols], rtol=1e-13)
    assert np.all(t[rows, cols] > 0)


SMALL_TABLES = [((1, 1), ""), ((2, 1), ""), ((3, 5), ""), ((16, 16), ""), ((16, 64), ""), ((5, 33), ""),
                ((16, 16), "first row empty"), ((9, 12), "first column empty"), ((17, 4), ""), ((16, 65), ""),
                ((6, 6), "an empty cell inside")]


@pytest.mark.parametrize("shape, zeros", SMALL_TABLES)
def test_small_2d_tables_sample_the_same_in_vector_lanes_and_one_at_a_time(shape, zeros):
    """Tables of at most 16 rows and 64 columns whose CDFs have no empty bin after the first
    take the vector kernel of small_table2d.h on AVX-512 builds (Sampler.kernel; whole vectors
    of a batch, while one point alone takes sample_many's path; 17 rows, 65 columns or an empty
    cell inside a row never do): the same points and densities bit for bit, on uniforms that
    are exactly the tables' CDF entries (inverted from the cells' corners), an ulp either side
    of them, 0 and 1."""
    rng = np.random.default_rng(shape[0] * 100 + shape[1])
    t = rng.gamma(0.5, 1.0, shape) + 1e-9
    if zeros == "first row empty":
        t[0] = 0.0
    elif zeros == "first column empty":
        t[:, 0] = 0.0
    elif zeros:
        t[2, 3] = 0.0
    s = rest.sampler("piecewise_constant_2d", table=t)
    fits = shape[0] <= 16 and shape[1] <= 64 and zeros != "an empty cell inside"
    avx512 = rest.build_info()["isa"] == "AVX-512"
    assert s.kernel == ("small table in vector lanes" if fits and avx512 else "batch loop")
    corners = np.stack(np.meshgrid(np.arange(shape[1] + 1) / shape[1], np.arange(shape[0] + 1) / shape[0]),
                       axis=-1).reshape(-1, 2)
    entries = s.invert(np.minimum(corners, np.nextafter(1.0, 0.0)))
    entries = entries[np.all(np.isfinite(entries), axis=1)]
    u = np.concatenate([entries, np.nextafter(entries, 0.0), np.nextafter(entries, 2.0),
                        [[0.0, 0.0], [1.0, 1.0], [0.0, 1.0], [1.0, 0.0], [np.nextafter(1.0, 0.0)] * 2],
                        rng.random((4001, 2))])
    u = np.clip(u, 0.0, 1.0)
    x, p = s.sample(u)
    one = [s.sample(u[i:i + 1]) for i in range(u.shape[0])]
    np.testing.assert_array_equal(x.view(np.uint64), np.concatenate([o[0] for o in one]).view(np.uint64))
    np.testing.assert_array_equal(p.view(np.uint64), np.concatenate([o[1] for o in one]).view(np.uint64))
    rows = np.minimum(np.floor(x[:, 1] * shape[0]), shape[0] - 1).astype(int)
    cols = np.minimum(np.floor(x[:, 0] * shape[1]), shape[1] - 1).astype(int)
    assert np.all(t[rows, cols] > 0)
    np.testing.assert_allclose(p, t[rows, cols] / t.mean(), rtol=1e-12)


@pytest.mark.parametrize("shape", [(16, 16), (4, 128)], ids=["small table in vector lanes", "batch loop"])
@pytest.mark.parametrize("n", [1003, 70001])
def test_a_table_samplers_bad_densities_are_screened_where_they_are_drawn(shape, n):
    """A table of subnormal values has every cell's density overflow to +inf: importance
    sampling and MIS with the uniform square report every sample as a bad pdf (none averaged),
    whether the small-table kernel screens its lanes or the batch loop's points are screened
    after, at vector and block tails."""
    s = rest.sampler("piecewise_constant_2d", table=np.full(shape, 1e-320))
    avx512 = rest.build_info()["isa"] == "AVX-512"
    assert s.kernel == ("small table in vector lanes" if shape == (16, 16) and avx512 else "batch loop")
    assert np.all(s.sample(np.full((9, 2), 0.3))[1] == np.inf)
    box = rest.techniques("gaussian2d")["mis_balance:uniform_box+piecewise_constant_2d"].mis[0]
    for technique in (rest.importance(s), rest.mis([box, s])):
        e = rest.integrate("gaussian2d", technique, n, seed=1)
        assert e.issues == {"bad_pdf": n} and e.n == 0
