"""Render cases of a suite: plan the renders their measurements need, render the missing
ones, and measure bias, variance, convergence, efficiency and error against time from the
stored images.

Each render is one work unit (kind "render"): its image goes to the store's EXR folder and
its row records the image's name, wall time and invalid pixels, so a killed run re-renders
nothing it stored.  Renders run one at a time in this process: Mitsuba and OpenGL use every
core themselves, and their contexts do not travel to Dask workers.

A scene with an exact answer (``Renderer.exact``) renders no reference.  Otherwise the
reference is ``reference_parts`` independent renders by ``Renderer.reference()`` with
``reference_spp`` samples in total, stored as units like any other and then cached as EXR
(mean and variance of the mean) plus JSON in ``references/`` beside the database, keyed by a
hash of the reference renderer's fingerprint (scene, variant, integrator settings,
library versions), budget and seed; every case and run that needs the same reference reuses it.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from harness.stats import images as ist
from harness import stats
from harness.adapters import ImageFaults, Renderer, image_faults, renderer
from harness.suite.plan import Unit
from harness.suite.store import Store, read_exr, write_exr
from harness.suite.parse import RenderCase, Suite

__all__ = ["RenderResult", "run_renders", "render_key", "judge_renders", "judge_render_convergence",
           "render_failures", "render_rows", "render_table", "format_render_table", "equal_time_relmse",
           "ReferenceCache"]

_FORMAT = 1            # bump when a render unit's meaning changes
_KIND = "render"


@dataclass(frozen=True)
class RenderResult:
    case: RenderCase
    key: str
    reference: str                         # "exact" or the reference's cache key
    faults: ImageFaults                    # over every render of the case
    bias: ist.ImageBias | None
    variance: tuple[float, float, int] | None
    convergence: stats.ConvergenceResult | None
    efficiency: stats.Efficiency | None
    errors: pd.DataFrame | None            # per budget: spp, seconds, relmse, relmse_se, replicas
    reference_noise: float = 0.0           # the reference's own relMSE (subtracted from every relMSE)
    notes: list[str] = field(default_factory=list)


# --- keys and seeds ----------------------------------------------------------------------------
def _hash(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:24]


def render_key(suite: Suite, rc: RenderCase, r: Renderer) -> str:
    """Fingerprint of a render case's images: the renderer's fingerprint and the suite seed."""
    return _hash({"renderer": r.fingerprint(), "seed": suite.seed, "format": _FORMAT})


def reference_key(suite: Suite, rc: RenderCase, ref: Renderer) -> str:
    return _hash({"reference": ref.fingerprint(), "spp": rc.reference_spp, "parts": rc.reference_parts,
                  "seed": suite.seed, "format": _FORMAT})


def _seed(key: str, stream: int, replica: int) -> int:
    """A render's seed (31 bits): independent streams per case, stream and replica."""
    return int(hashlib.sha256(f"{key}/{stream}/{replica}".encode()).hexdigest()[:8], 16) & 0x7FFFFFFF


# --- planning ----------------------------------------------------------------------------------
def _case_units(rc: RenderCase, key: str) -> list[Unit]:
    wanted = set(rc.measurements)
    units: list[Unit] = []
    if wanted & {"bias", "variance"}:
        units += [Unit(key, 0, rc.spp, r, 0, 0, _KIND) for r in range(rc.replicas)]
    if wanted & {"convergence", "error_vs_time"}:
        chosen = list(enumerate(rc.budgets))
    elif "efficiency" in wanted:
        chosen = [(len(rc.budgets) - 1, rc.budgets[-1])]
    else:
        chosen = []
    for i, b in chosen:
        units += [Unit(key, 1 + i, b, r, 0, 0, _KIND) for r in range(rc.replicas)]
    return units


def _reference_units(rc: RenderCase, ref_key: str) -> list[Unit]:
    per = rc.reference_spp // rc.reference_parts
    return [Unit(ref_key, 0, per, k, 0, 0, _KIND) for k in range(rc.reference_parts)]


