"""The HTML report, opened in a real browser (Debian's headless Chromium through Playwright),
and its CSV / Markdown tables, from a real SQLite store: a tiny suite run by the runner (three
estimators, two sampler checks) plus two render cases whose images and measurement rows the
test stores itself, and one superseded case from an "earlier run" that must not be shown."""
from __future__ import annotations

import io
import json
import math
import shutil
import sqlite3
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from PIL import Image
from playwright.sync_api import sync_playwright

from harness.cli import main
from harness.suite.parse import load_suite
from harness.suite.readers import load
from harness.suite.run import run_suite
from harness.suite.store import Store
from reports import images, load_results

CHROMIUM = "/usr/bin/chromium"
SCREENSHOT_COPY = Path("/tmp/report-screenshot.png")
TECHNIQUES = ["uniform", "importance:linear", "uniform/stratified"]
STALE_ESTIMATE = 123.456789   # the superseded case's estimate: must not appear anywhere


def _scene(h: int = 48, w: int = 64) -> np.ndarray:
    """A small linear-radiance test image: a gradient, a bright disc above 1, a dark corner."""
    y, x = np.mgrid[0:h, 0:w] / np.array([h, w])[:, None, None]
    img = np.stack([0.2 + 0.6 * x, 0.1 + 0.5 * y, 0.3 + 0.2 * x * y], axis=2)
    img[(x - 0.6) ** 2 + (y - 0.45) ** 2 < 0.04] = [1.5, 1.2, 0.9]
    img[: h // 6, : w // 6] = 0.0
    return img.astype(np.float32)


def _render_rows(key: str, technique: str, scale: float, baseline: str) -> list[dict]:
    """Measurement rows as a renderer adapter stores them (names and detail keys as in
    harness.suite.renders)."""
    budgets = [4, 16, 64]
    rmse = [scale * 0.4 * (b / 4) ** -0.5 for b in budgets]
    common = {"case_key": key, "suite": "tiny", "integrand": "toy_scene", "technique": technique,
              "alpha": 0.01}
    return [
        {**common, "measurement": "bias", "value": 1e-4, "lo": -2e-4, "hi": 4e-4, "n": 128, "pvalue": 0.6,
         "verdict": "unbiased", "detail": {"spp": 16, "replicas": 8, "worst_scale": "2x2 tiles",
                                           "scales": [{"scale": "pixels", "pvalue": 0.7},
                                                      {"scale": "2x2 tiles", "pvalue": 0.1}],
                                           "pvalue_counts": [60 + 3 * k for k in range(20)]}},
        {**common, "measurement": "convergence", "value": -0.5, "lo": -0.6, "hi": -0.4, "n": 24,
         "pvalue": 0.9, "verdict": "as expected",
         "detail": {"expected": -0.5, "budgets": budgets, "rmse": rmse, "rmse_lo": [0.8 * r for r in rmse],
                    "rmse_hi": [1.25 * r for r in rmse], "seconds": [0.002 * b * scale for b in budgets],
                    "error": "sqrt(relMSE)"}},
        {**common, "measurement": "efficiency", "value": 1 / scale**3, "lo": 0.8 / scale**3,
         "hi": 1.25 / scale**3, "n": 128, "detail": {"baseline": baseline, "definition": "1/(relMSE T)"}},
        {**common, "measurement": "relmse", "value": 0.01 * scale, "lo": 0.008 * scale, "hi": 0.012 * scale,
         "n": 8, "detail": {"spp": 64}},
    ]


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> dict:
    """Runs the tiny suite, stores the render cases, writes the report in all three formats."""
    tmp = tmp_path_factory.mktemp("report")
    suite_file = tmp / "tiny.toml"
    suite_file.write_text(textwrap.dedent(f"""\
        [suite]
        name = "tiny"
        seed = 3
        samples = 65_536
        alpha = 0.01
        batches = 16
        replicas = 8
        budgets = [256, 1024, 4096]

        [[case]]
        integrand = "gaussian"
        techniques = {json.dumps(TECHNIQUES)}

        [[sampler]]
        name = "cosine_hemisphere"
        samples = 20_000

        [[sampler]]
        name = "linear"
        samples = 20_000
        """))
    db = tmp / "tiny.sqlite"
    suite = load_suite(suite_file)
    # an "earlier run" of gaussian/uniform under another build: same definition, older rows
    store = Store(db)
    store.add_case("0" * 24, "tiny", "gaussian", "uniform", {"seed": 3, "case_id": 0, "samples": 65536})
    earlier = store.start_run("tiny", str(suite_file), "an earlier revision")
    store.finish_run(earlier, [{"case_key": "0" * 24, "suite": "tiny", "integrand": "gaussian",
                                "technique": "uniform", "measurement": "bias", "value": 1.0, "n": 65536,
                                "pvalue": 1e-9, "alpha": 0.01, "verdict": "biased",
                                "detail": {"estimate": STALE_ESTIMATE, "stderr": 0.1}}], 0, 0)
    store.close()
    run = run_suite(suite, db, threads=2)

    rng = np.random.default_rng(0)
    ref = _scene()
    store = Store(db)
    renders = {}
    for key, technique, scale in (("a" * 24, "integrator=path, variant=test", 1.0),
                                  ("b" * 24, "integrator=ptracer, variant=test", 2.5)):
        est = ref + rng.normal(0, 0.05 * scale, ref.shape).astype(np.float32) * np.sqrt(ref + 0.05)
        if scale > 1:
            est[5, 40] = np.nan   # one broken pixel: drawn magenta and counted
        store.add_case(key, "tiny", "toy_scene", technique, {"adapter": "test", "spp": 64})
        store.put_image(f"{key}/reference", ref)
        store.put_image(f"{key}/estimate", est)
        store.put_measurements(_render_rows(key, technique, scale, "integrator=path, variant=test"),
                               run=run.run)
        if scale == 1:   # the first case has a stored bias test's |t| map (the second shows none)
            store.put_image(f"{key}/tmap", np.abs(est - ref)[:, :, :1] / 0.05)
        renders[key] = (ref, est)
    store.close()

    out = {"db": db, "tmp": tmp, "run": run, "renders": renders}
    for fmt, suffix in (("html", "html"), ("csv", "csv"), ("markdown", "md")):
        path = tmp / f"report.{suffix}"
        assert main(["report", "--db", str(db), "-o", str(path), "--format", fmt]) == 0
        out[fmt] = path
    return out


# --- in the browser -------------------------------------------------------------------------------
_PIXEL_STATS = """
imgs => imgs.map(img => {
  const c = document.createElement('canvas');
  c.width = img.naturalWidth; c.height = img.naturalHeight;
  const g = c.getContext('2d');
  g.drawImage(img, 0, 0);
  const d = g.getImageData(0, 0, c.width, c.height).data;
  let s = 0, s2 = 0, n = 0;
  for (let i = 0; i < d.length; i += 4) {
    const y = 0.299 * d[i] + 0.587 * d[i + 1] + 0.114 * d[i + 2];
    s += y; s2 += y * y; n++;
  }
  const m = s / n;
  return {cls: img.className, alt: img.alt, complete: img.complete, w: img.naturalWidth, h: img.naturalHeight,
          shownW: img.getBoundingClientRect().width, std: Math.sqrt(Math.max(s2 / n - m * m, 0))};
})
"""


def _png_std(png: bytes) -> float:
    """Standard deviation of the luminance (0..255) of a screenshot."""
    a = np.asarray(Image.open(io.BytesIO(png)).convert("L"), dtype=float)
    return float(a.std())


def _png_array(png: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=float)


def test_report_in_chromium(report):
    """Loads without console errors or network requests; every image decodes and shows
    something (pixel variance in the image and in its on-screen crop); tables, compare
    control and filter work; saves a screenshot."""
    html_path: Path = report["html"]
    errors, requests = [], []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM)
        try:
            page = browser.new_page(viewport={"width": 1500, "height": 1000})
            page.on("console",
                    lambda m: errors.append(f"console.{m.type}: {m.text}") if m.type == "error" else None)
            page.on("pageerror", lambda e: errors.append(f"page error: {e}"))
            page.on("request",
                    lambda r: requests.append(r.url) if not r.url.startswith(("data:", "file:")) else None)
            page.goto(html_path.as_uri(), wait_until="load")
            assert errors == [], errors
            assert requests == [], f"the report fetched from the network: {requests}"

            # every image decoded and is not blank (luminance spread in its own pixels)
            stats = page.eval_on_selector_all("img", _PIXEL_STATS)
            by_cls = {}
            for s in stats:
                by_cls.setdefault(s["cls"].split()[0], []).append(s)
                assert s["complete"] and s["w"] > 0 and s["h"] > 0, s
                assert s["shownW"] > 0, f"image not displayed: {s}"
                if s["cls"] != "colorbar":
                    assert s["std"] > 4, f"blank image: {s}"
            # 1 integrand figure, 1 scene figure, 2 sampler figures, 1 p-value histogram; per render 3
            # images (4 with the bias test's |t| map) + 2 in the wipe
            assert len(by_cls["plot"]) == 5, [s["alt"] for s in by_cls["plot"]]
            assert len(by_cls["render-img"]) == 7
            body = page.inner_text("body")
            assert "bias test |t| at 2x2 tiles" in body and "p-values of the pixels test" in body
            assert len(by_cls["under"]) == len(by_cls["top"]) == 2
            assert len(by_cls["colorbar"]) == 2                         # one scale per error map

            # what a person sees: each figure's on-screen crop has structure, not a blank box
            for loc in page.locator("img.plot").all() + page.locator("img.render-img").all():
                loc.scroll_into_view_if_needed()
                assert _png_std(loc.screenshot()) > 4, loc.get_attribute("alt")

            # summary: every case once (the superseded one not at all), verdicts, p, alpha, n
            rows = page.locator(".summary-table tbody tr")
            assert rows.count() == len(TECHNIQUES) + 2
            text = page.inner_text("#summary").replace("\xa0", " ")
            for t in TECHNIQUES + ["integrator=ptracer, variant=test", "α", "verdict (p)", "n = 65,536",
                                   "p = "]:
                assert t in text, t
            assert page.locator(".summary-table .badge.good").count() >= len(TECHNIQUES) + 2
            content = page.content()
            assert str(STALE_ESTIMATE) not in content and "1 superseded case" in content
            assert ("tiny: α = 0.01 for the whole run, 0.00333 for each of 3 families (estimator bias, "
                    "estimator convergence, sampler checks), Holm within each") in page.inner_text("header")
            samplers = page.inner_text("#sampler-table")
            assert "cosine_hemisphere" in samplers and "linear" in samplers and "passed" in samplers

            # the filter hides rows
            page.fill("#filter", "stratified")
            assert page.locator(".summary-table tbody tr:visible").count() == 1
            page.fill("#filter", "")
            assert page.locator(".summary-table tbody tr:visible").count() == len(TECHNIQUES) + 2

            # the wipe: all reference at 100, all estimate at 0, different pictures; flip toggles
            art = page.locator("article.render").first
            art.scroll_into_view_if_needed()
            slider, view = art.locator(".wipe input"), art.locator(".compare")
            slider.fill("100")
            shot_ref = _png_array(view.screenshot())
            slider.fill("0")
            shot_est = _png_array(view.screenshot())
            assert np.abs(shot_ref - shot_est).mean() > 1.0
            art.locator("button.flip").click()
            assert slider.input_value() == "100"
            assert np.abs(_png_array(view.screenshot()) - shot_ref).mean() < 0.5
            # the NaN planted in one estimate
            assert page.inner_text("#renders").count("; 1 non-finite pixel") == 1
            # one colour scale per scene: both configurations of toy_scene share the error map's ticks
            ticks = [t.inner_text() for t in page.locator("#renders .ticks").all()]
            assert len(ticks) == 2 and ticks[0] == ticks[1], ticks
            # the header says what the database holds, by kind
            assert "3 estimator cases, 2 sampler checks, 2 render configurations" in page.inner_text("header")
            # the summary tables fit a 1400 px wide window: no horizontal scrolling
            page.set_viewport_size({"width": 1400, "height": 1000})
            widths = page.eval_on_selector_all("#summary .scroll", "els => els.map(e => [e.scrollWidth, "
                                                                   "e.clientWidth])")
            assert len(widths) == 2 and all(sw <= cw for sw, cw in widths), widths
            page.set_viewport_size({"width": 1500, "height": 1000})
            assert errors == [], errors

            page.evaluate("window.scrollTo(0, 0)")
            shot = report["tmp"] / "report.png"
            page.screenshot(path=str(shot), full_page=True)
        finally:
            browser.close()
    assert _png_std(shot.read_bytes()) > 10
    shutil.copyfile(shot, SCREENSHOT_COPY)


