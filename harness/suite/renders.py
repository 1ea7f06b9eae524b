"""Render cases of a suite (``[[render]]``: a renderer configuration through its adapter), as a
case kind: plan the renders their measurements need, and measure bias, variance, convergence,
efficiency and error against time from the stored images.

Each render is one work unit (kind "render"), a serial job of the executor: its image goes to
the store's EXR folder and its row records the image's name, wall time and invalid pixels, so
a killed run re-renders nothing it stored.  Under Dask the renders run on the workers, one at
a time, with renderers rebuilt there from the suite's keys (same images, bit for bit).

A scene with an exact answer (``Renderer.exact``) renders no reference.  Otherwise the
reference is ``reference_parts`` independent renders by ``Renderer.reference()`` with
``reference_spp`` samples in total, stored as units like any other and then cached (mean and
variance of the mean as float64 .npy, so a rerun measures against bitwise the first run's
reference; EXR copies for viewing; a JSON record) in ``references/`` beside the database, keyed
by a hash of the reference renderer's fingerprint (scene, variant, integrator settings, library
versions), budget and seed; every case and run that needs the same reference reuses it.
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from harness import stats
from harness.adapters import ImageFaults, Renderer, RenderError, image_faults, renderer
from harness.adapters.base import checked_render
from harness.stats import images as ist
from harness.stats.scales import FINE_REPLICAS
from harness.suite.execute import JobResult
from harness.suite.kind import Outcome
from harness.suite.parse import RenderCase, Suite
from harness.suite.plan import (
    Unit,
    reference_key,
    reference_stream,
    reference_units,
    render_key,
    render_seed,
    render_stream,
    render_units,
)
from harness.suite.render_tables import failures, judge, render_rows, render_table
from harness.suite.store import Store, write_exr, write_npy
from harness.suite.verdicts import mark_xfail

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["RenderJob", "RenderResult", "RenderKind", "ReferenceCache", "cached_renderer"]

_RENDERERS: dict[str, Renderer] = {}   # per process: renderers keep JIT kernels and GL contexts warm


def cached_renderer(adapter: str, spec: tuple[tuple[str, Any], ...], *, reference: bool = False,
                    base: str = "") -> Renderer:
    """The renderer an adapter builds from a [[render]] table's keys (or its reference
    renderer), built once per process; ``base``: the suite file's folder."""
    key = json.dumps([adapter, list(spec), reference, base], sort_keys=True, default=str)
    if key not in _RENDERERS:
        r = (cached_renderer(adapter, spec, base=base) if reference
             else renderer(adapter, dict(spec), base=Path(base) if base else None))
        _RENDERERS[key] = r.reference() if reference else r
    return _RENDERERS[key]


@dataclass(frozen=True)
class RenderJob:
    """One render: ``unit.budget`` spp at the unit's seed (from ``stream``, the case's
    render_stream or reference_stream), by the case's renderer (or its reference renderer)."""

    unit: Unit
    stream: str
    adapter: str
    spec: tuple[tuple[str, Any], ...]
    reference: bool
    base: str = ""
    serial: bool = True

    def run(self) -> JobResult:
        u = self.unit
        r = cached_renderer(self.adapter, self.spec, reference=self.reference, base=self.base)
        out = checked_render(r, self.adapter, u.budget, render_seed(self.stream, u))
        name = f"{u.case_key}/render-s{u.stream}-b{u.budget}-r{u.replica}"
        payload = {"image": name, "spp": out.spp, "faults": image_faults(out.image).to_dict()}
        return JobResult(u, payload, out.seconds, {name: out.image})


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


class ReferenceCache:
    """Rendered references keyed by hash: the parts (K, h, w, c) as one lossless float64 array
    (.npy, what every run measures against, so a rerun is bitwise equal to the first run), the
    mean as EXR for viewing, and a JSON record written last."""

    def __init__(self, folder: Path):
        self.folder = folder

    def _path(self, key: str, what: str) -> Path:
        return self.folder / f"{key}-{what}"

    def load(self, key: str) -> ist.Reference | None:
        meta_p = self._path(key, "meta.json")
        if not meta_p.exists():  # written last: its presence means the arrays are complete
            return None
        try:
            meta = json.loads(meta_p.read_text())
            parts = np.load(self._path(key, "parts.npy"))
            if parts.shape[0] != int(meta["parts"]):
                raise ValueError(f"{parts.shape[0]} parts stored, {meta['parts']} recorded")
            return ist.Reference.from_parts(parts)
        except (OSError, ValueError, KeyError) as e:  # damaged or partly deleted: built again from its parts
            warnings.warn(f"{meta_p}: cached reference unreadable ({e}); building it again", stacklevel=2)
            return None

    def save(self, key: str, ref: ist.Reference, meta: dict[str, Any]) -> None:
        self.folder.mkdir(parents=True, exist_ok=True)
        write_npy(self._path(key, "parts.npy"), np.asarray(ref.parts, dtype=np.float64))
        write_exr(self._path(key, "mean.exr"), ref.mean)
        meta_p = self._path(key, "meta.json")
        tmp = meta_p.with_suffix(".json.partial")
        record = {**meta, "parts": ref.count}
        tmp.write_text(json.dumps(record, indent=1, sort_keys=True, default=str))
        os.replace(tmp, meta_p)


