"""Real Mitsuba 3 renders (scalar_rgb and llvm_ad_rgb, 32 x 32) through the harness: the
adapter, the per-pixel bias test (false alarms and power), rendered-reference caching and a
suite that compares integrators."""
from __future__ import annotations

import json
import math
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from scipy import stats as sps

from harness.adapters import image_faults, renderer
from harness.adapters.base import RenderError
from harness.stats.images import Reference, pixel_bias_test, relmse
from harness.suite.parse import SuiteError, load_suite
from harness.suite.readers import load
from harness.suite.run import run_suite

VARIANTS = ["scalar_rgb", "llvm_ad_rgb"]


def _stack(r, spp: int, seeds) -> np.ndarray:
    return np.stack([r.render(spp, s).image for s in seeds])


@pytest.mark.parametrize("variant", VARIANTS)
def test_render_protocol_and_exact_scenes(variant):
    for scene, value in (("furnace", 1.0), ("plane", 0.5)):
        r = renderer("mitsuba", {"scene": scene, "integrator": "path", "variant": variant})
        out = r.render(16, 7)
        assert out.image.shape == (32, 32, 3) and out.image.dtype == np.float64
        assert out.spp == 16 and out.seconds > 0
        assert np.array_equal(out.image, r.render(16, 7).image)          # a seed fixes the image
        assert not np.array_equal(out.image, r.render(16, 8).image)
        assert np.all(r.exact() == value)
        assert image_faults(out.image).total == 0
        # the exact answer is what the renderer converges to: image mean within 4 standard errors
        imgs = _stack(r, 16, range(8))
        means = imgs.reshape(8, -1).mean(axis=1)
        assert abs(means.mean() - value) < 4 * means.std(ddof=1) / math.sqrt(8) + 1e-6
        fp = r.fingerprint()
        assert fp["variant"] == variant and fp["scene"] == scene and "mitsuba" in fp["environment"]


def test_spec_errors_name_the_key():
    cases = [({"scene": "nowhere"}, "'scene'"),
             ({"scene": "furnace", "integrator": "nosuch"}, "'integrator'"),
             ({"scene": "furnace", "variant": "llvm_ad_spectral"}, "'variant'"),
             ({"scene": "furnace", "variant": "x"}, "'variant'"),
             ({"scene": "furnace", "max_depth": 0}, "'max_depth'"),
             ({"scene": "furnace", "width": 0}, "'width'"), ({"scene": "furnace", "spp": 3}, "'spp'")]
    for spec, key in cases:
        with pytest.raises(ValueError, match=key):
            renderer("mitsuba", spec)


def test_pixel_bias_test_false_alarms_and_power():
    """Furnace, path tracer, llvm: 40 independent bias tests at alpha = 0.05 must not reject
    more often than Binomial(40, 0.05) allows at 1e-3; planted biases must be found."""
    r = renderer("mitsuba", {"scene": "furnace", "integrator": "path", "variant": "llvm_ad_rgb"})
    ref = Reference.exact(r.exact())
    runs = [_stack(r, 32, range(16 * k, 16 * k + 16)) for k in range(40)]
    p = np.array([pixel_bias_test(x, ref, 32).pvalue for x in runs])
    assert (p <= 0.05).sum() <= sps.binom.isf(1e-3, 40, 0.05)
    assert np.all((p >= 0) & (p <= 1))
    x = runs[0]
    # a global 1 % energy gain: the image-mean test sees it
    b = pixel_bias_test(x * 1.01, ref, 32)
    assert b.pvalue_mean < 1e-6 and b.pvalue < 1e-5
    # one pixel 30 % too bright in every replica: found, and the tile that rejects covers it.  The
    # furnace's pixels are left-skewed (and 56 % constant at 1), so the skew gate leaves their
    # bright side untested at the pixel scale; a 2 x 2 tile averages the skew down and finds it.
    y = x.copy()
    y[:, 16, 20, :] *= 1.3
    b = pixel_bias_test(y, ref, 32)
    s, (row, col, _) = b.worst_scale, b.worst_pixel
    assert b.pvalue < 1e-3 and s.size in (1, 2, 4) and b.worst_t > 0
    assert row <= 16 < row + s.size and col <= 20 < col + s.size, (s.name, b.worst_pixel)
    # a NaN pixel is excluded from the test, not averaged in
    z = x.copy()
    z[3, 5, 6, 1] = np.nan
    b = pixel_bias_test(z, ref, 32)
    assert b.excluded == 1 and math.isfinite(b.pvalue)
    assert image_faults(z[3]).nan == 1 and image_faults(z[3]).examples["nan"] == [(5, 6)]