class ReferenceCache:
    """Rendered references as EXR (mean, variance of the mean) + JSON, keyed by hash."""

    def __init__(self, folder: Path):
        self.folder = folder

    def _paths(self, key: str) -> tuple[Path, Path, Path]:
        return self.folder / f"{key}-mean.exr", self.folder / f"{key}-variance.exr", self.folder / f"{key}.json"

    def load(self, key: str) -> ist.Reference | None:
        mean_p, var_p, meta_p = self._paths(key)
        if not meta_p.exists():  # written last: its presence means both images are complete
            return None
        meta = json.loads(meta_p.read_text())
        return ist.Reference(read_exr(mean_p).astype(np.float64), read_exr(var_p).astype(np.float64), int(meta["parts"]),
                             float(meta["image_mean_variance"]))

    def save(self, key: str, ref: ist.Reference, meta: dict[str, Any]) -> None:
        self.folder.mkdir(parents=True, exist_ok=True)
        mean_p, var_p, meta_p = self._paths(key)
        write_exr(mean_p, ref.mean)
        write_exr(var_p, ref.variance)
        tmp = meta_p.with_suffix(".json.partial")
        tmp.write_text(json.dumps({**meta, "parts": ref.parts, "image_mean_variance": ref.image_mean_variance},
                                  indent=1, sort_keys=True, default=str))
        os.replace(tmp, meta_p)


# --- running ------------------------------------------------------------------------------------
def _image_name(unit: Unit) -> str:
    return f"{unit.case_key}/render-s{unit.stream}-b{unit.budget}-r{unit.replica}"


def run_renders(suite: Suite, store: Store, *, progress: Callable[[int, int], None] | None = None,
                add_case: Callable[[str, RenderCase], None] | None = None) -> tuple[list[RenderResult], int, int]:
    """Renders what is missing for the suite's render cases and measures every case.
    Returns the results, the number of units planned and the number rendered."""
    if not suite.renders:
        return [], 0, 0
    cache = ReferenceCache(store.path.parent / "references")
    cases: list[tuple[RenderCase, str, Renderer, str | None, Renderer | None]] = []
    for rc in suite.renders:
        r = renderer(rc.adapter, dict(rc.spec))
        key = render_key(suite, rc, r)
        ref = r.reference() if r.exact() is None else None
        cases.append((rc, key, r, reference_key(suite, rc, ref) if ref is not None else None, ref))
        store.add_case(key, suite.name, rc.scene, rc.label, {"adapter": rc.adapter, "spec": dict(rc.spec),
                                                              "fingerprint": r.fingerprint()})

    units: dict[Unit, Renderer] = {}
    for rc, key, r, ref_key, ref in cases:
        for u in _case_units(rc, key):
            units[u] = r
        if ref_key is not None and ref is not None and cache.load(ref_key) is None:
            for u in _reference_units(rc, ref_key):
                units.setdefault(u, ref)
    stored = store.stored_keys({u.case_key for u in units})
    missing = [u for u in sorted(units) if u.key not in stored]
    done = len(units) - len(missing)
    for u in missing:
        out = units[u].render(u.budget, _seed(u.case_key, u.stream, u.replica))
        name = _image_name(u)
        store.put_image(name, out.image)
        store.put(u.key, {"image": name, "spp": out.spp, "faults": image_faults(out.image).to_dict()}, out.seconds)
        store.commit()
        done += 1
        if progress:
            progress(done, len(units))

    results = []
    for rc, key, r, ref_key, ref in cases:
        if ref_key is None:
            reference, noise_label = ist.Reference.exact(r.exact()), "exact"
        else:
            reference = cache.load(ref_key)
            if reference is None:
                reference = _build_reference(store, cache, rc, ref_key, ref)
            noise_label = ref_key
        results.append(_measure(rc, key, store, reference, noise_label))
    return results, len(units), len(missing)


