"""Results -> one self-contained HTML page: inline CSS, a few lines of inline JavaScript (a
table filter and an image wipe), every figure an embedded PNG.  Nothing is fetched from the
network, so the file can be mailed, archived or opened offline.
"""
from __future__ import annotations

import datetime as _dt
import html
import math
import re
import struct
from typing import Any

from reports import images, plots, pool, tables
from reports.data import SAMPLER_PREFIX, Results

__all__ = ["render_html"]

e = html.escape


def _img(png: bytes, alt: str, cls: str = "plot") -> str:
    w, h = struct.unpack(">II", png[16:24])  # PNG IHDR: width, height
    return f'<img class="{cls}" src="{images.data_uri(png)}" width="{w}" height="{h}" alt="{e(alt)}">'


def _badge(verdict: str) -> str:
    return f'<span class="badge {tables.verdict_class(verdict)}">{e(verdict)}</span>' if verdict else ""


def _table(rows: list[dict[str, Any]], columns: list[tables.Column], *, table_id: str = "",
           table_cls: str = "", group: str | None = None, sticky: int = 0) -> str:
    """A table of formatted cells; the first ``sticky`` (<= 2) columns stay put when it scrolls sideways."""
    head = "".join(f'<th title="{e(c.title)}" '
                   f'class="{" ".join(([f"c{i}"] if i < sticky else []) + (["num"] if c.numeric else []))}">'
                   f'{e(c.header)}</th>' for i, c in enumerate(columns))
    body, last = [], None
    for row, cells in zip(rows, tables.render_rows(rows, columns)):
        bad = any(tables.verdict_class(c.verdict) == "bad" for c in cells if c.verdict)
        classes = (["has-bad"] if bad else []) + (["group"] if group and row.get(group) != last else [])
        last = row.get(group) if group else None
        tds = []
        for i, (c, cell) in enumerate(zip(columns, cells)):
            note = f'<div class="note">{_note(cell.note)}</div>' if cell.note else ""
            cls = " ".join(([f"c{i}"] if i < sticky else []) + (["num"] if c.numeric else []))
            text = _badge(cell.verdict) if cell.verdict else e(cell.text)
            if i < sticky:   # long technique names may break after : / + , only
                text = re.sub(r"([:/+,])", r"\1<wbr>", text)
            tip = f' title="{e(cell.text)}"' if i == 0 and sticky else ""
            tds.append(f'<td class="{cls}"{tip}>{text}{note}</td>')
        body.append(f'<tr class="{" ".join(classes)}">{"".join(tds)}</tr>')
    ident = (f' id="{table_id}"' if table_id else "") + (f' class="{table_cls}"' if table_cls else "")
    return (f'<div class="scroll"><table{ident}><thead><tr>{head}</tr></thead>'
            f'<tbody>{"".join(body)}</tbody></table></div>')


_NOUNS = {"estimator": ("estimator case", "estimator cases"), "sampler": ("sampler check", "sampler checks"),
          "render": ("render configuration", "render configurations")}


def _holdings(results: Results) -> str:
    """What the database holds, by kind: "3 estimator cases, 2 sampler checks"."""
    m = results.measurements
    parts = []
    for kind, (one, many) in _NOUNS.items():
        n = m.loc[m["kind"] == kind, "case_key"].nunique()
        if n:
            parts.append(f"{n} {one if n == 1 else many}")
    return ", ".join(parts)


def _note(text: str) -> str:
    """A cell's second line: its pieces ("[lo, hi]", "n = 1,024", ...) never break inside, so
    narrow columns wrap between them; a baseline's long name ("vs ...") may break."""
    pieces = re.split(r", (?![^\[]*\])", text)   # commas outside brackets
    return ", ".join(e(p) if p.startswith("vs ") else f'<span class="nw">{e(p)}</span>' for p in pieces)