def test_rendered_reference_error_enters_the_test():
    """Against a noisy rendered reference the test uses both errors (Welch), so a reference
    from few samples does not make a correct integrator look biased."""
    r = renderer("mitsuba", {"scene": "cornell", "integrator": "path", "variant": "llvm_ad_rgb",
                             "max_depth": 3})
    ref = Reference.from_parts(_stack(r.reference(), 64, range(1000, 1008)))
    assert ref.count == 8 and ref.parts.shape == (8, *ref.mean.shape) and np.all(ref.variance >= 0)
    b = pixel_bias_test(_stack(r, 64, range(16)), ref, 64)
    assert b.pvalue > 1e-3
    assert relmse(_stack(r, 64, range(16, 20)), ref).shape == (4,)


def _suite(tmp: Path, body: str) -> Path:
    path = tmp / "renders.toml"
    path.write_text(textwrap.dedent(body))
    return path


SUITE = """\
    [suite]
    name = "renders"
    alpha = 0.01

    [[render]]
    adapter = "mitsuba"
    scene = "furnace"
    integrator = ["path", "ptracer"]
    variant = "{variant}"
    spp = 256
    replicas = 8
    budgets = [16, 64, 256]

    [[render]]
    adapter = "mitsuba"
    scene = "furnace"
    integrator = "path"
    max_depth = 1            # camera rays only: the sphere stays black, a planted bias
    variant = "{variant}"
    spp = 16
    replicas = 8
    measurements = ["bias"]
    expect = "biased"

    [[render]]
    adapter = "mitsuba"
    scene = "cornell"
    integrator = ["path", "direct"]
    max_depth = 2
    variant = "{variant}"
    spp = 32
    replicas = 8
    budgets = [4, 16, 32]
    reference_spp = 2048
"""


@pytest.mark.parametrize("variant", VARIANTS)
def test_suite_compares_integrators_and_caches_references(tmp_path, variant):
    path = _suite(tmp_path, SUITE.format(variant=variant))
    suite = load_suite(path)
    assert [rc.label for rc in suite.renders][:2] == [f"integrator=path, variant={variant}",
                                                      f"integrator=ptracer, variant={variant}"]
    db = tmp_path / "a.sqlite"
    summary = run_suite(suite, db)
    rs = summary["render"].results
    assert len(rs) == 5
    verdicts = [v["bias"] for v in summary["render"].verdicts]
    assert verdicts == ["unbiased", "unbiased", "biased (expected)", "unbiased", "unbiased"], verdicts
    assert summary["render"].failures == ("",) * 5
    # exact scenes render no reference; the Cornell box's reference is rendered once for both
    # integrators (direct's reference is path tracing at depth 2, the same images) and cached
    refs = sorted((tmp_path / "references").glob("*-meta.json"))
    assert len(refs) == 1 and json.loads(refs[0].read_text())["spp"] == 2048
    assert rs[0].reference == "exact" and rs[3].reference == rs[4].reference != "exact"
    for r in (rs[0], rs[1], rs[3]):
        c = r.convergence
        lo, hi = c.confidence_interval()
        assert lo - 0.1 < -0.5 < hi + 0.1, c
    df = load(db)
    assert {"bias", "variance", "convergence", "efficiency", "relmse", "error_vs_time",
            "equal_time_relmse"} <= set(df["measurement"])
    eff = df[(df.measurement == "efficiency") & (df.integrand == "mitsuba:furnace")]
    assert eff["value"].iloc[0] == pytest.approx(1.0)          # path is the baseline
    assert eff["value"].iloc[1] < 0.1                          # the light tracer is far less efficient here
    assert (eff["lo"] <= eff["value"]).all() and (eff["value"] <= eff["hi"]).all()
    # a second database reuses the cached reference: the Cornell reference is not rendered again
    again = run_suite(suite, tmp_path / "b.sqlite")
    assert again.units_planned == summary.units_planned - 8
    # and a rerun on the first database renders nothing
    assert run_suite(suite, db).units_run == 0