# --- tables ---------------------------------------------------------------------------------------
def test_csv_has_every_case_with_stored_numbers(report):
    df = pd.read_csv(report["csv"])
    stored = load(report["db"])
    assert len(df) == len(TECHNIQUES) + 2 + 2           # estimators, renders, sampler checks
    assert set(df["kind"]) == {"estimator", "render", "sampler"}
    for col in ("alpha", "bias", "bias_lo", "bias_hi", "bias_n", "bias_pvalue", "bias_verdict",
                "convergence_slope", "convergence_slope_lo", "convergence_slope_hi", "efficiency_ratio",
                "chi_square_pvalue", "chi_square_verdict", "relmse"):
        assert col in df, col
    # the numbers are the stored ones, not recomputed
    for tech in TECHNIQUES:
        row = df[(df["integrand"] == "gaussian") & (df["technique"] == tech)].iloc[0]
        want = stored[(stored["integrand"] == "gaussian") & (stored["technique"] == tech)
                      & (stored["measurement"] == "bias") & (stored["case_key"] == row["case_key"])].iloc[0]
        assert (row["bias"] == want["value"] and row["bias_pvalue"] == want["pvalue"]
                and row["bias_n"] == want["n"])
        assert row["bias_verdict"] == "unbiased" and row["alpha"] == 0.01 / 3   # 3 families share alpha
    assert (df["case_key"] != "0" * 24).all()           # the superseded run is left out


