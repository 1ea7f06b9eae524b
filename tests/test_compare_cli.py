"""`harness compare A B`: folders of replica images, or two render cases of a stored run, compared
by the two-sample test; the page it writes opened in real headless Chromium."""
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
from playwright.sync_api import sync_playwright

from harness.suite.store import write_exr

HARNESS = str(Path(sys.executable).with_name("harness"))


def _replicas(folder: Path, seed: int, gain: float = 1.0, count: int = 6) -> None:
    folder.mkdir()
    rng = np.random.default_rng(seed)
    for k in range(count):
        write_exr(folder / f"r{k}.exr", gain * (0.5 + 0.05 * rng.standard_normal((16, 24, 3))))


def run(*args, cwd):
    return subprocess.run([HARNESS, "compare", *args], capture_output=True, text=True, cwd=cwd, timeout=300)


def test_compare_folders_and_the_page(tmp_path):
    _replicas(tmp_path / "a", 1)
    _replicas(tmp_path / "b", 2)
    _replicas(tmp_path / "c", 3, gain=1.02)
    same = run("a", "b", "-o", "ab.html", cwd=tmp_path)
    assert same.returncode == 0 and "consistent: p = " in same.stdout and "6 replicas" in same.stdout, same
    differ = run("a", "c", "-o", "ac.html", cwd=tmp_path)
    assert differ.returncode == 1 and "differ: p = " in differ.stdout, differ
    errors = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path="/usr/bin/chromium")
        try:
            page = browser.new_page()
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto((tmp_path / "ac.html").as_uri())
            shown = page.eval_on_selector_all("img", "els => els.map(e => e.complete && e.naturalWidth > 0)")
            text = page.inner_text("body")
        finally:
            browser.close()
    assert errors == [] and len(shown) == 8 and all(shown)   # means, relMSE, FLIP (2 each), |t| map, p-values
    # 6 replicas a set: 8 x 8 tiles and the image only (the fine scales need 8)
    assert "FLIP (HDR) of A against mean B" in text and "p-values of the 8x8 tiles test" in text


def test_compare_errors_are_one_line(tmp_path):
    _replicas(tmp_path / "a", 1)
    _replicas(tmp_path / "small", 2, count=3)
    (tmp_path / "empty").mkdir()
    bad = tmp_path / "bad"
    _replicas(bad, 4)
    (bad / "r9.exr").write_bytes(b"not an image")
    for args, message in ((("a", "nothere"), "nothere: not a folder of replica images"),
                          (("a", "empty"), "empty: no .exr, .pfm, .hdr images in it"),
                          (("a", "small"), "at least 4 replicas of each, got 6 and 3"),
                          (("a", "bad"), "cannot read image"),
                          (("a", "./a/"), "'a' and './a/' name one replica set"),   # had been "consistent"
                          (("a", "b", "--db", "none.sqlite"), "no results database at none.sqlite"),
                          (("a", "a", "-o", "empty"), "-o empty: a folder; give a file name"),
                          (("a", "a", "-o", "nofolder/x.html"), "-o nofolder/x.html: no folder nofolder")):
        r = run(*args, cwd=tmp_path)
        assert r.returncode == 2 and message in r.stderr and "Traceback" not in r.stderr, (args, r.stderr)


def test_compare_two_render_cases_of_a_stored_run(tmp_path):
    (tmp_path / "flat.py").write_text(textwrap.dedent('''
        import numpy as np
        def render(spp, seed, gain=1.0):
            rng = np.random.default_rng(seed)
            return gain * (0.5 + 0.05 * rng.standard_normal((8, 8, 3)) / np.sqrt(spp))
    '''))
    (tmp_path / "s.toml").write_text(textwrap.dedent('''
        [[render]]
        adapter = "python"
        function = "flat:render"
        scene = "flat"
        reference_spp = 64
        spp = 4
        replicas = 6
        measurements = ["bias"]

        [[render]]
        adapter = "python"
        function = "flat:render"
        params = { gain = 1.05 }
        scene = "flat"
        reference_spp = 64
        spp = 4
        replicas = 6
        measurements = ["bias"]
    '''))
    done = subprocess.run([HARNESS, "run", "s.toml", "--db", "r.sqlite"], capture_output=True, text=True,
                          cwd=tmp_path, timeout=300)
    assert "render configurations" in done.stdout, done.stdout + done.stderr
    r = run("flat:render", "flat:render(gain=1.05)", "--db", "r.sqlite", "-o", "db.html", cwd=tmp_path)
    assert r.returncode == 1 and "differ" in r.stdout, r
    assert "A: python:flat/flat:render (6 replicas" in r.stdout
    ambiguous = run("flat", "flat:render", "--db", "r.sqlite", cwd=tmp_path)
    assert ambiguous.returncode == 2 and "'flat': 2 render cases match in r.sqlite" in ambiguous.stderr
    itself = run("flat:render", "flat:render", "--db", "r.sqlite", cwd=tmp_path)
    assert itself.returncode == 2 and "name one replica set (r.sqlite case " in itself.stderr, itself.stderr