def test_a_configuration_is_compared_with_a_sibling_without_a_converged_reference(tmp_path):
    """The light tracer against the path tracer's own 16 replicas (Jung et al.'s setting: two
    noisy renderers, no converged reference): the path tracer is tested against its rendered
    reference, the light tracer against the path tracer's replicas, both unbiased; the table
    names the reference configuration, and no reference is rendered for the light tracer."""
    table = ('{ adapter = "mitsuba", scene = "cornell", integrator = ["path", "ptracer"], max_depth = 2, '
             'variant = "llvm_ad_rgb", spp = 64, replicas = 16, measurements = ["bias"], '
             'reference = { integrator = "path" } }')
    path = _suite(tmp_path, f"render = [{table}]\n")
    summary = run_suite(load_suite(path), tmp_path / "s.sqlite")
    traced, light = summary["render"].results
    assert [v["bias"] for v in summary["render"].verdicts] == ["unbiased", "unbiased"]
    assert traced.bias.reference_parts == 8 and light.bias.reference_parts == 16
    assert light.reference == "integrator=path, max_depth=2, variant=llvm_ad_rgb"
    assert list(summary["render"].frame["reference"]) == ["4096 spp", light.reference]
    assert summary.units_planned == 16 + 16 + 8     # two sets of replicas and the path tracer's parts


def test_nan_pixels_are_reported_with_positions(tmp_path, monkeypatch):
    """A renderer that returns NaN pixels makes its case 'invalid', with counts and positions."""
    from harness.adapters.mitsuba import render as adapter

    real = adapter.MitsubaRenderer.render

    def broken(self, spp, seed):
        out = real(self, spp, seed)
        out.image[2, 3, 0] = np.nan
        return out

    monkeypatch.setattr(adapter.MitsubaRenderer, "render", broken)
    path = _suite(tmp_path, """\
        [[render]]
        adapter = "mitsuba"
        scene = "plane"
        spp = 8
        replicas = 4
        measurements = ["bias"]
    """)
    suite = load_suite(path)
    summary = run_suite(suite, tmp_path / "nan.sqlite")
    r = summary["render"].results[0]
    assert r.faults.nan == 4 and r.faults.examples["nan"][0] == (0, 2, 3)
    assert summary["render"].verdicts[0]["bias"] == "invalid"
    assert "invalid (4 bad pixels)" in summary["render"].failures[0]
    assert "nan pixel" in summary["render"].failures[0]
    assert r.bias.excluded == 1


def test_xml_scene_file(tmp_path):
    xml = tmp_path / "scene.xml"
    xml.write_text(textwrap.dedent("""\
        <scene version="3.0.0">
          <sensor type="perspective">
            <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
            <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
              <rfilter type="box"/></film>
          </sensor>
          <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
          <shape type="sphere"><bsdf type="diffuse"><rgb name="reflectance" value="1"/></bsdf></shape>
        </scene>"""))
    r = renderer("mitsuba", {"scene": str(xml), "integrator": "path"})
    assert r.exact() is None and r.render(4, 1).image.shape == (16, 16, 3)
    fp = r.fingerprint()
    assert fp["scene"] == {"sha256": __import__("hashlib").sha256(xml.read_bytes()).hexdigest()}
    assert fp["environment"]["file"] == str(xml.resolve())   # where it lies: the key's, not the seeds'
    with pytest.raises(ValueError, match="'width'"):
        renderer("mitsuba", {"scene": str(xml), "width": 8})
    # a relative path from the suite file's folder (base), as every adapter's paths
    relative = renderer("mitsuba", {"scene": "scene.xml"}, base=tmp_path)
    assert relative.fingerprint()["environment"]["file"] == str(xml.resolve())
    with pytest.raises(ValueError, match=r"'scene': 'scene.xml' is neither .* existing file \(/"):
        renderer("mitsuba", {"scene": "scene.xml"}, base=tmp_path / "elsewhere")