def _counts(results: Results) -> tuple[list[str], list[str]]:
    """Descriptions of what a CI run fails on (failing verdicts; cases with an xfail reason
    that no longer fail: strict), and of the known findings (xfailed cases, with their reason)."""
    m = results.measurements

    def name(r) -> str:
        return f"{r.integrand.removeprefix(SAMPLER_PREFIX)} / {r.technique}"

    failing = m["verdict"].isin(tables.BAD)
    problems = [f"{name(r)}: {r.measurement} {r.verdict}"
                + (f" (p = {tables.fmt_p(r.pvalue)})" if r.pvalue == r.pvalue and r.pvalue is not None
                   else "")
                for r in m[failing & (m["xfail"] == "")].itertuples()]
    known = []
    for _, g in m[m["xfail"] != ""].groupby("case_key", sort=False):
        r = next(g.itertuples())
        if (g["verdict"].isin(tables.FAILING)).any():
            known.append(f"{name(r)}: {r.xfail}")
        else:
            problems.append(f"{name(r)}: [XPASS(strict)] expected to fail ({r.xfail}) but passed")
    return problems, known


def _summary_section(results: Results) -> str:
    parts = ['<section id="summary"><h2>Summary</h2>'
             '<p class="lead">One row per case: each figure with its 95&nbsp;% interval and sample count n; '
             'verdicts are Holm-corrected across the suite at its family-wise α. Hover a column header for '
             'its definition. The CSV output (<code>harness report --format csv</code>) has every stored '
             'number.</p>'
             '<div class="controls"><input id="filter" type="search" '
             'placeholder="filter rows, e.g. gaussian or sobol" '
             'aria-label="filter rows"> <label><input id="only-bad" type="checkbox"> only failures</label> '
             '<span id="shown" class="muted"></span></div>']
    found = False
    for kind, title in (("estimator", "Estimators"),
                        ("render", "Renderer configurations")):
        wide = tables.wide_table(results.of_kind(kind))
        if wide.empty:
            continue
        found = True
        noun = _NOUNS[kind][0] if len(wide) == 1 else _NOUNS[kind][1]
        alphas = ", ".join(f"{a:g}" for a in sorted(set(wide["alpha"].dropna()))) if "alpha" in wide else ""
        parts.append(f"<h3>{title} ({len(wide)} {noun}" + (f"; Holm at α = {alphas}" if alphas else "")
                     + ")</h3>")
        parts.append(_table(wide.to_dict("records"), tables.summary_columns(wide), table_cls="summary-table",
                            group="integrand", sticky=2))
    if not found:
        parts.append("<p>No cases stored.</p>")
    return "".join(parts) + "</section>"


def _convergence_section(figs: dict[tuple[str, str], plots.Group], pngs: list[bytes]) -> str:
    """Per integrand (suite, name): its figure, drawn from ``figs`` into ``pngs`` (same order)."""
    if not figs:
        return ""
    suites = {s for s, _ in figs}
    parts = ['<section id="convergence"><h2>Convergence, error against time, efficiency</h2><p '
             'class="lead">Per integrand: left, the error of each technique at geometric budgets (points '
             'with 95&nbsp;% intervals over replicas) and its fitted log-log slope with a permutation-test '
             '95&nbsp;% interval (legend); the dashed grey line shows the expected Monte Carlo rate. '
             'Middle, the same errors against the measured wall time per estimate. Right, the efficiency '
             '1/(V·T) as a ratio against the baseline technique with its 95&nbsp;% interval (the replicas '
             'ran interleaved, so the machine&#8217;s state cancels). The table&#8217;s log10 '
             '1/(V·T<sub>clock</sub>) is each technique&#8217;s own efficiency with T in ticks of a '
             'reference clock timed beside each replica: its interval holds across runs; the figure in 1/s '
             '(CSV only) has an interval of one run&#8217;s machine state.</p>']
    nav = " · ".join(f'<a href="#int-{e(s)}-{e(i)}">{e(i)}</a>' for s, i in figs)
    parts.append(f'<p class="toc">{nav}</p>')
    for ((suite, integrand), group), png in zip(figs.items(), pngs):
        title = integrand + (f" ({suite})" if len(suites) > 1 else "")
        common = f' <span class="muted">all with {e(group.common)}</span>' if group.common else ""
        parts.append(f'<figure class="wide" id="int-{e(suite)}-{e(integrand)}"><figcaption>'
                     f'<h3>{e(title)}{common}</h3>'
                     f'</figcaption>{_img(png, f"convergence of {integrand}")}'
                     "</figure>")
    parts.append("</section>")
    return "".join(parts)


