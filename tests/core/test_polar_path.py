"""The estimators' polar path: importance sampling and MIS of an integrand that reads a
direction's cos(theta) alone, by samplers whose pdf does too, draw no azimuth, and where f is
one of the samplers' pdfs (the same polar_function) compute it once.  It must give the
general path's bits, and hand every block with something to report back to it."""
from __future__ import annotations

import numpy as np
import pytest

import reference_estimators as rest

N = rest.CHUNK_SIZE + 4099     # a partial chunk and a partial block, the scalar tails included
# a partial block of 13 generator rows of an MIS pair's 8 samples: the fused pair's loop that
# draws its rows inside, an odd count for its rows drawn ahead (not whole rows of importance
# sampling's 16 samples: its block draws first)
N_ROWS = rest.CHUNK_SIZE + 2048 + 104

# (integrand, technique, the samplers it draws from with their parameters)
CASES = [
    ("ggx_lobe", "importance:ggx", [("ggx", {"alpha": 0.01})]),
    ("ggx_lobe", "importance:cosine_hemisphere", [("cosine_hemisphere", {})]),
    ("ggx_lobe", "uniform", [("uniform_hemisphere", {})]),
    ("ggx_lobe", "mis_balance:cosine_hemisphere+ggx", [("cosine_hemisphere", {}), ("ggx", {"alpha": 0.01})]),
    ("ggx_lobe", "mis_power:cosine_hemisphere+ggx", [("cosine_hemisphere", {}), ("ggx", {"alpha": 0.01})]),
    ("cosine_power", "importance:cosine_hemisphere", [("cosine_hemisphere", {})]),
    ("cosine_power", "importance:cosine_hemisphere/sobol", [("cosine_hemisphere", {})]),
    ("cosine_power", "uniform", [("uniform_hemisphere", {})]),
    ("spherical_cap", "uniform", [("uniform_sphere", {})]),
    # f is the pdf of the technique's first sampler (so the other's pdf at the first's points is
    # not f), and f is no sampler's pdf (GGX of another roughness)
    ("ggx_lobe", "mis_balance:ggx+cosine_hemisphere", [("ggx", {"alpha": 0.01}), ("cosine_hemisphere", {})]),
    ("ggx_lobe", "mis_power:ggx(0.02)+cosine_hemisphere",
     [("ggx", {"alpha": 0.02}), ("cosine_hemisphere", {})]),
    ("ggx_lobe", "importance:ggx(0.02)", [("ggx", {"alpha": 0.02})]),
    # MIS pairs whose f is one sampler's pdf run in one fused loop (polar_mis.cpp), whatever
    # direction sampler the other is: a hemisphere, a sphere (half its points where f is 0), a
    # cone, GGX of another roughness
    ("ggx_lobe", "mis_balance:uniform_hemisphere+ggx",
     [("uniform_hemisphere", {}), ("ggx", {"alpha": 0.01})]),
    ("ggx_lobe", "mis_power:uniform_sphere+ggx", [("uniform_sphere", {}), ("ggx", {"alpha": 0.01})]),
    ("ggx_lobe", "mis_balance:ggx+uniform_cone",
     [("ggx", {"alpha": 0.01}), ("uniform_cone", {"cos_max": 0.5})]),
    ("ggx_lobe", "mis_power:ggx(0.3)+ggx", [("ggx", {"alpha": 0.3}), ("ggx", {"alpha": 0.01})]),
]


def technique(f: str, name: str, samplers: list):
    """The catalogue's technique of that name, else importance sampling or MIS (the name says
    which heuristic) by the samplers."""
    if name in rest.techniques(f):
        return name
    ss = [rest.sampler(n, **p) for n, p in samplers]
    return rest.importance(ss[0]) if len(ss) == 1 else rest.mis(ss, "power" if "power" in name else "balance")


def general_contributions(f: str, name: str, samplers: list, power: float, n: int, **keys) -> np.ndarray:
    """The contributions computed as the general path does, from whole points: the samplers'
    sample() and pdf() and the integrand's eval() on the uniforms the estimate consumes."""
    kind = "sobol" if name.endswith("/sobol") else "random"
    u = rest.points(n, 2 * len(samplers), kind, **keys)
    fi = rest.integrand(f)
    ss = [rest.sampler(name, **params) for name, params in samplers]
    if len(ss) == 1:
        x, p = ss[0].sample(u)
        return fi.eval(x) / p
    y = np.zeros(n)
    for a, sa in enumerate(ss):
        x, p = sa.sample(u[:, 2 * a:2 * a + 2])
        w = np.zeros(n)
        for b, sb in enumerate(ss):
            w += (p if b == a else sb.pdf(x)) ** power
        fx = fi.eval(x)
        # the balance heuristic's f / w, else p^(beta - 1) f / w, in the core's order
        y += np.where(fx == 0, 0.0, fx / w if power == 1 else p ** (power - 1) * fx / w)
    return y