def test_markdown_tables(report):
    md = report["markdown"].read_text()
    for heading in ("## Cases", "## Render cases", "## Sampler checks"):
        assert heading in md
    lines = [ln for ln in md.splitlines() if ln.startswith("| gaussian")]
    assert len(lines) == len(TECHNIQUES)
    assert all("(p = " in ln and "n = 65,536)" in ln and "estimate 0.74" in ln for ln in lines)
    assert md.count("| toy_scene") == 2 and "| cosine_hemisphere" in md


# --- what the report reads ------------------------------------------------------------------------
def test_sampler_checks_store_residual_grids_and_marginals(report):
    res = load_results(report["db"])
    rows = {r["integrand"]: r for r in res.samplers.to_dict("records")}
    hemi = rows["sampler:cosine_hemisphere"]["detail"]
    coarse = np.asarray(hemi["residuals"]["coarse"], float)
    assert coarse.shape == (16, 32)
    # standardised residuals of a correct sampler: mean 0, variance 1 over the 512 cells (about 39
    # samples each; pdf cos(theta)/pi leaves the cells at the horizon below 5 expected: pooled, NaN)
    assert (0.85 < np.nanstd(coarse) < 1.15 and abs(np.nanmean(coarse)) < 0.15
            and np.isfinite(coarse).mean() > 0.9)
    assert np.isnan(coarse[0]).all()
    fine = np.asarray(hemi["residuals"]["fine"], float)   # 2.4 samples a cell: every one pooled
    assert fine.shape == (64, 128) and np.isnan(fine).all()
    for axis in ("s0", "s1"):
        m = hemi["marginals"][axis]
        assert len(m["observed"]) == len(m["expected"]) == 128
        assert sum(m["observed"]) == 20_000 and abs(sum(m["expected"]) - 20_000) < 1
    line = rows["sampler:linear"]["detail"]
    assert len(line["residuals"]["fine"]) == 512 and list(line["marginals"]) == ["s0"]