def _build_reference(store: Store, cache: ReferenceCache, rc: RenderCase, ref_key: str, ref: Renderer) -> ist.Reference:
    payloads = store.payloads(ref_key)
    images = np.stack([store.image(p["image"]) for _, p in sorted(payloads.items())]).astype(np.float64)
    reference = ist.Reference.from_parts(images)
    cache.save(ref_key, reference, {"fingerprint": ref.fingerprint(), "spp": rc.reference_spp,
                                    "invalid_pixels": _faults(payloads).total,
                                    "seconds": float(sum(store.seconds(ref_key).values()))})
    return reference


def _stack(store: Store, payloads: dict[tuple, dict], seconds: dict[tuple, float],
           stream: int) -> tuple[np.ndarray, np.ndarray, int]:
    """The replica images of one stream (R, h, w, c), their wall times (R,) and their budget."""
    rows = sorted((k, p) for k, p in payloads.items() if k[1] == stream)
    images = np.stack([store.image(p["image"]) for _, p in rows]).astype(np.float64)
    return images, np.array([seconds[k] for k, _ in rows]), rows[0][0][2]


def _faults(payloads: dict[tuple, dict]) -> ImageFaults:
    total = ImageFaults()
    for k, p in sorted(payloads.items()):
        f = p["faults"]
        for kind in ("nan", "inf", "negative"):
            setattr(total, kind, getattr(total, kind) + f[kind])
            ex = total.examples.setdefault(kind, [])
            ex += [(int(k[3]), *pos) for pos in f["examples"].get(kind, [])][: max(0, 8 - len(ex))]
    total.examples = {k: v for k, v in total.examples.items() if v}
    return total


def _measure(rc: RenderCase, key: str, store: Store, reference: ist.Reference, ref_label: str) -> RenderResult:
    payloads, seconds_of = store.payloads(key), store.seconds(key)
    wanted = set(rc.measurements)
    faults = _faults(payloads)
    notes: list[str] = []
    bias = variance = convergence = eff = errors = None
    if wanted & {"bias", "variance"}:
        images, _, spp = _stack(store, payloads, seconds_of, 0)
        if "bias" in wanted:
            bias = ist.pixel_bias_test(images, reference, spp)
            if bias.untestable > bias.tested:
                notes.append(f"pixel test covers {bias.tested} of {bias.tested + bias.untestable} pixel-channels "
                             "(the rest too skewed at this spp; the image-mean test covers them)")
        if "variance" in wanted:
            variance = ist.pixel_variance(images, reference, spp)
        store.put_image(f"{key}/estimate", images.mean(axis=0))
    store.put_image(f"{key}/reference", reference.mean)
    chosen = sorted({k[1] for k in payloads} - {0})
    noise = reference.noise_relmse()
    reps, rows = [], []
    for stream in chosen:
        images, seconds, spp = _stack(store, payloads, seconds_of, stream)
        err = ist.relmse(images, reference)
        reps.append((spp, err, seconds))
        rows.append({"spp": spp, "seconds": float(np.median(seconds)), "relmse": float(err.mean()),
                     "relmse_se": float(err.std(ddof=1) / math.sqrt(err.size)), "replicas": int(err.size)})
    if reps and min(row["relmse"] for row in rows) <= 0:
        notes.append(f"relMSE at or below the reference's own ({noise:.2g}) at some budget: the reference is too "
                     "noisy to measure this configuration's error; render it with more samples")
        reps = []
    if reps:
        errors = pd.DataFrame(rows)
        spp, err, seconds = reps[-1]
        eff = ist.image_efficiency(rc.label, spp, err, seconds)
        if "convergence" in wanted and len(reps) >= 3:
            convergence = stats.fit_convergence([ist.as_replicates(rc.scene, rc.label, s, e, t) for s, e, t in reps])
        if "bias" not in wanted and "variance" not in wanted:  # the top budget's images, read last above
            store.put_image(f"{key}/estimate", images.mean(axis=0))
    if reps and noise > 0.1 * max(reps[-1][1].mean() + noise, 1e-300):
        notes.append(f"the reference's own relMSE {noise:.2g} is over 10 % of the top budget's: "
                     "render the reference with more samples")
    if faults.total:
        notes.append(f"invalid pixels excluded: {faults}")
    return RenderResult(rc, key, ref_label, faults, bias, variance, convergence, eff, errors, noise, notes)


