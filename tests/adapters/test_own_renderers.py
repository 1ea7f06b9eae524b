"""Renderers of a team's own through the command and python adapters, and third-party
adapters registered under the entry-point group harness.adapters: real subprocesses, real EXR
files, every failure a clear error naming the command, and nothing stored for a failed render."""
import json
import sys
import textwrap
from importlib.metadata import EntryPoint
from pathlib import Path

import numpy as np
import pytest

from harness.adapters import base
from harness.adapters.base import Render, RenderError, renderer
from harness.suite.parse import SuiteError, load_suite
from harness.suite.run import run_suite
from harness.suite.store import Store, write_exr

SCRIPT = '''
import argparse, json, sys, time
import numpy as np
import OpenImageIO as oiio


def write_exr(path, image):
    out = oiio.ImageOutput.create(path)
    out.open(path, oiio.ImageSpec(image.shape[1], image.shape[0], image.shape[2], "float"))
    out.write_image(np.ascontiguousarray(image, dtype=np.float32))
    out.close()


p = argparse.ArgumentParser()
p.add_argument("--spp", type=int); p.add_argument("--seed", type=int); p.add_argument("--out")
p.add_argument("--mode", default="ok")
a = p.parse_args()
if a.mode in ("bytes", "failbytes"):     # a progress bar's bytes that are not UTF-8
    sys.stdout.buffer.write(b"\\xff\\xfe progress \\x80\\n"); sys.stdout.flush()
    sys.stderr.buffer.write(b"warning: \\xe9clairage \\xff\\n"); sys.stderr.flush()
if a.mode == "failbytes":
    sys.exit(4)
if a.mode == "fail":
    print("scene file not found: cornell.xml", file=sys.stderr); sys.exit(3)
if a.mode == "sleep":
    time.sleep(30)
if a.mode == "noimage":
    sys.exit(0)
if a.mode == "garbage":
    open(a.out, "w").write("not an image"); sys.exit(0)
rng = np.random.default_rng(a.seed)
img = rng.random((4, 6, 3, a.spp)).mean(axis=3) * 2     # mean 1 per pixel
write_exr(a.out, img)
if a.mode == "sidecar":
    json.dump({{"seconds": 0.125}}, open(a.out + ".json", "w"))
print(f"rendered in {{0.25 * a.spp}} s")
'''


@pytest.fixture
def repo(tmp_path):
    (tmp_path / "render.py").write_text(SCRIPT.format())
    write_exr(tmp_path / "ones.exr", np.ones((4, 6, 3)))
    return tmp_path


def command(mode="ok", **keys):
    return {"command": "{python} render.py --spp {spp} --seed {seed} --out {out} --mode " + mode, **keys}


def test_a_command_renders_with_its_own_or_its_wall_time(repo):
    r = renderer("command", command(time="stdout:rendered in ([0-9.]+) s", exact="ones.exr"), base=repo)
    out = r.render(8, 3)
    assert out.image.shape == (4, 6, 3) and out.seconds == 2.0 and out.spp == 8
    assert np.array_equal(r.exact(), np.ones((4, 6, 3)))
    assert r.describe() == ("render.py", command()["command"])
    side = renderer("command", command("sidecar"), base=repo).render(4, 1)
    assert side.seconds == 0.125
    wall = renderer("command", command(), base=repo)
    assert wall.render(4, 1).seconds >= 0 and wall._startup > 0
    assert "start-up time (the wall time of a 1-spp render" in wall.notes()[0]
    again = renderer("command", command(), base=repo).render(8, 3)
    assert np.array_equal(again.image, out.image)          # the seed reaches the renderer
    # output that is not UTF-8 is read with its odd bytes replaced (it had ended the run)
    odd = renderer("command", command("bytes", time="stdout:rendered in ([0-9.]+) s"), base=repo).render(8, 3)
    assert np.array_equal(odd.image, out.image) and odd.seconds == 2.0


