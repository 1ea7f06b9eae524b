"""The pytest plugin, run as a user runs it: suite files collected as test items in a
subprocess.  (The assertion helpers of harness.testing are tested in test_testing.py.)"""
from __future__ import annotations

import subprocess
import sys

import reference_estimators as rest


def pytest_run(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *args],
                          capture_output=True, text=True, cwd=cwd, timeout=600, check=False)


def test_ci_suite_collects_every_case_and_passes(root, tmp_path):
    r = pytest_run("suites/ci.toml", "--harness-db", str(tmp_path / "ci.sqlite"), cwd=root)
    assert r.returncode == 0, r.stdout[-3000:]
    from harness import load_suite

    suite = load_suite(root / "suites" / "ci.toml")
    n = sum(len(rest.techniques(f)) for f in rest.catalogue())
    assert len(suite.cases) == n and len(suite.samplers) == 10
    assert f"{n + len(suite.samplers)} passed" in r.stdout


def test_a_failing_case_explains_itself(tmp_path):
    """clamped:uniform(0.9) has a bias of -0.021; with 16 samples (standard error about 0.02)
    it cannot be found, so its case fails as 'bias missed' and says what it measured and
    expected."""
    suite = tmp_path / "weak.toml"
    suite.write_text('[suite]\nname = "weak"\nsamples = 16\nbatches = 8\nreplicas = 4\n'
                     'measurements = ["bias"]\n\n'
                     '[[case]]\nintegrand = "gaussian"\ntechniques = ["uniform", "clamped:uniform(0.9)"]\n')
    r = pytest_run(str(suite), "--harness-db", str(tmp_path / "weak.sqlite"))
    assert r.returncode == 1, r.stdout
    assert "1 failed, 1 passed" in r.stdout
    out = r.stdout
    for fragment in ("gaussian/clamped:uniform(0.9)", "bias: estimate", "(n = 16)", "exact 0.7468241328",
                     "family-wise alpha = 0.01", "% CI [", "verdict: bias missed",
                     "expected: biased (deliberately)"):
        assert fragment in out, fragment


def test_a_malformed_suite_is_a_collection_error_naming_file_line_key(tmp_path):
    suite = tmp_path / "bad.toml"
    suite.write_text('[suite]\nsamples = 1000\n\n[[case]]\nintegrand = "gaussian"\ntechniques = ["nope"]\n')
    r = pytest_run(str(suite))
    assert r.returncode != 0 and f"{suite}:6: techniques: unknown technique 'nope'" in r.stdout


def test_only_suite_files_matching_harness_suites_are_collected(tmp_path):
    """A user repository: its suites under checks/ (ini option harness_suites), a broken scratch
    suite elsewhere that must not break collection."""
    (tmp_path / "pytest.ini").write_text("[pytest]\nharness_suites = checks/*.toml\n")
    (tmp_path / "checks").mkdir()
    (tmp_path / "checks" / "mine.toml").write_text(
        '[suite]\nname = "mine"\nsamples = 4096\nbatches = 8\nmeasurements = ["bias"]\n\n'
        '[[case]]\nintegrand = "gaussian"\ntechniques = ["uniform", "importance:linear"]\n')
    (tmp_path / "scratch").mkdir()
    (tmp_path / "scratch" / "broken.toml").write_text(
        '[suite]\nsamples = -1\n\n[[case]]\nintegrand = "nope"\n')
    r = pytest_run("--harness-db", str(tmp_path / "mine.sqlite"), cwd=tmp_path)
    assert r.returncode == 0, r.stdout[-3000:]
    assert "2 passed" in r.stdout and "broken" not in r.stdout


def test_sampler_only_suites_are_collected_and_a_stopped_run_fails_once_in_one_line(tmp_path):
    """A suite of [[sampler]] tables alone had not been collected (CI green without its checks);
    a .toml that is not UTF-8 had stopped the session; a team's estimator failing in the run
    had failed every case with a long traceback, the suite rerun for each."""
    (tmp_path / "pytest.ini").write_text("[pytest]\nharness_suites = checks/*.toml\n")
    checks = tmp_path / "checks"
    checks.mkdir()
    (checks / "samplers.toml").write_text('[[sampler]]\nname = "linear"\nsamples = 20000\n')
    (checks / "latin1.toml").write_bytes(b'a = "\xff"\n')
    (checks / "myest.py").write_text("calls = []\n\ndef good(u):\n    return u[:, 0]\n\n"
                                     "def late(u):\n    if len(u) > 8:\n        calls.append(1)\n"
                                     "        raise RuntimeError(f'kaput {len(calls)}')\n"
                                     "    return u[:, 0]\n")
    (checks / "late.toml").write_text('[suite]\nsamples = 4096\nbatches = 8\nmeasurements = ["bias"]\n\n'
                                      '[[case]]\nestimator = "myest:good"\ndim = 1\nreference = 0.5\n\n'
                                      '[[case]]\nestimator = "myest:late"\ndim = 1\nreference = 0.5\n')
    r = pytest_run("--harness-db", str(tmp_path / "r.sqlite"), cwd=tmp_path)
    out = r.stdout
    assert "1 passed" in out and "2 failed" in out, out[-3000:]          # the sampler check ran
    # pytest's short summary repeats each message, in full where the CI variable is set: count the
    # failure sections above it
    failures = out.split("short test summary info")[0]
    stopped = "the suite's run stopped: myest:late raised RuntimeError: kaput 1 (called on shape"
    assert failures.count(stopped) == 2
    assert "kaput 2" not in out and "Traceback" not in out and len(out.splitlines()) < 40, out
