"""examples/own-renderer, a user-style repository, run as its README says: its suite passes
with the wrong twins xfailed, and its own pytest run (suite items and unit tests) passes."""
import shutil
import subprocess
import sys
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "own-renderer"
BIN = Path(sys.executable).parent


def test_own_renderer_example_runs_as_its_readme_says(tmp_path):
    repo = tmp_path / "own-renderer"
    shutil.copytree(EXAMPLE, repo, ignore=shutil.ignore_patterns("__pycache__", ".pytest_cache"))
    r = subprocess.run([str(BIN / "harness"), "run", "suite.toml", "--db", "r.sqlite"], cwd=repo,
                       capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stdout + r.stderr
    out = r.stdout
    assert "3 cases, 3 sampler checks, 3 render configurations" in out
    assert "summary: 6 passed, 0 failed, 3 xfailed" in out
    for twin in ("XFAIL skewed#2", "XFAIL sampler:mysampler:skewed@hemisphere#5",
                 "--off-by-one#1: divides the sum of spp samples by spp + 1"):
        assert twin in out
    assert "command:myrenderer.py" in out and "myrenderer:?" not in out
    rep = subprocess.run([str(BIN / "harness"), "report", "--db", "r.sqlite", "-o", "r.html"], cwd=repo,
                         capture_output=True, text=True, timeout=300)
    page = (repo / "r.html").read_text()
    assert rep.returncode == 0 and "3 known findings (xfail" in page and "a CI run fails on" not in page
    assert page.count(">xfailed<") == 3 and "xfail: divides the sum of spp samples by spp + 1" in page
    p = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--harness-db",
                        "r.sqlite"], cwd=repo, capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "12 passed, 3 xfailed" in p.stdout
    assert "PytestAssertRewriteWarning" not in p.stdout + p.stderr
    c = subprocess.run([str(BIN / "harness"), "check-sampler", "mysampler:Absorbing", "--samples", "200000"],
                       cwd=repo, capture_output=True, text=True, timeout=300)
    assert c.returncode == 0 and "PASSED" in c.stdout, c.stdout + c.stderr