def _sampler_jobs(rows: list[dict[str, Any]]) -> list[tuple[Any, tuple]]:
    return [(plots.sampler_figure, (str(r["technique"]), r["detail"], int(r["n"] or 0))) for r in rows
            if r["measurement"] == "chi_square"]


def _sampler_section(rows: list[dict[str, Any]], pngs: list[bytes | None]) -> str:
    """Sampler-check rows and the figures of their chi-square rows (``_sampler_jobs`` order)."""
    if not rows:
        return ""
    figures = iter(pngs)
    parts = ['<section id="samplers"><h2>Sampler checks</h2>'
             '<p class="lead">Each sampler against its claimed pdf: deterministic checks, then chi-square at '
             'two resolutions on equal-measure cells (expected counts by adaptive cubature), 1-D marginals '
             'and a pdf-moment test, combined by Holm. Heatmaps show the standardised residual '
             '(observed − expected)/σ per cell: noise looks like salt and pepper; a wrong sampler shows '
             'structure.</p>',
             _table(rows, tables.sampler_columns(), table_id="sampler-table")]
    for r in rows:
        label = r["integrand"].removeprefix(SAMPLER_PREFIX)
        head = (f'<h3>{e(label)} <span class="muted">on the {e(r["technique"])}, '
                f'{e(r["measurement"])}</span> {_badge(str(r["verdict"] or ""))}</h3>')
        fig = next(figures) if r["measurement"] == "chi_square" else None
        if fig is not None:
            body = _img(fig, f"chi-square residuals of {label}")
        elif r["measurement"] == "chi_square":
            body = ('<p class="muted">No residuals stored for this check (stored by an older version); '
                    'delete its unit from the database and rerun the suite to draw them.</p>')
        else:
            body = ""
        tests = r["detail"].get("tests", [])
        rows_t = "".join(f'<tr><td>{e(str(t.get("test")))}</td><td class="num">'
                         f'{tables.fmt_num(t.get("statistic"), ".4g")}'
                         f'</td><td class="num">{tables.fmt_num(t.get("df"), "g")}</td><td class="num">'
                         f'{tables.fmt_p(t.get("pvalue"))}</td><td class="num">'
                         f'{tables.fmt_p(t.get("adjusted"))}</td>'
                         f'<td>{e(str(t.get("detects", "")))}</td></tr>' for t in tests)
        fails = "".join(f'<li>{e(f["check"])}: {f["count"]} ({e(str(f.get("detail", "")))}); examples: '
                        f'{e(str(f.get("examples", []))[:300])}</li>'
                        for f in r["detail"].get("failures", []))
        detail = (f'<details><summary>sub-tests ({len(tests)})</summary><div class="scroll">'
                  '<table class="small">'
                  '<thead><tr><th>test</th><th class="num">statistic</th><th class="num">df</th>'
                  '<th class="num">p</th>'
                  f'<th class="num">Holm-adjusted p</th><th>detects</th></tr></thead>'
                  f'<tbody>{rows_t}</tbody></table>'
                  f'</div>{f"<ul class=fail>{fails}</ul>" if fails else ""}</details>')
        parts.append(f'<figure class="wide sampler">{head}{body}{detail}</figure>')
    parts.append("</section>")
    return "".join(parts)


def _chip(r: dict[str, Any]) -> str:
    """One stored measurement as a compact label: name, value [95% CI], n, p, verdict."""
    v = tables.value_of
    extra = ", ".join(([f"n = {tables.fmt_n(v(r, 'n'))}"] if v(r, "n") is not None else [])
                      + ([tables.p_equals(v(r, "pvalue"))] if v(r, "pvalue") is not None else []))
    return (f'<span class="chip"><b>{e(str(r["measurement"]))}</b> '
            f'{e(tables.fmt_interval(v(r, "value"), v(r, "lo"), v(r, "hi")))}'
            f'{f" <span class=muted>({e(extra)})</span>" if extra else ""} '
            f'{_badge(str(v(r, "verdict") or ""))}</span>')