# --- verdicts, rows, table -------------------------------------------------------------------------
def judge_renders(results: list[RenderResult], alpha: float) -> list[str]:
    """Bias verdicts, Holm-corrected over the suite's render cases at family-wise ``alpha``."""
    tested = [i for i, r in enumerate(results) if r.bias is not None]
    reject, _ = stats.holm([results[i].bias.pvalue for i in tested], alpha) if tested else ([], [])
    verdicts = ["" for _ in results]
    for i, rej in zip(tested, reject):
        r = results[i]
        if r.faults.total:
            verdicts[i] = f"invalid ({r.faults.total} bad pixels)"
        elif r.case.expect == "biased":
            verdicts[i] = "biased (expected)" if rej else "bias missed"
        else:
            verdicts[i] = "biased" if rej else "unbiased"
    for i, r in enumerate(results):
        if not verdicts[i] and r.faults.total:
            verdicts[i] = f"invalid ({r.faults.total} bad pixels)"
    return verdicts


def judge_render_convergence(results: list[RenderResult], alpha: float) -> list[str]:
    """"slower than expected" where the relMSE's slope is measurably worse than spp^-1/2
    (one-sided, Holm over the suite's render cases); "" where not measured."""
    idx = [i for i, r in enumerate(results) if r.convergence is not None and r.case.expect == "unbiased"]
    reject, _ = stats.holm([results[i].convergence.pvalue for i in idx], alpha) if idx else ([], [])
    out = ["" for _ in results]
    for i, rej in zip(idx, reject):
        out[i] = "slower than expected" if rej else "as expected"
    return out


def render_failures(results: list[RenderResult], alpha: float) -> list[str]:
    """Why each case fails ("" if it passes): a wrong bias verdict, invalid pixels, or a
    convergence measurably slower than spp^-1/2; with the figures a reader needs."""
    out = []
    for r, v, c in zip(results, judge_renders(results, alpha), judge_render_convergence(results, alpha)):
        problems = []
        if v.startswith(("invalid", "bias missed")) or v == "biased":
            b = r.bias
            what = "unbiased" if r.case.expect == "unbiased" else "biased"
            text = f"bias: {v}; expected {what}"
            if b is not None:
                text += (f"; p = {b.pvalue:.3g} (pixels {b.pvalue_pixels:.3g}, image mean {b.pvalue_mean:.3g}) at "
                         f"family-wise alpha {alpha} (Holm over {len(results)} configurations), {b.replicas} replicas x "
                         f"{b.spp} spp, {b.tested} pixel-channels tested; worst pixel (row, col, channel) "
                         f"{b.worst_pixel} t = {b.worst_t:+.2f}; image-mean bias {b.bias_mean:+.3g} ± {b.bias_mean_se:.2g}")
            if r.faults.total:
                text += f"; {r.faults}"
            problems.append(text)
        if c == "slower than expected":
            cr = r.convergence
            problems.append(f"convergence: sqrt(relMSE) slope {cr.slope:+.2f} [{cr.slope_interval[0]:+.2f}, "
                            f"{cr.slope_interval[1]:+.2f}], expected {cr.expected:+.2f} or faster (one-sided p = {cr.pvalue:.3g}, "
                            f"Holm at alpha {alpha})\n{cr.table.to_string(index=False)}")
        out.append("\n".join(problems))
    return out


def _estimand(r: RenderResult) -> tuple[str, str]:
    """Cases compared with each other: one scene and one reference (exact, or the same
    rendered reference, so the same path depth)."""
    return r.case.scene, r.reference