@pytest.mark.parametrize("mode, keys, message", [
    ("fail", {}, r"exited with status 3; stderr ends:\n    scene file not found: cornell.xml"),
    ("failbytes", {}, "exited with status 4; stderr ends:\n    warning: \ufffdclairage \ufffd"),
    ("sleep", {"timeout": 1}, r"timed out after 1 s"),
    ("noimage", {}, r"wrote no image at \{out\} = .*image.exr"),
    ("garbage", {}, r"cannot read image .*image.exr"),
    ("ok", {"time": "stdout:took ([0-9.]+) s"}, r"its output has no match of time = 'stdout:took"),
])
def test_a_failed_render_is_a_clear_error_naming_the_command(repo, mode, keys, message):
    r = renderer("command", command(mode, **keys), base=repo)
    head = r"command '.*render.py --spp 2 --seed 5 .*--mode " + mode + ".*"
    with pytest.raises(RenderError, match=head + message):
        r.render(2, 5)


def test_the_fingerprint_follows_the_script_source(repo):
    before = renderer("command", command(), base=repo).fingerprint()
    (repo / "render.py").write_text((repo / "render.py").read_text() + "\n# changed\n")
    after = renderer("command", command(), base=repo).fingerprint()
    assert before["environment"]["sources"]["render.py"] != after["environment"]["sources"]["render.py"]
    assert "cwd" not in json.dumps(after) and str(repo) not in json.dumps(after)