# the path each case's blocks take (Estimate.kernel)
PATHS = {
    "importance:ggx": "polar: u0s drawn in the sampler",
    "importance:cosine_hemisphere": "polar: u0s drawn in the sampler",
    "uniform": "polar: u0s drawn in the sampler",
    "importance:cosine_hemisphere/sobol": "polar",                 # no generator rows to draw
    "mis_balance:cosine_hemisphere+ggx": "polar: MIS pair in one loop",
    "mis_power:cosine_hemisphere+ggx": "polar: MIS pair in one loop",
    "mis_balance:ggx+cosine_hemisphere": "polar: MIS pair in one loop",
    "mis_power:ggx(0.02)+cosine_hemisphere": "polar",              # f is neither sampler's pdf
    "importance:ggx(0.02)": "polar: u0s drawn in the sampler",
    "mis_balance:uniform_hemisphere+ggx": "polar: MIS pair in one loop",
    "mis_power:uniform_sphere+ggx": "polar: MIS pair in one loop",
    "mis_balance:ggx+uniform_cone": "polar: MIS pair in one loop",
    "mis_power:ggx(0.3)+ggx": "polar: MIS pair in one loop",
}


@pytest.mark.parametrize("n", [N, N_ROWS], ids=["tail", "rows"])
@pytest.mark.parametrize("f, name, samplers", CASES, ids=[f"{c[0]}-{c[1]}" for c in CASES])
def test_polar_path_gives_the_general_paths_bits(f, name, samplers, n):
    keys = dict(seed=7, case_id=3, replica=1)
    power = 2.0 if name.startswith("mis_power") else 1.0
    t = technique(f, name, samplers)
    y = rest.contributions(f, t, n, threads=2, **keys)
    np.testing.assert_array_equal(y, general_contributions(f, name, samplers, power, n, **keys))
    e = rest.integrate(f, t, n, threads=2, **keys)
    assert e.n == n and e.ok
    assert e.mean == rest.accumulate(y).mean
    assert (e.kernel, e.redone_blocks) == (PATHS[name], 0)


def test_a_block_with_bad_pdfs_is_reported_with_whole_points():
    """GGX at alpha = 1e-170 has pdf NaN everywhere (alpha^2 underflows): every sample is
    reported as the general path reports it, its example naming the direction, not z alone."""
    s = rest.sampler("ggx", alpha=1e-170)
    u = rest.points(3000, 2, seed=2)
    x, _ = s.sample(u)
    e = rest.integrate("ggx_lobe", rest.importance(s), 3000, seed=2)
    assert (e.kernel, e.redone_blocks) == ("polar: u0s drawn in the sampler", 2)
    assert e.counts["bad_pdf"] == 3000 and e.n == 0
    for example in e.examples:
        assert example["issue"] == "bad_pdf" and len(example["point"]) == 3
        np.testing.assert_array_equal(example["point"], x[example["index"]])


def test_an_mis_block_with_bad_pdfs_is_reported_with_whole_points():
    """MIS of the cosine lobe and GGX at alpha = 1e-170: the cosine lobe's block is clean, its
    weights NaN (GGX's pdf), and GGX's own points have pdf NaN: the block goes back to the
    general path, which drops every sample for its GGX point and names that direction."""
    t = rest.mis([rest.sampler("cosine_hemisphere"), rest.sampler("ggx", alpha=1e-170)])
    u = rest.points(3000, 4, seed=4)
    x, _ = rest.sampler("ggx", alpha=1e-170).sample(u[:, 2:])
    e = rest.integrate("ggx_lobe", t, 3000, seed=4)
    assert e.counts["bad_pdf"] == 3000 and e.n == 0
    for example in e.examples:
        np.testing.assert_array_equal(example["point"], x[example["index"]])
    assert np.isnan(rest.contributions("ggx_lobe", t, 3000, seed=4)).all()