def _baselines(results: list[RenderResult]) -> dict[tuple[str, str], RenderResult]:
    """The first case of each estimand is the baseline of its efficiency ratios."""
    base: dict[tuple[str, str], RenderResult] = {}
    for r in results:
        if r.efficiency is not None:
            base.setdefault(_estimand(r), r)
    return base


def equal_time_relmse(results: list[RenderResult]) -> dict[str, tuple[float, float]]:
    """relMSE of each case at the longest time every case of its estimand reached: (time s,
    relMSE), interpolated linearly in log relMSE against log time between the two measured
    budgets around that time.  Budgets are taken in spp order with their median times made
    non-decreasing (timing noise of small renders), and nothing is extrapolated: a case whose
    smallest budget already takes longer gets NaN."""
    out: dict[str, tuple[float, float]] = {}
    by_estimand: dict[tuple[str, str], list[RenderResult]] = {}
    for r in results:
        if r.errors is not None and len(r.errors) >= 2 and (r.errors["relmse"] > 0).all():
            by_estimand.setdefault(_estimand(r), []).append(r)
    for group in by_estimand.values():
        t_star = min(float(r.errors["seconds"].max()) for r in group)
        for r in group:
            e = r.errors.sort_values("spp")
            t = np.maximum.accumulate(e["seconds"].to_numpy())
            lt, le = np.log(t), np.log(e["relmse"].to_numpy())
            x = math.log(t_star)
            if x < lt[0]:
                out[r.key] = (t_star, math.nan)
                continue
            i = int(np.clip(np.searchsorted(lt, x), 1, len(lt) - 1))
            w = (x - lt[i - 1]) / (lt[i] - lt[i - 1]) if lt[i] > lt[i - 1] else 1.0
            out[r.key] = (t_star, float(math.exp(le[i - 1] + min(w, 1.0) * (le[i] - le[i - 1]))))
    return out


def render_rows(suite: Suite, results: list[RenderResult], verdicts: list[str]) -> list[dict[str, Any]]:
    """Measurement rows for the store (same columns as the core cases')."""
    rows: list[dict[str, Any]] = []
    base = _baselines(results)
    equal = equal_time_relmse(results)
    for r, verdict in zip(results, verdicts):
        common = {"case_key": r.key, "suite": suite.name, "integrand": r.case.scene, "technique": r.case.label}
        if r.bias is not None:
            b = r.bias
            rows.append({**common, "measurement": "bias", "value": b.bias_mean, "lo": b.bias_mean - 1.96 * b.bias_mean_se,
                         "hi": b.bias_mean + 1.96 * b.bias_mean_se, "n": b.replicas * b.spp, "pvalue": b.pvalue,
                         "alpha": suite.alpha, "verdict": verdict,
                         "detail": {"pvalue_pixels": b.pvalue_pixels, "pvalue_mean": b.pvalue_mean,
                                    "worst_pixel": list(b.worst_pixel), "worst_t": b.worst_t, "tested": b.tested,
                                    "untestable": b.untestable, "excluded": b.excluded, "replicas": b.replicas,
                                    "spp": b.spp, "reference": r.reference, "faults": r.faults.to_dict(),
                                    "notes": r.notes}})
        if r.variance is not None:
            v, se, n = r.variance
            rows.append({**common, "measurement": "variance", "value": v, "lo": v - 1.96 * se, "hi": v + 1.96 * se,
                         "n": n, "detail": {"per": "sample, mean over pixels and channels"}})
        if r.convergence is not None:
            c = r.convergence
            rows.append({**common, "measurement": "convergence", "value": c.slope, "lo": c.slope_interval[0],
                         "hi": c.slope_interval[1], "n": int(c.table["replicas"].sum()), "pvalue": c.pvalue,
                         "verdict": "worse than expected" if c.worse_than_expected else "as expected",
                         "detail": {"expected": c.expected, "budgets": c.table["n"].tolist(),
                                    "rmse": c.table["rmse"].tolist(), "rmse_lo": c.table["rmse_lo"].tolist(),
                                    "rmse_hi": c.table["rmse_hi"].tolist(), "seconds": c.table["seconds"].tolist(),
                                    "error": "sqrt(relMSE)"}})
        if r.efficiency is not None:
            e, b0 = r.efficiency, base[_estimand(r)]
            ratio, (lo, hi) = (1.0, (1.0, 1.0)) if b0 is r else stats.efficiency_ratio(e, b0.efficiency)
            rows.append({**common, "measurement": "efficiency", "value": ratio, "lo": lo, "hi": hi,
                         "n": e.n * e.replicas, "detail": {"baseline": b0.case.label, "log10_value": e.log10_value,
                                                            "seconds": e.seconds, "spp": e.n,
                                                            "definition": "1/(relMSE T)"}})
        if r.errors is not None:
            top = r.errors.iloc[-1]
            rows.append({**common, "measurement": "relmse", "value": top["relmse"],
                         "lo": top["relmse"] - 1.96 * top["relmse_se"], "hi": top["relmse"] + 1.96 * top["relmse_se"],
                         "n": int(top["replicas"]), "detail": {"spp": int(top["spp"]), "seconds": top["seconds"],
                                                                "reference_noise": r.reference_noise,
                                                                "epsilon": ist.RELMSE_EPSILON}})
            rows.append({**common, "measurement": "error_vs_time", "value": float(top["relmse"]),
                         "n": int(r.errors["replicas"].sum()), "detail": {"rows": r.errors.to_dict("records")}})
        if r.key in equal:
            t_star, e_star = equal[r.key]
            rows.append({**common, "measurement": "equal_time_relmse", "value": e_star, "n": int(r.errors["replicas"].sum()),
                         "detail": {"seconds": t_star}})
    return rows