SCENE_WITH_FILES = """\
    <scene version="3.0.0">
      <!-- ---------- what it reads ---------- -->
      <default name="mesh" value="tri.obj"/>
      <path value="textures"/>
      <sensor type="perspective">
        <transform name="to_world"><lookat origin="0,0,3" target="0,0,0" up="0,1,0"/></transform>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/>
          <rfilter type="box"/></film>
      </sensor>
      <include filename="parts/light.xml"/>
      <!-- <shape type="obj"><string name="filename" value="old.obj"/></shape> -->
      <shape type="obj"><string name="filename" value="$mesh"/>
        <bsdf type="diffuse"><texture type="bitmap" name="reflectance">
          <string name="filename" value="albedo.exr"/></texture></bsdf>
      </shape>
    </scene>"""


def test_the_files_a_scene_reads_are_in_its_key_and_reload_it(tmp_path):
    """A mesh named through a <default>, a texture found through a <path> tag and an included
    file that reads the environment map from the scene's folder: each one's digest is in the
    renderer's environment (and a same-named mesh in the <path> folder's, which Mitsuba may
    read in its place; not a file named only in a comment), so editing one re-renders on the
    same seeds, and the renderer loads the scene again; a comment holding "--", which XML
    forbids and Mitsuba's parser takes, is read as Mitsuba reads it."""
    from harness.adapters.mitsuba.runtime import activate
    from harness.suite.parse import loads_suite
    from harness.suite.plan import render_key, render_stream

    (tmp_path / "parts").mkdir()
    (tmp_path / "textures").mkdir()
    xml = tmp_path / "scene.xml"
    xml.write_text(textwrap.dedent(SCENE_WITH_FILES))
    (tmp_path / "parts" / "light.xml").write_text(
        '<scene version="3.0.0"><emitter type="envmap"><string name="filename" value="sky.exr"/>'
        "</emitter></scene>")
    triangle = "v -2 -2 0\nv 2 -2 0\nv 0 2 0\nvt 0 0\nvt 1 0\nvt 0.5 1\nf 1/1 2/2 3/3\n"
    for mesh in ("tri.obj", "textures/tri.obj", "old.obj"):
        (tmp_path / mesh).write_text(triangle)

    def write_exr(path, value):
        activate("scalar_rgb").Bitmap(np.full((4, 8, 3), value, dtype=np.float32)).write(str(path))

    write_exr(tmp_path / "sky.exr", 1.0)
    write_exr(tmp_path / "textures" / "albedo.exr", 0.5)
    r = renderer("mitsuba", {"scene": str(xml), "integrator": "direct"})
    before, image = r.fingerprint(), r.render(16, 3).image
    reads = before["environment"]["reads"]
    assert sorted(reads) == ["parts/light.xml", "sky.exr", "textures/albedo.exr", "textures/tri.obj",
                             "tri.obj"]
    assert all(isinstance(d, str) and len(d) == 24 for d in reads.values())

    write_exr(tmp_path / "textures" / "albedo.exr", 0.25)   # a darker triangle
    after = r.fingerprint()
    assert {k for k in reads if after["environment"]["reads"][k] != reads[k]} == {"textures/albedo.exr"}
    assert after["scene"] == before["scene"]
    suite = loads_suite('[[render]]\nadapter = "mitsuba"\nscene = "furnace"\n')
    assert render_key(suite, after) != render_key(suite, before)          # rendered again ...
    assert render_stream(suite, after) == render_stream(suite, before)    # ... on the same seeds
    darker = r.render(16, 3).image                                        # the scene loaded again
    assert darker.mean() < image.mean() and not np.array_equal(darker, image)
    (tmp_path / "textures" / "tri.obj").write_text(triangle + "\n")     # the shadowing candidate
    assert r.fingerprint()["environment"]["reads"]["textures/tri.obj"] != reads["textures/tri.obj"]
    write_exr(tmp_path / "textures" / "albedo.exr", 0.75)   # keyed, then edited before it loads
    r.fingerprint()
    write_exr(tmp_path / "textures" / "albedo.exr", 0.6)
    with pytest.raises(RenderError, match=r"its files changed after the run took its key "
                                          r"\(textures/albedo\.exr\); run it again"):
        r.render(16, 3)
    r.fingerprint()

    (tmp_path / "tri.obj").unlink()
    (tmp_path / "textures" / "tri.obj").unlink()
    assert "tri.obj" not in r.fingerprint()["environment"]["reads"]
    with pytest.raises(RenderError, match=r"Mitsuba cannot load .*scene\.xml: .*tri\.obj"):
        r.render(16, 3)   # Mitsuba's loader reports the missing mesh
    with pytest.raises(ValueError, match=r"^'scene': Mitsuba cannot load .*scene\.xml: .*tri\.obj"):
        renderer("mitsuba", {"scene": str(xml)})   # the scene's key named, not the integrator's
    assert renderer("mitsuba", {"scene": "furnace"}).fingerprint()["environment"].get("reads") is None