def test_file_digests_follow_any_write(tmp_path):
    """file_digest hashes a file again after any write: a same-size edit whose modification
    time is put back (cp -p, rsync -t) too (the change time moves; what is kept while a stat
    identity stands: the next test)."""
    import hashlib
    import os

    f = tmp_path / "mesh.obj"
    f.write_bytes(b"v 0 0 0\n")
    first = base.file_digest(f)
    assert first == hashlib.sha256(b"v 0 0 0\n").hexdigest()[:24] == base.file_digest(f)
    st = f.stat()
    f.write_bytes(b"v 0 0 1\n")
    os.utime(f, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert f.stat().st_size == st.st_size and f.stat().st_mtime_ns == st.st_mtime_ns
    assert base.file_digest(f) == hashlib.sha256(b"v 0 0 1\n").hexdigest()[:24]


def test_a_file_changed_within_its_clocks_tick_is_hashed_again(tmp_path, monkeypatch):
    """On a file system whose clock ticks coarsely (FAT: 2 s; Linux's coarse timestamps: a few
    ms) two same-size writes in one tick leave the same stat: a file changed within _RACY_NS of
    its reading is hashed on every call, and a digest is kept only for an older one."""
    import hashlib
    import time
    from pathlib import Path

    real_stat = Path.stat
    tick = {"ns": 0}

    class Coarse:   # the real stat, its times those of the clock's tick
        def __init__(self, st):
            self.st_dev, self.st_ino, self.st_size = st.st_dev, st.st_ino, st.st_size
            self.st_mtime_ns = self.st_ctime_ns = tick["ns"]

    monkeypatch.setattr(Path, "stat", lambda self, **kw: Coarse(real_stat(self, **kw)))
    f = tmp_path / "mesh.obj"
    digests = []
    tick["ns"] = time.time_ns() + 60 * 10**9     # (a tick ahead of this clock: a stall keeps it recent)
    for text in (b"v 0 0 0\n", b"v 0 0 1\n"):   # two writes in one tick, just now
        f.write_bytes(text)
        digests.append(base.file_digest(f))
    assert digests == [hashlib.sha256(t).hexdigest()[:24] for t in (b"v 0 0 0\n", b"v 0 0 1\n")]
    tick["ns"] = time.time_ns() - 3600 * 10**9     # a file last changed an hour ago: kept
    f.write_bytes(b"v 0 0 2\n")
    kept = base.file_digest(f)
    f.write_bytes(b"v 0 0 3\n")                    # (its stat forged to stay the same)
    assert base.file_digest(f) == kept == hashlib.sha256(b"v 0 0 2\n").hexdigest()[:24]


def render_function(spp, seed, gain=1.0):
    rng = np.random.default_rng(seed)
    return gain * rng.random((4, 6, 3, spp)).mean(axis=3) * 2, 0.01 * spp


def test_a_python_function_renders_and_its_errors_name_the_call(repo):
    (repo / "fn.py").write_text("from test_own_renderers import render_function\n"
                                "def broken(spp, seed):\n    raise KeyError('material')\n"
                                "def flat(spp, seed):\n    return [1.0, 2.0]\n")
    sys.path.insert(0, str(Path(__file__).parent))
    r = renderer("python", {"function": "fn:render_function", "params": {"gain": 2.0}}, base=repo)
    out = r.render(4, 1)
    assert out.seconds == 0.04 and out.image.shape == (4, 6, 3) and out.image.mean() > 1.5
    with pytest.raises(RenderError, match=r"fn:broken\(spp=4, seed=1\) raised KeyError: 'material'"):
        renderer("python", {"function": "fn:broken"}, base=repo).render(4, 1)
    with pytest.raises(RenderError,
                       match=r"fn:flat\(spp=4, seed=1\) returned an image of shape \(2,\); expected an"):
        renderer("python", {"function": "fn:flat"}, base=repo).render(4, 1)


SUITE = '''
[suite]
seed = 1

[[render]]
adapter = "command"
command = "{python} render.py --spp {spp} --seed {seed} --out {out}"
exact = "ones.exr"
time = "stdout:rendered in ([0-9.]+) s"
spp = 16
replicas = 8
budgets = [1, 4, 16]

[[render]]
adapter = "command"
command = "{python} render.py --spp {spp} --seed {seed} --out {out} --mode fail"
exact = "ones.exr"
spp = 16
replicas = 4
measurements = ["bias"]
'''


def test_a_command_renderer_in_a_suite_and_a_failing_one(repo):
    (repo / "s.toml").write_text(SUITE)
    suite = load_suite(repo / "s.toml")
    assert [(rc.scene, rc.label) for rc in suite.renders] == [
        ("command:render.py", "{python} render.py --spp {spp} --seed {seed} --out {out}"),
        ("command:render.py", "{python} render.py --spp {spp} --seed {seed} --out {out} --mode fail")]
    with pytest.raises(RenderError, match="exited with status 3"):
        run_suite(suite, repo / "r.sqlite", threads=1)
    stored = Store(repo / "r.sqlite")
    try:
        kept = len(stored.payloads(suite_key(suite, 0)))   # rendered before the failing one ran
        assert not stored.payloads(suite_key(suite, 1))    # nothing stored for the failing render
    finally:
        stored.close()
    (repo / "s.toml").write_text(SUITE.split("[[render]]")[0] + "[[render]]" + SUITE.split("[[render]]")[1])
    s = run_suite(load_suite(repo / "s.toml"), repo / "r.sqlite", threads=1)
    assert s.failed == 0 and s.units_run == 8 + 3 * 8 - kept  # resumed: what was stored is kept
    assert s["render"].frame["bias"].tolist() == ["unbiased"]


def suite_key(suite, i):
    from harness.suite.plan import render_key
    from harness.suite.renders import cached_renderer

    rc = suite.renders[i]
    return render_key(suite, cached_renderer(rc.adapter, rc.spec, base=rc.base).fingerprint())


@pytest.mark.parametrize("table, message", [
    ('adapter = "command"', "s.toml:1: 'command': missing key: the command line that renders one image"),
    ('adapter = "command"\ncommand = "render {spp} {out}"',
     "s.toml:3: command: the command must contain {seed}"),
    ('adapter = "command"\ncommand = "r {spp} {seed} {out} {frames}"',
     "s.toml:3: command: placeholders are {spp}, {seed}, {out}, {width}, {height}, {python}"),
    ('adapter = "command"\ncommand = "r {spp} {seed} {out}"\nexact = "nothere.exr"',
     "s.toml:4: exact: no image file"),
    ('adapter = "command"\ncommand = "r {spp} {seed} {out}"\ntime = "took (.*)"',
     "s.toml:4: time: expected \"stdout:<regex>\""),
    ('adapter = "command"\ncommand = "r {spp} {seed} {out}"\nframes = 3',
     "s.toml:4: frames: unknown key for the command adapter"),
    ('adapter = "python"\nfunction = "nomodule:render"',
     "s.toml:3: function: 'nomodule:render': cannot import"),
    ('adapter = "myrenderer"', "s.toml:2: adapter: expected one of: mitsuba, pyrender, command, python"),
])
def test_render_table_mistakes_name_file_line_and_key(repo, table, message):
    (repo / "s.toml").write_text(f"[[render]]\n{table}\n")
    with pytest.raises(SuiteError) as e:
        load_suite(repo / "s.toml")
    assert message in str(e.value)


def test_third_party_adapters_register_through_entry_points(repo, monkeypatch):
    (repo / "thirdparty.py").write_text(textwrap.dedent('''
        import numpy as np
        from harness.adapters.base import Render

        class Flat:
            def __init__(self, spec):
                self.level = spec.get("level", 1.0)
            def render(self, spp, seed):
                return Render(np.full((2, 2, 3), self.level), spp, 0.001)
            def exact(self):
                return np.full((2, 2, 3), self.level)
            def fingerprint(self):
                return {"adapter": "flat", "level": self.level}
            def reference(self):
                return self

        def make_renderer(spec):
            if set(spec) - {"level", "scene"}:
                raise ValueError(f"'{sorted(set(spec) - {'level', 'scene'})[0]}': unknown key")
            return Flat(spec)
    '''))
    monkeypatch.syspath_prepend(str(repo))
    eps = [EntryPoint("flat", "thirdparty:make_renderer", base.ENTRY_POINTS)]
    monkeypatch.setattr(base, "entry_points", lambda group: eps if group == base.ENTRY_POINTS else [])
    assert base.adapter_names()[-1] == "flat"
    (repo / "s.toml").write_text('[[render]]\nadapter = "flat"\nscene = "wall"\nlevel = 0.5\nspp = 4\n'
                                 'replicas = 4\nmeasurements = ["bias"]\n')
    s = run_suite(load_suite(repo / "s.toml"), repo / "r.sqlite", threads=1)
    assert s.failed == 0 and s["render"].frame["bias"].tolist() == ["unbiased"]
    (repo / "bad.toml").write_text('[[render]]\nadapter = "flat"\ncolour = 2\n')
    with pytest.raises(SuiteError, match="bad.toml:3: colour: unknown key"):
        load_suite(repo / "bad.toml")


FLAKY = '''
import sys
import numpy as np

def wrong_size(spp, seed):           # the exact image is (4, 6, 3)
    return np.ones((3, 6, 3))

def varying(spp, seed):              # its size changes from call to call
    return np.ones((4 + seed % 2, 6, 3))

def exits(spp, seed):                # a command-line tool's main() called as a function
    sys.exit(0)
'''


def test_a_python_renders_wrong_size_or_exit_is_a_render_error_and_nothing_is_stored(repo):
    (repo / "flaky.py").write_text(FLAKY)
    table = ('[[render]]\nadapter = "python"\nfunction = "flaky:{}"\n{}spp = 4\nreplicas = 4\n'
             'measurements = ["bias"]\n')
    (repo / "size.toml").write_text(table.format("wrong_size", 'exact = "ones.exr"\n'))
    wrong = (r"render\(spp=4, seed=\d+\) returned an image of shape \(3, 6, 3\); "
             r"the exact image's is \(4, 6, 3\)")
    with pytest.raises(RenderError, match=wrong):
        run_suite(load_suite(repo / "size.toml"), repo / "size.sqlite", threads=1)
    stored = Store(repo / "size.sqlite")
    try:
        assert not stored.payloads(suite_key(load_suite(repo / "size.toml"), 0))
    finally:
        stored.close()
    with pytest.raises(RenderError, match=r"flaky:exits\(spp=4, seed=\d+\) called sys.exit\(0\)"):
        renderer("python", {"function": "flaky:exits"}, base=repo).render(4, 1)
    # without an exact image the sizes are compared once stored: a clear error on every run
    (repo / "vary.toml").write_text(table.format("varying", ""))
    varies = (r"the render of budget \d+, replica \d+ has shape \(\d, 6, 3\), where the case's "
              r"(first render|reference) has .* image size varies")
    for _ in range(2):
        with pytest.raises(RenderError, match=varies):
            run_suite(load_suite(repo / "vary.toml"), repo / "vary.sqlite", threads=1)


def test_a_registered_adapters_own_failures_name_it(repo, monkeypatch):
    (repo / "fragile.py").write_text(textwrap.dedent('''
        import numpy as np
        from harness.adapters.base import Render

        class Fragile:
            def __init__(self, spec):
                self.scene = spec["scene"]          # a KeyError where the table has none
            def render(self, spp, seed):
                if self.scene == "gpu":
                    raise RuntimeError("GPU lost")
                return Render(np.ones((2, 2, 3)) if self.scene == "ok" else np.ones(4), spp, 0.001)
            def exact(self):
                return np.ones((2, 2, 3))
            def fingerprint(self):
                return {"adapter": "fragile", "scene": self.scene}
            def reference(self):
                return self

        def make_renderer(spec):
            return Fragile(spec)
    '''))
    monkeypatch.syspath_prepend(str(repo))
    eps = [EntryPoint("fragile", "fragile:make_renderer", base.ENTRY_POINTS)]
    monkeypatch.setattr(base, "entry_points", lambda group: eps if group == base.ENTRY_POINTS else [])
    (repo / "nokey.toml").write_text('[[render]]\nadapter = "fragile"\nspp = 4\nmeasurements = ["bias"]\n')
    with pytest.raises(SuiteError, match=r"nokey.toml:1: adapter 'fragile': its factory "
                                         r"'fragile:make_renderer' raised KeyError: 'scene'"):
        load_suite(repo / "nokey.toml")
    for scene, message in (("gpu", r"render\(spp=4, seed=\d+\) raised RuntimeError: GPU lost"),
                           ("flat", r"render\(spp=4, seed=\d+\) returned an image of shape \(4,\)")):
        (repo / "s.toml").write_text(f'[[render]]\nadapter = "fragile"\nscene = "{scene}"\nspp = 4\n'
                                     'replicas = 4\nmeasurements = ["bias"]\n')
        with pytest.raises(RenderError, match=r"adapter 'fragile': " + message):
            run_suite(load_suite(repo / "s.toml"), repo / f"{scene}.sqlite", threads=1)


def test_a_render_is_taken_as_the_store_takes_it_and_complex_values_are_refused():
    # a (height, width) image, a list or a tensor had been stored as given: checked_render takes
    # them as images with one channel or as arrays, not as mistakes
    class Returns:
        def __init__(self, image):
            self.image = image

        def render(self, spp, seed):
            return Render(self.image, spp, 0.01)

        def exact(self):
            return None

    flat = base.checked_render(Returns([[1.0, 2.0], [3.0, 4.0]]), "flat", 4, 1)
    assert flat.image.shape == (2, 2, 1) and flat.image.dtype == np.float64 and flat.seconds == 0.01
    mask = base.checked_render(Returns(np.eye(2, dtype=bool)), "flat", 4, 1)   # as contributions take it
    assert mask.image.dtype == np.float64 and mask.image.sum() == 2.0
    for image, message in ((np.ones((2, 2, 3)) * 1j, r"returned a ndarray of complex128 values; expected"),
                           ([[1.0], [2.0, 3.0]], r"returned a list that is no array"),
                           (np.full((2, 2), "0.5"), r"returned a ndarray of <U3 values"),
                           (np.ones(4), r"returned an image of shape \(4,\)")):
        with pytest.raises(RenderError, match=r"adapter 'flat': render\(spp=4, seed=1\) " + message):
            base.checked_render(Returns(image), "flat", 4, 1)