def render_table(results: list[RenderResult], verdicts: list[str]) -> pd.DataFrame:
    base = _baselines(results)
    equal = equal_time_relmse(results)
    out = []
    for r, verdict in zip(results, verdicts):
        row: dict[str, Any] = {"scene": r.case.scene, "configuration": r.case.label, "reference": (
            "exact" if r.reference == "exact" else f"{r.case.reference_spp} spp")}
        if r.bias is not None:
            row.update({"spp x R": f"{r.bias.spp} x {r.bias.replicas}", "p": r.bias.pvalue, "bias": verdict,
                        "worst |t|": abs(r.bias.worst_t)})
        elif verdict:
            row["bias"] = verdict
        if r.errors is not None:
            top = r.errors.iloc[-1]
            row["relMSE (top spp)"] = f"{top['relmse']:.3g} ± {top['relmse_se']:.2g} @ {int(top['spp'])}"
        if r.convergence is not None:
            c = r.convergence
            row["slope [95% CI]"] = f"{c.slope:+.2f} [{c.slope_interval[0]:+.2f}, {c.slope_interval[1]:+.2f}]"
        if r.efficiency is not None:
            b0 = base[_estimand(r)]
            ratio, (lo, hi) = stats.efficiency_ratio(r.efficiency, b0.efficiency)
            row["1/(relMSE·T) vs first [95% CI]"] = "1 (baseline)" if b0 is r else f"{ratio:.3g} [{lo:.3g}, {hi:.3g}]"
        if r.key in equal:
            t_star, e_star = equal[r.key]
            row["relMSE @ equal time"] = f"{e_star:.3g} @ {t_star * 1e3:.3g} ms"
        out.append(row)
    return pd.DataFrame(out)


def format_render_table(results: list[RenderResult], alpha: float) -> str:
    if not results:
        return ""
    df = render_table(results, judge_renders(results, alpha))
    text = df.to_string(index=False, float_format=lambda v: f"{v:.3g}")
    notes = [f"  {r.case.scene} {r.case.label}: {n}" for r in results for n in r.notes]
    return text + (("\n" + "\n".join(notes)) if notes else "")