def test_a_folder_added_to_mitsubas_resolver_is_searched_for_the_scenes_files(tmp_path, monkeypatch):
    """Mitsuba finds a scene's files in the folders of its file resolver too: the working folder
    it was imported in (a later chdir does not move it) and any a user appends (a shared
    folder of assets).  Their files are in the key; an edit there renders again.  Taking the
    key leaves the resolver as it was (Mitsuba's parser adds a scene's <path> folders to it)."""
    from harness.adapters.mitsuba.runtime import activate, using_variant

    (tmp_path / "scene" / "textures").mkdir(parents=True)     # the <path> folder, empty
    (tmp_path / "assets").mkdir()
    xml = tmp_path / "scene" / "scene.xml"
    xml.write_text(textwrap.dedent(SCENE_WITH_FILES).replace('<include filename="parts/light.xml"/>', ""))
    (tmp_path / "assets" / "tri.obj").write_text("v -2 -2 0\nv 2 -2 0\nv 0 2 0\nf 1 2 3\n")
    albedo = tmp_path / "assets" / "albedo.exr"
    activate("scalar_rgb").Bitmap(np.full((4, 8, 3), 0.5, dtype=np.float32)).write(str(albedo))
    monkeypatch.chdir(tmp_path / "scene")       # not where Mitsuba's resolver began
    with using_variant("scalar_rgb") as mi:
        resolver = mi.file_resolver()
        kept = [str(resolver[i]) for i in range(len(resolver))]
        resolver.append(str(tmp_path / "assets"))
    try:
        r = renderer("mitsuba", {"scene": str(xml), "integrator": "direct"})
        reads = r.fingerprint()["environment"]["reads"]
        assets = (tmp_path / "assets").resolve()
        assert sorted(reads) == [str(assets / "albedo.exr"), str(assets / "tri.obj")]
        with using_variant("scalar_rgb") as mi:
            folders = mi.file_resolver()
            assert [str(folders[i]) for i in range(len(folders))] == kept + [str(assets)]
        assert r.render(4, 1).image.shape == (8, 8, 3)   # Mitsuba found them there too
        activate("scalar_rgb").Bitmap(np.full((4, 8, 3), 0.25, dtype=np.float32)).write(str(albedo))
        assert r.fingerprint()["environment"]["reads"][str(albedo.resolve())] != reads[str(albedo.resolve())]
    finally:
        with using_variant("scalar_rgb") as mi:
            mi.file_resolver().clear()
            for folder in kept:
                mi.file_resolver().append(folder)


def test_scene_files_without_mitsubas_parser_read_the_text(tmp_path, monkeypatch):
    """Without Mitsuba's parser (mi.parser) the names come from the files' text: the same files
    as the parser's here, the commented-out mesh too (a superset); an include that holds only a
    <default> (which the parser does not list) either way; an unreadable file recorded."""
    from harness.adapters.mitsuba import scene_files as sf

    (tmp_path / "parts").mkdir()
    (tmp_path / "textures").mkdir()
    (tmp_path / "scene.xml").write_text(textwrap.dedent(SCENE_WITH_FILES))
    (tmp_path / "parts" / "light.xml").write_text(
        '<scene version="3.0.0"><include filename="more.inc"/>'
        '<emitter type="envmap"><string name="filename" value="sky.exr"/></emitter></scene>')
    (tmp_path / "more.inc").write_text('<scene version="3.0.0"><default name="x" value="1"/></scene>')
    for name in ("tri.obj", "old.obj", "sky.exr", "textures/albedo.exr"):
        (tmp_path / name).write_text(name)
    parsed = sf.scene_files(tmp_path / "scene.xml", "scalar_rgb")
    monkeypatch.setattr(sf, "_parsed", lambda scene, variant: None)
    scanned = sf.scene_files(tmp_path / "scene.xml", "scalar_rgb")
    assert sorted(parsed) == ["more.inc", "parts/light.xml", "sky.exr", "textures/albedo.exr", "tri.obj"]
    assert sorted(scanned) == sorted([*parsed, "old.obj"]) and all(scanned[k] == v for k, v in parsed.items())
    monkeypatch.setattr(sf, "file_digest", lambda path: (_ for _ in ()).throw(PermissionError(13, "denied")))
    assert set(sf.scene_files(tmp_path / "scene.xml", "scalar_rgb").values()) == {"unreadable: denied"}


