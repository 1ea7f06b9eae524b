"""``harness compare A B``: two renderers' replica renders compared without a reference.

A and B are folders of replica images (EXR, PFM or HDR, one independent render each, read
with OpenImageIO in file-name order) or, with ``db``, two render cases of a stored run (named
by their configuration or "scene/configuration", else by a case-key prefix or a part of
"scene/configuration" that only one case has; their bias-test renders are used).
The verdict is harness.stats.compare's two-sample test; the page shows each set's mean, the
relMSE and NVIDIA FLIP error maps of each mean against the other's (relMSE on one shared
scale), the |t| map at the most significant scale, the histogram of the finest scale's
p-values and every figure with its sample count.
"""
from __future__ import annotations

import datetime as _dt
import html
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from harness.adapters.base import read_image
from harness.stats.compare import ImageComparison
from harness.suite.readers import connect_read_only
from harness.suite.store import image_dir, read_stored, same_unit
from reports import images, plots

__all__ = ["ReplicaSet", "compare_page", "load_pair", "load_replicas"]

_IMAGE_SUFFIXES = (".exr", ".pfm", ".hdr")
e = html.escape


@dataclass(frozen=True)
class ReplicaSet:
    """Replica renders (R, h, w, c) float64 and where they came from."""

    label: str
    images: np.ndarray
    source: str


def load_replicas(source: str, *, db: str | Path | None = None) -> ReplicaSet:
    """The replica set ``source`` names (see the module docstring); ValueError naming the
    folder, file or case when it cannot be read."""
    if db is not None:
        return _from_db(source, Path(db))
    folder = Path(source)
    if not folder.is_dir():
        raise ValueError(f"{source}: not a folder of replica images (or give --db to name a render case)")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES)
    if not files:
        raise ValueError(f"{source}: no {', '.join(_IMAGE_SUFFIXES)} images in it")
    stack = []
    for f in files:
        try:
            a = read_image(f).astype(np.float64)
        except OSError as err:
            raise ValueError(str(err)) from None
        if stack and a.shape != stack[0].shape:
            raise ValueError(f"{f}: shape {a.shape}, but {files[0].name} has {stack[0].shape}: replicas of "
                             "one configuration must have one size")
        stack.append(a)
    return ReplicaSet(folder.name, np.stack(stack), str(folder))


def load_pair(a: str, b: str, *, db: str | Path | None = None) -> tuple[ReplicaSet, ReplicaSet]:
    """The two replica sets ``a`` and ``b`` name (:func:`load_replicas`); a ValueError where
    both name one set (one folder, or one render case): its replicas compared with themselves
    had read "consistent, p = 1", a verdict about nothing."""
    if db is None and Path(a).resolve() == Path(b).resolve():    # before reading either
        raise ValueError(f"{a!r} and {b!r} name one replica set ({a}): compare takes two, one for each "
                         "renderer or configuration")
    first, second = load_replicas(a, db=db), load_replicas(b, db=db)
    if first.source == second.source:
        raise ValueError(f"{a!r} and {b!r} name one replica set ({first.source}): compare takes two, "
                         "one for each renderer or configuration")
    return first, second


def _from_db(name: str, db: Path) -> ReplicaSet:
    if not db.is_file():
        raise ValueError(f"no results database at {db}")
    con = connect_read_only(db)
    try:
        rendered = {k for (k,) in con.execute("SELECT DISTINCT case_key FROM units WHERE kind = 'render'")}
        cases = [c for c in con.execute("SELECT case_key, integrand, technique FROM cases")
                 if c[0] in rendered]
        exact = [c for c in cases if name in (c[2], f"{c[1]}/{c[2]}")]
        renders = exact or [c for c in cases if c[0].startswith(name) or name in f"{c[1]}/{c[2]}"]
        if len(renders) != 1:
            known = "; ".join(f"{k[:8]} {i}/{t}" for k, i, t in cases)
            what = "no render case matches" if not renders else f"{len(renders)} render cases match"
            raise ValueError(f"{name!r}: {what} in {db} (its configuration, a key prefix or part of "
                             f"scene/configuration); its render cases: {known or 'none'}")
        key, scene, config = renders[0]
        # only the renders the latest run planned (its spp, its replicas)
        latest = ("" if "planned" not in {t for (t,) in con.execute("SELECT name FROM sqlite_master")} else
                  f" AND EXISTS (SELECT 1 FROM planned p WHERE {same_unit('p', 'u')})")
        rows = con.execute("SELECT replica, payload FROM units u WHERE case_key = ? AND kind = 'render' AND "
                           "stream = 0" + latest + " ORDER BY replica", (key,)).fetchall()
        files = {}
        for replica, payload in rows:
            image = json.loads(payload)["image"]
            row = con.execute("SELECT file FROM images WHERE name = ?", (image,)).fetchone()
            if row is None:
                raise ValueError(f"{db}: the image {image!r} of {scene}/{config} is not stored")
            files[replica] = image_dir(db) / row[0]
    finally:
        con.close()
    if not files:
        raise ValueError(f"{scene}/{config} in {db} has no bias-test renders (measurements without 'bias')")
    try:
        stack = np.stack([read_stored(files[r]).astype(np.float64) for r in sorted(files)])
    except OSError as err:
        raise ValueError(str(err)) from None
    return ReplicaSet(f"{scene}/{config}", stack, f"{db} case {key}")