def test_latest_run_only_and_image_pairs(report):
    res = load_results(report["db"])
    assert res.superseded == 1
    assert "0" * 24 not in set(res.measurements["case_key"])
    assert set(res.image_pairs) == {"a" * 24, "b" * 24}
    assert set(res.of_kind("render")["integrand"]) == {"toy_scene"}


# --- the error map and tone mapping ------------------------------------------------------------------
def test_relmse_map_and_tonemap_values():
    ref = np.full((2, 3, 3), 0.5, np.float32)
    assert np.all(images.relmse_map(ref, ref) == 0)
    # est = 2 ref: (ref)^2 / (ref^2 + 0.01) per channel
    assert np.allclose(images.relmse_map(ref, 2 * ref), 0.25 / 0.26)
    grey = images.relmse_map(np.zeros((1, 1, 1)), np.full((1, 1, 1), 0.1))   # one channel counts as grey
    assert np.allclose(grey, 0.01 / 0.01)
    t = images.tonemap(np.array([[[0.0, 1.0, 0.5], [2.0, -1.0, np.nan]]], np.float32))
    assert t[0, 0].tolist() == [0, 255, 188]               # sRGB(0.5) = 0.735 -> 188
    assert t[0, 1].tolist() == [255, 0, 255]               # NaN pixel: magenta
    with pytest.raises(ValueError, match="same shape"):
        images.relmse_map(ref, ref[:1])