def test_suite_errors_name_file_line_and_key(tmp_path):
    for body, line, key in [
        ('[[render]]\nadapter = "mitsuba"\nscene = "furnace"\nintegrator = "nosuch"\n', 4, "integrator"),
        ('[[render]]\nadapter = "mitsuba"\nscene = "furnace"\nvariant = "bogus"\n', 4, "variant"),
        ('[[render]]\nadapter = "mitsuba"\nscene = "nowhere"\n', 3, "scene"),
        ('[[render]]\nadapter = "povray"\n', 2, "adapter"),
        ('[[render]]\nadapter = "mitsuba"\nscene = "furnace"\nreplicas = 2\n', 4, "replicas"),
        ('[[render]]\nadapter = "mitsuba"\nscene = "furnace"\nbudgets = [4, 4]\n', 4, "budgets"),
        ('[[render]]\nadapter = "mitsuba"\nscene = "furnace"\nexpect = "maybe"\n', 4, "expect"),
        ('[[render]]\nadapter = "mitsuba"\nscene = "cornell"\nreference_spp = 100\n', 4, "reference_spp"),
    ]:
        path = tmp_path / "bad.toml"
        path.write_text(body)
        with pytest.raises(SuiteError, match=rf"bad\.toml:{line}: {key}: "):
            load_suite(path)


def test_suite_file_as_pytest_items(tmp_path, root):
    """`pytest suites/mitsuba.toml`-style collection: a render table becomes test items."""
    path = _suite(tmp_path, """\
        [suite]
        name = "items"
        [[render]]
        adapter = "mitsuba"
        scene = "plane"
        integrator = ["path", "direct"]
        spp = 32
        replicas = 8
        budgets = [4, 8, 32]
    """)
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", str(path), "-p", "no:cacheprovider",
                          "--harness-db", str(tmp_path / "items.sqlite")],
                         capture_output=True, text=True, cwd=root)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "2 passed" in out.stdout


def test_interrupted_render_suite_resumes_without_rerendering(tmp_path, monkeypatch):
    """A run stopped after 5 renders resumes with the missing ones only and ends with the same
    measurements as an uninterrupted run (renders are seeded per case, stream and replica)."""
    from harness.adapters.mitsuba import render as adapter

    path = _suite(tmp_path, """\
        [[render]]
        adapter = "mitsuba"
        scene = "cornell"
        integrator = "path"
        max_depth = 2
        spp = 8
        replicas = 4
        budgets = [2, 4, 8]
        reference_spp = 256
    """)
    suite = load_suite(path)
    clean = run_suite(suite, tmp_path / "clean.sqlite")

    real, calls = adapter.MitsubaRenderer.render, []

    def flaky(self, spp, seed):
        calls.append(seed)
        if len(calls) > 5:
            raise KeyboardInterrupt
        return real(self, spp, seed)

    monkeypatch.setattr(adapter.MitsubaRenderer, "render", flaky)
    (tmp_path / "references").rename(tmp_path / "references.clean")  # the resumed run renders its own
    with pytest.raises(KeyboardInterrupt):
        run_suite(suite, tmp_path / "resumed.sqlite")
    monkeypatch.setattr(adapter.MitsubaRenderer, "render", real)
    resumed = run_suite(suite, tmp_path / "resumed.sqlite")
    assert resumed.units_run == resumed.units_planned - 5
    a, b = load(tmp_path / "clean.sqlite"), load(tmp_path / "resumed.sqlite")
    assert a[["measurement", "pvalue"]].equals(b[["measurement", "pvalue"]])
    assert clean["render"].results[0].bias.pvalue == resumed["render"].results[0].bias.pvalue