@dataclass(frozen=True)
class _Case:
    rc: RenderCase
    key: str
    renderer: Renderer
    ref_key: str | None          # None: the scene has an exact answer
    ref: Renderer | None
    stream: str                  # what the renders' seeds derive from (plan.render_stream)
    ref_stream: str | None       # ... the reference's (plan.reference_stream)
    ref_fingerprint: dict | None = None   # what ref_key was taken from
    sibling: _Case | None = None  # the configuration whose bias replicas are the reference


class RenderKind:
    """The suite's ``[[render]]`` tables.  Renderers are built (and their libraries imported)
    only when the suite has render cases and the runner registers them."""

    name = "render"

    def __init__(self, suite: Suite):
        self.suite = suite
        self.cases: list[_Case] = []

    def names(self) -> list[str]:
        return [f"render:{rc.scene}/{rc.label}#{rc.case_id}" for rc in self.suite.renders]

    def register(self, store: Store) -> None:
        self.cases = []
        for rc in self.suite.renders:
            # each fingerprint taken once: the keys, the seeds and the record all stand for the
            # same files (a renderer's files may change, and hashing a scene's can take seconds)
            r = cached_renderer(rc.adapter, rc.spec, base=rc.base)
            fp = r.fingerprint()
            key = render_key(self.suite, fp)
            rendered = r.exact() is None and rc.reference_config is None
            ref = cached_renderer(rc.adapter, rc.spec, reference=True, base=rc.base) if rendered else None
            ref_fp = ref.fingerprint() if ref else None
            ref_key = reference_key(self.suite, rc, ref_fp) if ref_fp else None
            ref_stream = reference_stream(self.suite, rc, ref_fp) if ref_fp else None
            self.cases.append(_Case(rc, key, r, ref_key, ref, render_stream(self.suite, fp), ref_stream,
                                    ref_fp))
            store.add_case(key, self.suite.name, rc.scene, rc.label,
                           {"adapter": rc.adapter, "spec": dict(rc.spec), "fingerprint": fp})
            if ref_key:
                store.use_key(ref_key)
        cases = self.cases
        self.cases = [c if c.rc.reference_config is None
                      else dataclasses.replace(c, sibling=_sibling(c, cases)) for c in cases]

    def plan(self, store: Store) -> list[RenderJob]:
        """Every render the measurements need (and the reference's parts, unless it is cached);
        a stored render whose image is missing or damaged is dropped, so it is rendered again."""
        cache = ReferenceCache(_reference_folder(store))
        jobs: dict[Unit, RenderJob] = {}
        for c in self.cases:
            for u in render_units(c.rc, c.key):
                jobs[u] = RenderJob(u, c.stream, c.rc.adapter, c.rc.spec, False, c.rc.base)
            if c.ref_key is not None and cache.load(c.ref_key) is None:
                for u in reference_units(c.rc, c.ref_key):
                    jobs.setdefault(u, RenderJob(u, c.ref_stream, c.rc.adapter, c.rc.spec, True, c.rc.base))
        damaged = []
        for key in {u.case_key for u in jobs}:
            for u, p in store.payloads(key).items():
                problem = store.image_problem(p["image"]) if u in jobs else None
                if problem:
                    warnings.warn(f"{problem}: rendering it again", stacklevel=2)
                    damaged.append(u)
        store.drop_units(damaged)
        # interleaved: replica r of every configuration, then r + 1, ...: a drift of the machine's
        # speed falls on all of them alike (their wall times are compared)
        order = {k: i for i, k in enumerate(dict.fromkeys(k for c in self.cases for k in (c.key, c.ref_key)))}
        return [jobs[u] for u in sorted(jobs, key=lambda u: (u.stream, u.replica, order[u.case_key], u))]

    def advance(self, store: Store) -> bool:
        return False

    def outcome(self, store: Store) -> Outcome:
        cache = ReferenceCache(_reference_folder(store))
        results = []
        for c in self.cases:
            if c.sibling is not None:   # two renderers, no converged reference: the sibling's replicas
                images, _, _ = _stack(store, _planned_payloads(store, c.sibling.rc, c.sibling.key),
                                      store.seconds(c.sibling.key), 0, c.sibling.rc.label)
                reference, label = ist.Reference.from_parts(images), c.sibling.rc.label
            elif c.ref_key is None:
                reference, label = ist.Reference.exact(c.renderer.exact()), "exact"
            else:
                reference, label = cache.load(c.ref_key), c.ref_key
                if reference is None:
                    reference = _build_reference(store, cache, c)
            results.append(_measure(c.rc, c.key, store, reference, label))
            if hasattr(c.renderer, "notes"):  # what the adapter says a reader must know (how it timed)
                results[-1].notes.extend(c.renderer.notes())
        alpha = self.suite.family_alpha
        verdicts = judge(results, alpha)
        table = render_table(results, verdicts)
        text = ""
        if results:
            # pandas only here: a run without renders prints without it (kind.Outcome.frame)
            import pandas as pd
            notes = [f"\n  {r.case.scene} {r.case.label}: {n}" for r in results for n in r.notes]
            aligned = pd.DataFrame(table).to_string(index=False, float_format=lambda v: f"{v:.3g}")
            text = (f"renders (multi-scale bias test, Holm over {len(results)} configurations at alpha "
                    f"{alpha:.3g}; relMSE = mean (x - ref)^2 / (ref^2 + 0.01); efficiency 1/(relMSE·T) "
                    "against the first configuration of the same scene and reference; relMSE at the longest "
                    "time all of those reached):\n" + aligned + "".join(notes))
        return Outcome(self.name, "render configurations", tuple(self.names()), tuple(results),
                       tuple(verdicts),
                       tuple(failures(results, verdicts, alpha)),
                       tuple(mark_xfail(render_rows(self.suite, results, verdicts),
                                        {c.key: c.rc.xfail for c in self.cases})), tuple(table), text,
                       tuple(rc.xfail for rc in self.suite.renders))


