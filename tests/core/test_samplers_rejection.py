"""The rejection method (rejection_sampler, hit or miss) and estimate_from_samples."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest
from scipy import special, stats

import reference_estimators as rest

from tests.core.sampler_cases import THREAD_N

# --- the rejection method -------------------------------------------------------------------
GAUSS_REF = 0.5 * math.sqrt(math.pi) * math.erf(1.0)


def proposal() -> rest.Sampler:
    return rest.sampler("linear", a=1, b=0.37)


def valid_bound() -> float:
    """1.01 x max of f/p over a fine grid: a valid c for exp(-x^2) under linear(1, 0.37)."""
    x = np.linspace(0, 1, 200_001)
    return 1.01 * float(np.max(np.exp(-x * x) / proposal().pdf(x)))


def test_gaussian_reference_matches_catalogue():
    assert rest.integrand("gaussian").reference == pytest.approx(GAUSS_REF, rel=1e-15)


def test_rejection_sampler_with_valid_bound():
    """Valid c: no bound violations; acceptance rate = reference / c within 5 sigma
    (binomial over the candidates); KS against erf(x) / erf(1) at alpha = 1e-3, seed 1."""
    c = valid_bound()
    s = rest.rejection_sampler("gaussian", proposal(), c)
    assert s.method == "rejection" and not s.invertible
    n = 200_000
    x, p, diag = s.draw(n, seed=1)
    assert diag["counts"]["bound_violation"] == 0, f"violations with valid c = {c}: {diag['examples']}"
    assert not any(e["issue"] == "bound_violation" for e in diag["examples"])
    assert diag["drawn"] == n and x.shape == (n,)
    k = diag["candidates"]
    assert k > n, f"candidates {k} <= drawn {n}"
    rate, expected = n / k, GAUSS_REF / c
    sigma = math.sqrt(expected * (1 - expected) / k)
    assert abs(rate - expected) < 5 * sigma, f"acceptance {rate:.6f}, expected {expected:.6f} +- {sigma:.2g}"
    assert np.all((x >= 0) & (x <= 1))
    assert np.allclose(p, np.exp(-x * x) / GAUSS_REF, rtol=1e-12), "draw() pdf is not target / reference"
    assert np.allclose(s.pdf(x), p, rtol=1e-12)
    res = stats.kstest(x, lambda t: special.erf(np.clip(t, 0, 1)) / special.erf(1.0))
    assert res.pvalue > 1e-3, f"KS D = {res.statistic:.5g}, p = {res.pvalue:.3g}"


def test_rejection_sampler_reports_bound_violations_when_c_is_too_small():
    c = 0.5 * valid_bound()
    s = rest.rejection_sampler("gaussian", proposal(), c)
    x, p, diag = s.draw(50_000, seed=1)
    assert diag["counts"]["bound_violation"] > 0, f"no violation reported with c = {c}: {diag['counts']}"
    ex = [e for e in diag["examples"] if e["issue"] == "bound_violation"]
    assert ex, f"no bound_violation examples: {diag['examples']}"
    for e in ex:
        (pt,) = e["point"]
        assert 0 <= pt <= 1, e
        assert e["value"] > 1, e
        expect = math.exp(-pt * pt) / (c * float(proposal().pdf(np.array([pt]))[0]))
        assert e["value"] == pytest.approx(expect, rel=1e-12), e


def test_rejection_sampler_draw_identical_for_any_thread_count():
    s = rest.rejection_sampler("gaussian", proposal(), 0.5 * valid_bound())
    x1, p1, d1 = s.draw(THREAD_N, seed=3, threads=1)
    for t in (2, 3):
        xt, pt, dt = s.draw(THREAD_N, seed=3, threads=t)
        assert np.array_equal(x1, xt) and np.array_equal(p1, pt), f"threads={t} differs"
        assert dt["counts"] == d1["counts"] and dt["candidates"] == d1["candidates"]


def test_rejection_sampler_sample_raises_and_names_draw():
    s = rest.rejection_sampler("gaussian", proposal(), valid_bound())
    with pytest.raises(ValueError, match=r"draw"):
        s.sample(np.full((4, s.udim), 0.5))


def test_rejection_sampler_invert_raises():
    s = rest.rejection_sampler("gaussian", proposal(), valid_bound())
    with pytest.raises(ValueError, match="no inverse"):
        s.invert(np.array([0.5]))


@pytest.mark.parametrize("c", [0.0, -1.0, math.inf, math.nan])
def test_rejection_sampler_rejects_bad_bound(c):
    with pytest.raises(ValueError, match=r"'c' must be finite and > 0"):
        rest.rejection_sampler("gaussian", proposal(), c)


def test_rejection_sampler_rejects_dimension_mismatch():
    with pytest.raises(ValueError, match="proposal"):
        rest.rejection_sampler("gaussian", rest.sampler("uniform_hemisphere"), 1.0)


def test_hit_or_miss_reports_bound_violations_when_c_is_too_small():
    est = rest.integrate("gaussian", rest.rejection(proposal(), 0.5 * valid_bound()), 100_000, seed=0)
    assert est.counts["bound_violation"] > 0, est.counts
    assert not est.ok
    assert "bound_violation" in est.issues
    ex = [e for e in est.examples if e["issue"] == "bound_violation"]
    assert ex and all(0 <= e["point"][0] <= 1 and e["value"] > 1 for e in ex), ex


def test_hit_or_miss_with_valid_bound_is_clean_and_unbiased():
    est = rest.integrate("gaussian", rest.rejection(proposal(), valid_bound()), 200_000, seed=0)
    assert est.counts["bound_violation"] == 0, est.examples
    assert est.ok, est.issues
    assert abs(est.z_score()) < 5, f"mean {est.mean} +- {est.stderr}, reference {GAUSS_REF}"


# --- estimate_from_samples -----------------------------------------------------------------
def test_estimate_from_samples_clean_call_is_ok_and_unbiased():
    s = proposal()
    x, p, _ = s.draw(200_000, seed=11)
    est = rest.estimate_from_samples("gaussian", x, p)
    assert est.ok, est.issues
    assert est.n == est.drawn == x.size
    assert abs(est.z_score()) < 5, f"mean {est.mean} +- {est.stderr}, reference {GAUSS_REF}"


def test_estimate_from_samples_excludes_and_reports_bad_samples():
    s = proposal()
    x, p, _ = s.draw(10_000, seed=12)
    x, p = x.copy(), p.copy()
    outside = {17: -0.25, 1234: 1.5, 5000: math.inf}
    zero = [3, 4000]
    bad = {99: -1.0, 7777: math.nan, 8888: math.inf}
    for i, v in outside.items():
        x[i] = v
    p[zero] = 0.0
    for i, v in bad.items():
        p[i] = v
    est = rest.estimate_from_samples("gaussian", x, p)
    assert est.counts["outside_domain"] == len(outside), est.counts
    assert est.counts["zero_pdf"] == len(zero), est.counts
    assert est.counts["bad_pdf"] == len(bad), est.counts
    n_bad = len(outside) + len(zero) + len(bad)
    assert est.drawn == x.size and est.n == x.size - n_bad, (est.n, est.drawn)
    assert not est.ok
    by_issue: dict[str, dict[int, tuple]] = {}
    for e in est.examples:
        by_issue.setdefault(e["issue"], {})[e["index"]] = e["point"]
    assert set(by_issue["outside_domain"]) == set(outside), est.examples
    for i, v in outside.items():
        assert by_issue["outside_domain"][i] == (v,), (i, by_issue["outside_domain"][i])
    assert set(by_issue["zero_pdf"]) == set(zero), est.examples
    assert set(by_issue["bad_pdf"]) == set(bad), est.examples
    for i in zero + list(bad):
        assert by_issue["zero_pdf" if i in zero else "bad_pdf"][i] == (x[i],)
    # The remaining samples give the same estimate as if the bad ones were never there.
    keep = np.ones(x.size, dtype=bool)
    keep[list(outside) + zero + list(bad)] = False
    clean = rest.estimate_from_samples("gaussian", x[keep], p[keep])
    assert clean.ok and clean.n == est.n
    assert est.mean == pytest.approx(clean.mean, rel=1e-13)


def test_estimate_from_samples_rejects_mismatched_pdf():
    with pytest.raises(ValueError, match=r"'pdf' must have shape \(3,\)"):
        rest.estimate_from_samples("gaussian", np.array([0.1, 0.2, 0.3]), np.array([1.0, 1.0]))
    with pytest.raises(ValueError, match=re.escape("'points' must have shape (N, 1) or (N,), got (3, 2)")):
        rest.estimate_from_samples("gaussian", np.zeros((3, 2)), np.ones(3))