def _flip(reference: np.ndarray, test: np.ndarray) -> tuple[np.ndarray, float] | None:
    """NVIDIA FLIP (HDR) of ``test`` against ``reference``: the magma error map (uint8) and
    the mean error; None where flip-evaluator is not installed."""
    try:
        import flip_evaluator
    except ImportError:
        return None
    rgb = [np.ascontiguousarray(np.repeat(v, 3, axis=2) if v.shape[2] == 1 else v[:, :, :3], dtype=np.float32)
           for v in (np.maximum(reference, 0), np.maximum(test, 0))]
    error_map, mean, _ = flip_evaluator.evaluate(rgb[0], rgb[1], "HDR")
    return (np.clip(np.asarray(error_map) * 255, 0, 255).round().astype(np.uint8), float(mean))


def _figure(png: bytes, caption: str) -> str:
    return (f'<figure><img src="{images.data_uri(png)}" alt="{e(caption)}"><figcaption>{e(caption)}'
            "</figcaption></figure>")


def compare_page(a: ReplicaSet, b: ReplicaSet, result: ImageComparison) -> str:
    """The comparison as one self-contained HTML page (images embedded)."""
    ma, mb = a.images.mean(axis=0), b.images.mean(axis=0)
    top = images.scale_top([images.relmse_map(mb, ma), images.relmse_map(ma, mb)])
    figs = [_figure(images.png_bytes(images.tonemap(m)),
                    f"mean of {x}: {s.label} ({s.images.shape[0]} replicas)")
            for m, x, s in ((ma, "A", a), (mb, "B", b))]
    for (x, y, name) in ((ma, mb, "A against mean B"), (mb, ma, "B against mean A")):
        emap = images.error_map(y, x, vmax=top)
        figs.append(_figure(images.png_bytes(emap.rgb), f"relMSE of {name}: {emap.mean:.3g} ± "
                                                        f"{emap.stderr:.2g} (log scale {emap.vmin:.0e} to "
                                                        f"{emap.vmax:.0e})"))
        flip = _flip(y, x)
        if flip is not None:
            figs.append(_figure(images.png_bytes(flip[0]), f"FLIP (HDR) of {name}: mean {flip[1]:.4f}"))
    worst = result.worst_scale
    t_rgb, t_top = images.t_map_rgb(result.t_map)
    figs.append(_figure(images.png_bytes(t_rgb), f"|t| at the most significant scale, {worst.name} (0 to "
                                                 f"{t_top:.3g}; worst {result.worst_t:+.2f} at "
                                                 f"{result.worst_pixel})"))
    finest = result.scales[0].name
    figs.append(_figure(plots.pvalue_histogram(result.pvalue_counts(), finest),
                        f"p-values of the {finest} test: flat under H0, a peak at 0 where the sets differ"))
    rows = "".join(f"<tr><td>{e(s.name)}</td><td class=num>{s.pvalue:.3g}</td>"
                   f"<td class=num>{s.alpha:.3g}</td><td class=num>{s.count}</td>"
                   f"<td class=num>{s.low_untested} / {s.high_untested}</td></tr>"
                   for s in result.scales)
    when = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    cls = "good" if result.passed else "bad"
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>harness compare: {e(a.label)} vs {e(b.label)}</title>
<style>body{{font:14px/1.45 system-ui,sans-serif;margin:20px 28px;color:#1f2328}}
.v{{padding:10px 14px;border-radius:6px;margin:12px 0}}.good{{background:#dafbe1}}.bad{{background:#ffebe9}}
table{{border-collapse:collapse;font-size:13px}}td,th{{padding:4px 10px;border-bottom:1px solid #d8dee4;
text-align:left}}.num{{text-align:right}}.grid{{display:grid;grid-template-columns:repeat(4,minmax(0,1fr));
gap:16px;max-width:1400px}}img{{width:100%;image-rendering:pixelated;border:1px solid #d8dee4}}
figcaption{{font-size:12.5px;color:#656d76}}</style></head><body>
<h1>Two renderers compared without a reference</h1>
<p>A: {e(a.label)} <small>({e(a.source)})</small><br>B: {e(b.label)} <small>({e(b.source)})</small></p>
<div class="v {cls}">{e(str(result))}</div>
<p>H0: both sets estimate the same image. Welch t per tile-channel at {len(result.scales)} scales, each at
α/{len(result.scales)} with Bonferroni over its tile-channels, α = {result.alpha:g}; a side (A darker / A
brighter) is untested where either set is skewed there. Image-mean difference A − B =
{result.difference:+.3g} ± {result.difference_se:.2g}.</p>
<table><tr><th>scale</th><th>p</th><th>level</th><th>tile-channels</th>
<th>untested darker / brighter</th></tr>
{rows}</table>
<div class="grid">{"".join(figs)}</div>
<p><small>Written by <code>harness compare</code> on {when}.</small></p></body></html>
"""