def _sibling(c: _Case, cases: list[_Case]) -> _Case:
    """The case whose spec ``c`` names as its reference (specs may hold tables, so no dict)."""
    return next(s for s in cases if s.rc.adapter == c.rc.adapter and s.rc.spec == c.rc.reference_config)


def _planned_payloads(store: Store, rc: RenderCase, key: str) -> dict[Unit, dict]:
    """The stored renders of the units this configuration plans: renders stored for an earlier
    version of the suite (other spp, budgets or replica counts) share the case key but are not
    part of this measurement."""
    planned = set(render_units(rc, key))
    return {u: p for u, p in store.payloads(key).items() if u in planned}


def _reference_folder(store: Store) -> Path:
    return store.path.parent / "references"


def _stored_images(store: Store, rows: list[tuple[Unit, dict]], label: str,
                   shape: tuple[int, ...] | None = None) -> np.ndarray:
    """The stored images of ``rows`` (units and payloads) as float64 (R, h, w, c); a
    RenderError naming the case (``label``) where their shapes differ from one another or from
    ``shape`` (the reference's): a renderer whose image size varies from call to call."""
    images = [store.image(p["image"]) for _, p in rows]
    want = shape or images[0].shape
    odd = next(((u, a.shape) for (u, _), a in zip(rows, images) if a.shape != want), None)
    if odd is not None:
        first = "reference" if shape else "first render"
        raise RenderError(f"{label}: the render of budget {odd[0].budget}, replica {odd[0].replica} has "
                          f"shape {odd[1]}, where the case's {first} has {want}: the renderer's image size "
                          "varies")
    return np.stack(images).astype(np.float64)


def _build_reference(store: Store, cache: ReferenceCache, c: _Case) -> ist.Reference:
    payloads = store.payloads(c.ref_key)
    images = _stored_images(store, sorted(payloads.items()), f"{c.rc.label} (reference)")
    reference = ist.Reference.from_parts(images)
    cache.save(c.ref_key, reference, {"fingerprint": c.ref_fingerprint, "spp": c.rc.reference_spp,
                                      "invalid_pixels": _faults(payloads).total,
                                      "seconds": float(sum(store.seconds(c.ref_key).values()))})
    return reference


def _stack(store: Store, payloads: dict[Unit, dict], seconds: dict[Unit, float], stream: int, label: str,
           shape: tuple[int, ...] | None = None) -> tuple[np.ndarray, np.ndarray, int]:
    """The replica images of one stream (R, h, w, c), their wall times (R,) and their budget;
    the images checked to share one shape, the reference's ``shape`` where given
    (:func:`_stored_images`; ``label`` names the case)."""
    rows = sorted((u, p) for u, p in payloads.items() if u.stream == stream)
    images = _stored_images(store, rows, label, shape)
    return images, np.array([seconds[u] for u, _ in rows]), rows[0][0].budget


