"""The pytest plugin and the assertion helpers, run as a user runs them."""
from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest

import reference_estimators as rest
from harness import testing

GAUSS = rest.integrand("gaussian").reference


def pytest_run(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *args],
                          capture_output=True, text=True, cwd=cwd, timeout=600)


def test_ci_suite_collects_every_case_and_passes(root, tmp_path):
    r = pytest_run("suites/ci.toml", "--harness-db", str(tmp_path / "ci.sqlite"), cwd=root)
    assert r.returncode == 0, r.stdout[-3000:]
    from harness import load_suite

    suite = load_suite(root / "suites" / "ci.toml")
    n = sum(len(rest.techniques(f)) for f in rest.catalogue())
    assert len(suite.cases) == n and len(suite.samplers) == 10
    assert f"{n + len(suite.samplers)} passed" in r.stdout


def test_a_failing_case_explains_itself(tmp_path):
    """clamped:uniform(0.9) has a bias of -0.021; with 64 samples in 8 batches it cannot be
    found, so its case fails as 'bias missed' and says what it measured and expected."""
    suite = tmp_path / "weak.toml"
    suite.write_text('[suite]\nname = "weak"\nsamples = 64\nbatches = 8\nreplicas = 4\nmeasurements = ["bias"]\n\n'
                     '[[case]]\nintegrand = "gaussian"\ntechniques = ["uniform", "clamped:uniform(0.9)"]\n')
    r = pytest_run(str(suite), "--harness-db", str(tmp_path / "weak.sqlite"))
    assert r.returncode == 1, r.stdout
    assert "1 failed, 1 passed" in r.stdout
    out = r.stdout
    for fragment in ("gaussian/clamped:uniform(0.9)", "bias: estimate", "(n = 64)", "exact 0.7468241328",
                     "family-wise alpha = 0.01", "% CI [", "verdict: bias missed", "expected: biased (deliberately)"):
        assert fragment in out, fragment


def test_a_malformed_suite_is_a_collection_error_naming_file_line_key(tmp_path):
    suite = tmp_path / "bad.toml"
    suite.write_text('[suite]\nsamples = 1000\n\n[[case]]\nintegrand = "gaussian"\ntechniques = ["nope"]\n')
    r = pytest_run(str(suite))
    assert r.returncode != 0 and f"{suite}:6: techniques: unknown technique 'nope'" in r.stdout


def test_assert_unbiased_and_assert_biased():
    f = lambda u: np.exp(-u[:, 0] ** 2)  # noqa: E731
    assert testing.assert_unbiased(f, 1, GAUSS, sample_count=100_000).verdict == "consistent"
    with pytest.raises(AssertionError, match=r"expected an unbiased estimator of 0.7468.*biased: estimate"):
        testing.assert_unbiased(lambda u: 1.01 * f(u), 1, GAUSS, sample_count=100_000)
    assert testing.assert_biased(lambda u: 1.01 * f(u), 1, GAUSS, sample_count=100_000).rejected
    with pytest.raises(AssertionError, match="expected a detectable bias"):
        testing.assert_biased(f, 1, GAUSS, sample_count=100_000)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        # a 50 % bias on Pareto-tailed contributions: p < alpha, but no level can be claimed
        testing.assert_unbiased(lambda u: u[:, 0] ** (-2 / 3) / 3 * 1.5, 1, 1.0, sample_count=100_000)
    assert any(issubclass(x.category, testing.HarnessWarning) for x in w)


def test_assert_converges():
    c = testing.assert_converges("gaussian", "uniform/stratified", [256, 1024, 4096, 16384], rate=-1.5, replicas=16)
    assert c.slope < -1.3
    with pytest.raises(AssertionError, match=r"expected RMSE ~ n\^-0.50 or faster, got .*clamped"):
        testing.assert_converges("gaussian", "clamped:uniform(0.9)", [256, 1024, 4096, 16384], replicas=16)


def test_assert_rare():
    assert testing.assert_rare(3, 10_000, 1e-3) > 0.01
    with pytest.raises(AssertionError, match=r"40 events in 10000 trials where at most a rate of 0.001"):
        testing.assert_rare(40, 10_000, 1e-3)
    with pytest.raises(ValueError, match="need 0 <= p <= 1"):
        testing.assert_rare(3, 10, 2.0)