def test_error_map_scale_spans_four_decades_below_the_percentile():
    rng = np.random.default_rng(1)
    ref = rng.uniform(0.2, 1.0, (32, 32, 3)).astype(np.float32)
    est = ref * (1 + rng.normal(0, 0.1, ref.shape)).astype(np.float32)
    est[0, 0] = np.inf
    m = images.error_map(ref, est)
    top = np.nanquantile(images.relmse_map(ref, est)[np.isfinite(images.relmse_map(ref, est))], 0.995)
    assert m.vmax / 10 < top <= m.vmax and math.isclose(m.vmin, m.vmax / 1e4)
    assert m.nonfinite == 1 and m.pixels == 32 * 32 - 1 and m.rgb[0, 0].tolist() == [255, 0, 255]
    assert m.rgb.shape == (32, 32, 3) and m.rgb.dtype == np.uint8


def test_slope_verdicts_state_their_margin_where_p_rounds_to_1():
    from reports.tables import _p_note

    row = {"convergence_pvalue": 1.0, "convergence_z": -12.3, "convergence_bound": -0.45}
    assert _p_note(row, "convergence") == "p ≈ 1: 12.3 s.e. inside the bound -0.45"
    assert _p_note({**row, "convergence_pvalue": 0.4}, "convergence") == "p = 0.4"
    assert _p_note({"convergence_pvalue": 1.0}, "convergence") == "p = 1"       # stored before z was