def _faults(payloads: dict[Unit, dict]) -> ImageFaults:
    """The invalid pixels of a case's renders: counts, and examples as (replica, row, col)."""
    total = ImageFaults(position="replica, row, col")
    for u, p in sorted(payloads.items()):
        f = p["faults"]
        for kind in ("nan", "inf", "negative"):
            setattr(total, kind, getattr(total, kind) + f[kind])
            ex = total.examples.setdefault(kind, [])
            ex += [(int(u.replica), *pos) for pos in f["examples"].get(kind, [])][: max(0, 8 - len(ex))]
    total.examples = {k: v for k, v in total.examples.items() if v}
    return total


def _measure(rc: RenderCase, key: str, store: Store, reference: ist.Reference,
             ref_label: str) -> RenderResult:
    payloads = _planned_payloads(store, rc, key)
    seconds_of = {u: s for u, s in store.seconds(key).items() if u in payloads}
    wanted = set(rc.measurements)
    faults = _faults(payloads)
    notes: list[str] = []
    bias = variance = convergence = eff = errors = None
    if wanted & {"bias", "variance"}:
        images, _, spp = _stack(store, payloads, seconds_of, 0, rc.label, reference.mean.shape)
        if "bias" in wanted:
            bias = ist.pixel_bias_test(images, reference, spp)
            if bias.replicas < FINE_REPLICAS:
                notes.append(f"pixels and tiles under 8 pixels are not tested at {bias.replicas} replicas, "
                             "and coarser tiles with the t law at 3 degrees of freedom (the t law fails "
                             f"there for sparse pixels); render {FINE_REPLICAS} or more to test them")
            skewed = [str(sc) for sc in bias.scales if sc.low_untested or sc.high_untested]
            if skewed:
                notes.append(f"sides of some tiles untested (replicas too skewed or constant there): "
                             f"{'; '.join(skewed)}")
            if bias.inconclusive:
                notes.append(bias.inconclusive)
            # the |t| map at the most significant scale (0 where untested), for the report
            store.put_image(f"{key}/tmap", np.nan_to_num(bias.t_map, nan=0.0).astype(np.float32))
        if "variance" in wanted:
            variance = ist.pixel_variance(images, reference, spp)
        store.put_image(f"{key}/estimate", images.mean(axis=0))
    store.put_image(f"{key}/reference", reference.mean)
    chosen = sorted({u.stream for u in payloads} - {0})
    noise = reference.noise_relmse()
    reps, rows = [], []
    for stream in chosen:
        images, seconds, spp = _stack(store, payloads, seconds_of, stream, rc.label, reference.mean.shape)
        err = ist.relmse(images, reference)
        reps.append((spp, err, seconds))
        rows.append({"spp": spp, "seconds": float(np.median(seconds)), "relmse": float(err.mean()),
                     "relmse_se": float(err.std(ddof=1) / math.sqrt(err.size)), "replicas": int(err.size)})
    if reps and min(row["relmse"] for row in rows) <= 0:
        notes.append(f"relMSE at or below the reference's own ({noise:.2g}) at some budget: the reference is "
                     "too noisy to measure this configuration's error; render it with more samples")
        reps = []
    if reps:
        import pandas as pd  # deferred, as in kind.Outcome.frame
        errors = pd.DataFrame(rows)
        spp, err, seconds = reps[-1]
        eff = ist.image_efficiency(rc.label, spp, err, seconds)
        if "convergence" in wanted and len(reps) >= 3:
            convergence = stats.fit_convergence([ist.as_replicates(rc.scene, rc.label, s, e, t)
                                                 for s, e, t in reps], pooled=True)
            if convergence.inconclusive:
                notes.append(f"convergence not judged: {convergence.inconclusive}")
        if "bias" not in wanted and "variance" not in wanted:  # the top budget's images, read last above
            store.put_image(f"{key}/estimate", images.mean(axis=0))
    if reps and noise > 0.1 * max(reps[-1][1].mean() + noise, 1e-300):
        notes.append(f"the reference's own relMSE {noise:.2g} is over 10 % of the top budget's: "
                     "render the reference with more samples")
    if faults.total:
        notes.append(f"invalid pixels excluded: {faults}")
    return RenderResult(rc, key, ref_label, faults, bias, variance, convergence, eff, errors, noise, notes)