def _bias_figures(results: Results, key: str, rows: list[dict[str, Any]], integrand: str, pix: str) -> str:
    """The bias test's |t| map at the scale that rejected (or came closest) and the histogram of
    its finest scale's p-values, where the case has a stored bias test."""
    bias = next((r for r in rows if r["measurement"] == "bias"), None)
    if bias is None or key not in results.t_maps:
        return ""
    detail = bias["detail"]
    rgb, top = images.t_map_rgb(results.image(results.t_maps[key])[:, :, 0])
    scale = detail.get("worst_scale", "")
    finest = (detail.get("scales") or [{}])[0].get("scale", "")
    out = (f'<figure>{_img(images.png_bytes(rgb), f"bias |t| map of {integrand}", cls="render-img" + pix)}'
           f'<figcaption>bias test |t| at {e(scale)} (the most significant scale; 0 to {top:.3g}, black: '
           f'untested)</figcaption></figure>')
    counts = detail.get("pvalue_counts")
    if counts:
        out += (f'<figure>{_img(plots.pvalue_histogram(counts, finest), f"p-values of {integrand}")}'
                f'<figcaption>p-values of the {e(finest)} test: flat under H0, a peak at 0 where a bias is '
                'spread over many tiles</figcaption></figure>')
    return out


def _render_section(results: Results) -> str:
    if not results.image_pairs:
        return ""
    bar = _img(images.colorbar_png(), "colour scale of the error map", cls="colorbar")
    parts = ['<section id="renders"><h2>Renders</h2>'
             '<p class="lead">Reference and estimate, tone-mapped identically (linear radiance clamped to '
             '[0, 1], sRGB curve), and the per-pixel relative squared error (est − ref)² / (ref² + 0.01), '
             'averaged over RGB, in false colour on a log scale shared by every configuration of a scene. '
             'Drag the slider over the comparison to wipe between reference (left) and estimate (right); '
             'magenta marks NaN or infinite pixels.</p>']
    m = results.cases
    pairs = {}
    for key, (ref_name, est_name) in results.image_pairs.items():
        rows = m[m["case_key"] == key].to_dict("records")
        integrand, technique = ((rows[0]["integrand"], rows[0]["technique"]) if rows else
                                results.labels.get(key, (key, "")))
        pairs[key] = (rows, integrand, technique, results.image(ref_name), results.image(est_name))
    # one colour scale per scene: its configurations compare by colour
    tops = {scene: images.scale_top([images.relmse_map(ref, est) for _, sc, _, ref, est in pairs.values()
                                     if sc == scene]) for scene in {p[1] for p in pairs.values()}}
    for key, (rows, integrand, technique, ref, est) in pairs.items():
        h, w = ref.shape[:2]
        emap = images.error_map(ref, est, vmax=tops[integrand])
        ref_png, est_png = images.png_bytes(images.tonemap(ref)), images.png_bytes(images.tonemap(est))
        pix = " pixelated" if w < 400 else ""
        stats = ("".join(_chip(r) for r in rows if r["measurement"] not in tables.HIDDEN)
                 or "no measurements stored")
        ticks = "".join(f"<span>1e{k}</span>" for k in range(round(math.log10(emap.vmin)),
                                                             round(math.log10(emap.vmax)) + 1))
        caption = (f"relMSE map: mean over {emap.pixels:,} pixels = {tables.fmt_num(emap.mean)} ± "
                   f"{tables.fmt_num(emap.stderr, '.2g')} (s.e.)"
                   + (f"; {emap.nonfinite:,} non-finite pixel{'s' * (emap.nonfinite != 1)}" if emap.nonfinite
                      else ""))
        parts.append(
            f'<article class="render" id="render-{e(key)}"><h3>{e(integrand)} '
            f'<span class="muted">{e(technique)}</span></h3>'
            f'<p class="stats">{stats}<span class="chip">{w}×{h} pixels</span></p><div class="triple">'
            f'<figure>{_img(ref_png, f"reference of {integrand}", cls="render-img" + pix)}'
            f'<figcaption>reference</figcaption></figure>'
            f'<figure>{_img(est_png, f"estimate of {integrand}", cls="render-img" + pix)}'
            f'<figcaption>estimate ({e(technique)})'
            f'</figcaption></figure><figure>'
            f'{_img(images.png_bytes(emap.rgb), f"relMSE map of {integrand}", cls="render-img" + pix)}'
            f'<div class="scale">{bar}<div class="ticks">{ticks}</div></div>'
            f'<figcaption>{e(caption)}</figcaption></figure>'
            f'<figure><div class="compare" style="aspect-ratio: {w} / {h}">'
            f'{_img(est_png, "estimate (wipe)", cls="under" + pix)}'
            f'{_img(ref_png, "reference (wipe)", cls="top" + pix)}'
            f'<div class="line"></div><span class="tag left">reference</span>'
            f'<span class="tag right">estimate</span></div>'
            f'<div class="wipe"><input type="range" min="0" max="100" value="50" '
            f'aria-label="wipe between reference and estimate"> <button type="button" class="flip" '
            f'title="show all reference / all estimate">flip</button></div>'
            f'<figcaption>compare: drag to wipe between reference and estimate</figcaption>'
            f'</figure>{_bias_figures(results, key, rows, integrand, pix)}</div></article>')
    parts.append("</section>")
    return "".join(parts)