def test_results_of_the_python_api_are_recorded_and_reported(tmp_path):
    import harness
    from harness import stats
    from harness.samplers import check_sampler

    def nee(u):
        return 1.5 * np.sqrt(u[:, 0])

    def cosine(u):
        r, phi = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
        return np.column_stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - r * r)])

    db = tmp_path / "mine.sqlite"
    results = {"nee": harness.check_unbiased(nee, 2, 1.0, sample_count=100_000),
               "nee rate": stats.convergence_rate(nee, budgets=[1024, 4096, 16384], dim=2, reference=1.0)}
    assert harness.record(db, results, suite="mine") == 2
    check = check_sampler(cosine, lambda x: x[:, 2] / np.pi, "hemisphere", sample_count=50_000)
    with pytest.raises(TypeError, match="needs domain="):
        harness.record(db, {"cosine": check}, suite="mine")
    harness.record(db, {"cosine": check}, suite="mine", domain="hemisphere")
    with pytest.raises(TypeError, match="cannot record a str"):
        harness.record(db, {"x": "passed"})
    assert main(["report", "--db", str(db), "-o", str(tmp_path / "mine.html")]) == 0
    page = (tmp_path / "mine.html").read_text()
    assert "2 estimator cases, 1 sampler check" in page
    assert page.count('<img class="plot"') == 2          # the convergence figure and the sampler's
    stored = load(db).set_index("measurement")
    assert stored.loc["bias", "verdict"] == "unbiased" and stored.loc["chi_square", "verdict"] == "passed"
    harness.record(db, results, suite="mine")          # recorded again: replaced, not added
    assert len(load(db)) == 3


def test_report_cli_errors(tmp_path, capsys):
    assert main(["report", "--db", str(tmp_path / "none.sqlite")]) == 2
    assert "no results database" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["report", "--db", str(tmp_path / "none.sqlite"), "--format", "pdf"])


def test_an_efficiency_in_clock_ticks_is_recorded_as_its_own_measurement(tmp_path):
    """harness.record keeps the two efficiency figures apart: 1/(V·T) in 1/s (an interval of
    that run's machine state) and in reference-clock ticks (an interval across runs)."""
    import json

    import harness
    from harness import stats

    r = stats.replicate("gaussian", "importance:linear", 65536, 8, seed=0, clock=True)
    db = tmp_path / "eff.sqlite"
    figures = {"is": stats.efficiency(r), "is (clock)": stats.efficiency(r, clock=True)}
    harness.record(db, figures, suite="eff")
    stored = load(db).set_index("measurement")
    assert set(stored.index) == {"log10_efficiency", "log10_efficiency_clock"}
    s, k = stored.loc["log10_efficiency"], stored.loc["log10_efficiency_clock"]
    assert json.loads(s["detail"])["interval"] == "this run's machine state"
    assert json.loads(k["detail"])["interval"].startswith("across runs")
    assert k["lo"] < k["value"] < k["hi"] and s["lo"] < s["value"] < s["hi"]


def test_recording_under_a_suite_files_name_is_refused(tmp_path):
    # it had replaced that suite's plan (harness gc then removed its units) and hidden its results
    import harness
    from harness.suite.parse import loads_suite
    from harness.suite.run import run_suite

    db = tmp_path / "t.sqlite"
    run_suite(loads_suite('[suite]\nname = "tiny"\nsamples = 4096\nmeasurements = ["bias"]\n\n[[case]]\n'
                          'integrand = "gaussian"\ntechniques = "uniform"\n', path=tmp_path / "tiny.toml"),
              db, threads=1)
    before = load(db)
    r = harness.check_unbiased(lambda u: u[:, 0], 1, 0.5, sample_count=10_000)
    with pytest.raises(ValueError, match=r"'suite': 'tiny' names the suite of .*tiny.toml in .*t.sqlite; "
                                         r"record under another name"):
        harness.record(db, {"mine": r}, suite="tiny")
    assert load(db).equals(before)
    with sqlite3.connect(db) as con:   # nothing written: no case of the recording under the suite's name
        assert con.execute("SELECT COUNT(*) FROM cases WHERE technique = 'check_unbiased'").fetchone() == (0,)
    with pytest.raises(TypeError, match="'results' must be a mapping of names to results, got list"):
        harness.record(db, [r])
    with pytest.raises(ValueError, match="a result's name must be a non-empty string, got None"):
        harness.record(db, {None: r})
    assert harness.record(db, {"mine": r}, suite="mine") == 1