def test_a_fused_mis_block_with_bad_pdfs_goes_back_to_the_general_path():
    """GGX at alpha = 1e200 draws z = 0 with pdf 0 (alpha^2 overflows) and x, y NaN: paired
    with GGX at the lobe's alpha, whose pdf is f, every block of the fused loop fails its
    screening and goes back to the general path, which drops every sample for its point outside
    the domain, names that direction, and gives the contributions NaN, as for any technique."""
    bad = rest.sampler("ggx", alpha=1e200)
    t = rest.mis([rest.sampler("ggx", alpha=0.01), bad], "power")
    u = rest.points(N_ROWS, 4, seed=4)
    x, _ = bad.sample(u[:, 2:])
    e = rest.integrate("ggx_lobe", t, N_ROWS, seed=4, threads=2)
    blocks = 32 + 2     # of the whole chunk, of the partial one (2048 + 104 samples)
    assert (e.kernel, e.redone_blocks) == ("polar: MIS pair in one loop", blocks)
    assert e.counts["outside_domain"] == N_ROWS and e.n == 0
    assert e.examples
    for example in e.examples:
        np.testing.assert_array_equal(example["point"], x[example["index"]])
    assert np.isnan(rest.contributions("ggx_lobe", t, N_ROWS, seed=4)).all()


def test_which_integrands_and_samplers_take_the_polar_path():
    """The catalogue's integrands that read cos(theta) alone and the direction samplers whose
    pdf does; every other integrand and sampler keeps the general path."""
    polar = {f.name for f in rest.catalogue() if f.polar}
    assert polar == {"cosine_power", "ggx_lobe", "spherical_cap"}
    tables = ("piecewise_constant_1d", "piecewise_constant_2d")    # need a table: not directions
    names = {s["name"] for s in rest.samplers()} - set(tables)
    polar_samplers = {name for name in names if rest.sampler(name).polar}
    directions = {"uniform_hemisphere", "uniform_sphere", "cosine_hemisphere", "uniform_cone", "ggx"}
    assert polar_samplers == directions
    assert not any(rest.sampler(t, table=np.ones((2, 2)) if t.endswith("2d") else np.ones(2)).polar
                   for t in tables)
    for f, t in [("gaussian2d", "mis_balance:uniform_box+piecewise_constant_2d"), ("gaussian", "uniform"),
                 ("gaussian", "rejection")]:
        assert rest.integrate(f, t, 5000).kernel == "general"
    # too few samples for a whole generator row (8 an MIS pair's, 16 importance sampling's): no
    # block takes the loops that draw the rows inside, and the path named is the polar passes
    for t, n in [("mis_balance:cosine_hemisphere+ggx", 7), ("importance:ggx", 15)]:
        e = rest.integrate("ggx_lobe", t, n)
        assert (e.kernel, e.redone_blocks) == ("polar", 0)
    for t, n, path in [("mis_balance:cosine_hemisphere+ggx", 8, "polar: MIS pair in one loop"),
                       ("importance:ggx", 16, "polar: u0s drawn in the sampler")]:
        assert rest.integrate("ggx_lobe", t, n).kernel == path


def test_which_pdfs_are_the_integrand():
    """GGX's pdf is the GGX lobe of the same roughness (polar_function names it, every bit of
    alpha included); no other sampler's pdf is a catalogue integrand, and a sampler's pdf of
    another roughness is not the lobe."""
    lobe = rest.integrand("ggx_lobe")
    assert lobe.polar_function == rest.sampler("ggx", alpha=0.01).polar_function != ""
    assert rest.sampler("ggx", alpha=np.nextafter(0.01, 1)).polar_function != lobe.polar_function
    names = {s["name"] for s in rest.samplers()} - {"piecewise_constant_1d", "piecewise_constant_2d"}
    assert {n for n in names if rest.sampler(n).polar_function} == {"ggx"}
    assert {f.name for f in rest.catalogue() if f.polar_function} == {"ggx_lobe"}
    z = np.concatenate([np.linspace(-1, 1, 20001), [0.0, -0.0, 1.0, 1 + 1e-15, 5e-324]])
    w = np.column_stack([np.sqrt(np.maximum(0, 1 - z * z)), np.zeros_like(z), z])
    np.testing.assert_array_equal(lobe.eval(w), rest.sampler("ggx", alpha=0.01).pdf(w))


@pytest.mark.parametrize("name", ["importance:cosine_hemisphere", "mis_balance:cosine_hemisphere+ggx"])
def test_a_clamped_polar_estimate_accumulates_the_clamped_contributions(name):
    """The polar path hands its scan of each block to the accumulator; a clamp changes the
    contributions after that scan, and the estimate must be that of the clamped values (the
    same bits as accumulating them), not of the scanned ones."""
    t = rest.clamped(rest.technique("ggx_lobe", name), 1.0)
    y = rest.contributions("ggx_lobe", t, N, seed=9)
    assert y.max() == 1.0 and (y < 1.0).any()
    e = rest.integrate("ggx_lobe", t, N, seed=9, threads=2)
    reference = rest.accumulate(y)
    assert (e.mean, e.variance) == (reference.mean, reference.variance)