def _alpha_text(results: Results, alphas: list[float]) -> str:
    """What the verdicts are held at: each shown run's false-alarm rate and its split over
    families where the run recorded them, else the stored rows' alphas."""
    told = [r for r in results.runs if r["alpha"] is not None and r["families"]]
    if not told:
        return f"family-wise α = {', '.join(f'{a:g}' for a in alphas) or '—'} (Holm)"
    return "; ".join(
        f"{r['suite']}: α = {r['alpha']:g} for the whole run"
        + (f", {r['alpha'] / len(r['families']):.3g} for each of {len(r['families'])} families "
           f"({', '.join(r['families'])}), Holm within each" if len(r["families"]) > 1 else " (Holm)")
        for r in told)


def render_html(results: Results) -> str:
    """The report page for ``results`` (see the module docstring)."""
    problems, known = _counts(results)
    holds = _holdings(results)
    suites = sorted(set(results.measurements["suite"]))
    alphas = sorted(set(results.measurements["alpha"].dropna()))
    when = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    if problems:
        status = (f'<div class="status bad"><strong>{len(problems)} result{"s" * (len(problems) != 1)} '
                  'a CI run fails on:</strong><ul>'
                  + "".join(f"<li>{e(p)}</li>" for p in problems) + "</ul></div>")
    elif holds:
        status = (f'<div class="status good"><strong>No failures:</strong> {e(holds)} came out as expected '
                  f'(or inconclusive where the variance is unreliable).</div>')
    else:
        status = '<div class="status neutral">No measurements stored in this database.</div>'
    if known:
        status += (f'<div class="status neutral"><strong>{len(known)} known finding{"s" * (len(known) != 1)} '
                   '(xfail: failing as recorded, a run passes on them):</strong><ul>'
                   + "".join(f"<li>{e(k)}</li>" for k in known) + "</ul></div>")
    groups = plots.integrand_curves(results)
    sampler_rows = results.samplers.to_dict("records")
    jobs = [(plots.integrand_figure, (g,)) for g in groups.values()] + _sampler_jobs(sampler_rows)
    pngs = pool.draw_all(jobs)
    sections = [_summary_section(results), _convergence_section(groups, pngs[:len(groups)]),
                _sampler_section(sampler_rows, pngs[len(groups):]), _render_section(results)]
    nav = "".join(f'<a href="#{i}">{t}</a>' for i, t, s in
                  (("summary", "Summary", sections[0]),
                   ("convergence", "Convergence & efficiency", sections[1]),
                   ("samplers", "Sampler checks", sections[2]), ("renders", "Renders", sections[3])) if s)
    stale = (f"; {results.superseded} superseded case{'s' * (results.superseded != 1)} from earlier runs "
             "not shown"
             if results.superseded else "")
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">\
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>mc-harness report: {e(", ".join(suites) or results.db.name)}</title>
<style>{_CSS}</style></head>
<body><header><h1>Monte Carlo comparison report <span class="muted">{e(", ".join(suites))}</span></h1>
<p class="meta">{e(str(results.db))} · {e(holds or "nothing stored")}
 · {e(_alpha_text(results, alphas))} · generated {when}{e(stale)}</p>
<nav>{nav}</nav></header><main>{status}{"".join(sections)}</main>
<footer>Written by <code>harness report</code> from the stored measurements; \
nothing here is recomputed from samples.
</footer><script>{_JS}</script></body></html>
"""


_CSS = """
:root{--fg:#1f2328;--muted:#656d76;--line:#d8dee4;--bg:#fff;--soft:#f6f8fa;--good:#1a7f37;--good-bg:#dafbe1;
--bad:#cf222e;--bad-bg:#ffebe9;--neutral:#7d5a00;--neutral-bg:#fff8c5;--accent:#0969da}
*{box-sizing:border-box}
body{margin:0;font:14px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,"DejaVu Sans",sans-serif;\
color:var(--fg);
background:var(--bg)}
header{padding:18px 28px 0;border-bottom:1px solid var(--line);background:var(--soft)}
h1{font-size:20px;margin:0 0 4px}\
h2{font-size:18px;margin:32px 0 6px;padding-top:8px;border-top:1px solid var(--line)}
h3{font-size:15px;margin:14px 0 6px}
.meta{margin:0 0 8px;color:var(--muted);font-size:12.5px;overflow-wrap:anywhere}
nav a{display:inline-block;padding:6px 12px 8px;color:var(--accent);text-decoration:none;\
border-bottom:2px solid transparent}
nav a:hover{border-bottom-color:var(--accent)}
main{padding:6px 28px 40px;max-width:1560px}
.lead{color:var(--muted);max-width:1100px;margin:4px 0 10px}.muted{color:var(--muted);font-weight:normal}
.status{margin:16px 0;padding:10px 14px;border-radius:6px;border:1px solid}
.status ul{margin:6px 0 0;padding-left:20px}
.status.good{background:var(--good-bg);border-color:#aceebb}.status.bad{background:var(--bad-bg);border-color:#ffcecb}
.status.neutral{background:var(--neutral-bg);border-color:#f2e19b}
.controls{margin:6px 0 8px;display:flex;gap:14px;align-items:center}
.controls input[type=search]{padding:5px 8px;border:1px solid var(--line);border-radius:6px;\
width:320px;font:inherit}
.scroll{overflow:auto;max-width:100%;border:1px solid var(--line);border-radius:6px}
#summary .scroll{max-height:75vh;margin-bottom:10px}
table{border-collapse:collapse;font-size:12.5px;width:100%}
th{position:sticky;top:0;background:var(--soft);text-align:left;font-weight:600;\
padding:6px 8px;border-bottom:1px solid var(--line);
white-space:nowrap;cursor:help;z-index:1}
td{padding:4px 8px;border-bottom:1px solid #eef1f4;vertical-align:top;white-space:nowrap;background:var(--bg)}
.c0,.c1{position:sticky;z-index:2}th.c0,th.c1{z-index:3}
.c0{left:0;width:122px;min-width:122px;max-width:122px;overflow:hidden;text-overflow:ellipsis}
.c1{left:122px;box-shadow:inset -1px 0 0 var(--line);white-space:normal;min-width:150px;max-width:230px}
.summary-table td:last-child{white-space:normal;min-width:180px;max-width:320px;\
color:var(--muted);font-size:12px}
tr.group td{border-top:1px solid #c9d1d9}tbody tr:hover td{background:#f3f8ff}
.num{text-align:right;font-variant-numeric:tabular-nums}
.note{color:var(--muted);font-size:11px;white-space:normal}.nw{white-space:nowrap}
table.small{font-size:12px}
.badge{display:inline-block;padding:1px 8px;border-radius:10px;font-size:11.5px;font-weight:600;\
white-space:nowrap}
.badge.good{color:var(--good);background:var(--good-bg)}.badge.bad{color:var(--bad);background:var(--bad-bg)}
.badge.neutral{color:var(--neutral);background:var(--neutral-bg)}
.toc{font-size:13px}.toc a{color:var(--accent);text-decoration:none}
figure{margin:0}figure.wide{margin:10px 0 22px}
img.plot{max-width:100%;height:auto;display:block;border:1px solid #eef1f4;border-radius:4px}
figure.sampler details{margin:6px 0 0}\
figure.sampler summary{cursor:pointer;color:var(--accent);font-size:13px}
ul.fail{color:var(--bad);font-size:12.5px}
.render{margin:14px 0 28px;padding:4px 0 10px;border-bottom:1px solid #eef1f4}\
.stats{margin:0 0 8px;font-size:12.5px}
.chip{display:inline-block;margin:0 14px 4px 0;white-space:nowrap}
.triple{display:grid;grid-template-columns:repeat(4,minmax(0,1fr));gap:16px;max-width:1480px;align-items:start}
.triple figcaption{font-size:12.5px;color:var(--muted);margin-top:4px}
img.render-img{width:100%;height:auto;display:block;border:1px solid var(--line)}
.pixelated{image-rendering:pixelated}
.scale img.colorbar{width:100%;height:12px;display:block;margin-top:6px;border:1px solid var(--line)}
.scale .ticks{display:flex;justify-content:space-between;font-size:11px;color:var(--muted)}
.compare{position:relative;width:100%;border:1px solid var(--line);user-select:none;overflow:hidden}
.compare img{position:absolute;inset:0;width:100%;height:100%;display:block}
.compare .line{position:absolute;top:0;bottom:0;width:2px;margin-left:-1px;background:#fff;\
box-shadow:0 0 2px #000}
.compare .tag{position:absolute;top:6px;font-size:11px;padding:1px 6px;\
background:rgba(0,0,0,.55);color:#fff;border-radius:3px}
.compare .left{left:6px}.compare .right{right:6px}
.wipe{display:flex;gap:8px;align-items:center;margin-top:4px}.wipe input{flex:1;min-width:0}
.wipe button{font:inherit;font-size:12px;padding:2px 10px;border:1px solid var(--line);\
border-radius:6px;background:var(--soft);
cursor:pointer}
footer{padding:14px 28px;color:var(--muted);font-size:12px;border-top:1px solid var(--line)}
code{font-size:12.5px;background:var(--soft);padding:1px 4px;border-radius:4px}
"""

_JS = """
(function(){
  var q=document.getElementById('filter'),bad=document.getElementById('only-bad'),\
shown=document.getElementById('shown');
  var rows=[].slice.call(document.querySelectorAll('.summary-table tbody tr'));
  function apply(){
    var s=q?q.value.toLowerCase():'',n=0;
    rows.forEach(function(tr){var ok=tr.textContent.toLowerCase().indexOf(s)>=0&&\
(!bad.checked||tr.classList.contains('has-bad'));
      tr.hidden=!ok;if(ok)n++;});
    if(shown)shown.textContent=n+' of '+rows.length+' rows';
  }
  if(q){q.addEventListener('input',apply);bad.addEventListener('change',apply);apply();}
  [].forEach.call(document.querySelectorAll('.render'),function(a){
    var r=a.querySelector('.wipe input'),top=a.querySelector('.compare .top'),\
line=a.querySelector('.compare .line');
    function set(){top.style.clipPath='inset(0 '+(100-r.value)+'% 0 0)';line.style.left=r.value+'%';}
    r.addEventListener('input',set);
    a.querySelector('.flip').addEventListener('click',function(){r.value=r.value>50?0:100;set();});
    set();
  });
})();
"""
