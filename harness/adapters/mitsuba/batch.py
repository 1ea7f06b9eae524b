"""The base of the Mitsuba sampler adapters: canonical uniforms and directions into drjit arrays
and back (one kernel a batch on JIT variants, one Python call a sample on scalar ones), what a
sample call returned (:class:`SampleBatch`), and :class:`MitsubaSampler`, the batch sample /
pdf / eval interface every adapter (BSDFs, microfacet distributions, phase functions,
emitters) implements.

Uniforms arrive as float64 in (0, 1) and are rounded to float32, clamped below 1 (a float64
just below 1 would round to 1.0, a value Mitsuba's warps never see).  Directions given to
``pdf`` and ``eval`` are rounded to float32 as given where their length is 1 within
:data:`UNIT_SLACK` (every direction a sampler returns, every float64 unit vector), so that a
direction Mitsuba returned is re-evaluated at exactly its float32 value; other non-zero
vectors are normalised in float64 first.  Renormalising a returned direction moves it by an
ulp, and some pdfs are that sensitive: principled's refraction from below changes by up to
4e-4 relative (measured, 1e6 samples at theta_i = 135 degrees), where the pdf at the returned
direction equals the reported one exactly.

Variants.  Every call holds ``runtime.VARIANT_LOCK`` and sets the sampler's variant; Mitsuba
objects are built once per sampler, for its variant.
"""
from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

import reference_estimators as rest

from harness.adapters.mitsuba.runtime import check_variant, is_jit, using_variant
from harness.samplers.domains import FLOAT32_UNIT_SLACK

__all__ = ["UNIT_SLACK", "MitsubaSampler", "SampleBatch", "direction", "float32_pdf_of", "plugin_label",
           "polar_angle"]

_BELOW_ONE = np.float32(1.0) - np.float32(2.0**-24)


def direction(wi: float | Sequence[float], name: str = "wi", *,
              below: bool = False) -> tuple[float, float, float]:
    """A polar angle in degrees (azimuth 0) or a 3-vector, as a unit vector: in the upper
    hemisphere (angle in [0, 90), z > 0), or anywhere but the horizon with ``below`` (angle
    in [0, 180] except 90, z != 0).  Raises ValueError naming ``name``."""
    if np.ndim(wi) == 0:
        theta = float(wi)
        ok = (0 <= theta <= 180 and theta != 90) if below else (0 <= theta < 90)
        if not ok:
            rule = "in [0, 180], not 90" if below else "in [0, 90)"
            raise ValueError(f"'{name}' as an angle must be a polar angle in degrees {rule}, got {wi!r}")
        t = math.radians(theta)
        return (math.sin(t), 0.0, math.cos(t))
    v = np.asarray(wi, dtype=float)
    norm = float(np.linalg.norm(v)) if v.shape == (3,) else 0.0
    if v.shape != (3,) or not np.all(np.isfinite(v)) or norm == 0 or (v[2] == 0 if below else v[2] <= 0):
        rule = "z != 0" if below else "z > 0"
        raise ValueError(f"'{name}' must be a polar angle in degrees or a 3-vector with {rule}, got {wi!r}")
    return tuple(float(c) for c in v / norm)  # type: ignore[return-value]


def float32_pdf_of(sampler: Any) -> Callable[[np.ndarray], np.ndarray] | None:
    """The sampler's ``float32_pdf`` where it is its ``pdf`` by construction: defined by the
    class that defines ``pdf`` or by a subclass of it (or both on the instance).  A subclass or
    instance that replaces ``pdf`` alone (a user's planted fault, a wrapper), one whose
    ``float32_pdf`` is None (a Mutant of such a sampler), and one whose methods come from
    ``__getattr__`` get None: their pdf is integrated through ``pdf``, as the drawn points
    are evaluated."""
    fast = getattr(sampler, "float32_pdf", None)
    if fast is None:
        return None
    own = vars(sampler) if hasattr(sampler, "__dict__") else {}
    if "pdf" in own or "float32_pdf" in own:
        return fast if "pdf" in own and "float32_pdf" in own else None
    pdf_owner, fast_owner = (next((c for c in type(sampler).__mro__ if name in c.__dict__), None)
                             for name in ("pdf", "float32_pdf"))
    return fast if pdf_owner and fast_owner and issubclass(fast_owner, pdf_owner) else None


def polar_angle(v: Sequence[float]) -> float:
    """The polar angle of a unit vector, in degrees."""
    return math.degrees(math.acos(max(-1.0, min(1.0, v[2]))))


def uniforms(u: np.ndarray, udim: int) -> list[np.ndarray]:
    """The first ``udim`` columns of ``u`` (N, >= udim) as float32, clamped below 1, in one
    pass in the core (reference_estimators.float32_columns: the clamp in float32 after
    rounding, the same bits as before it, rounding being monotone and the bound a float32)."""
    u = np.asarray(u, dtype=float)
    if u.ndim != 2 or u.shape[1] < udim:
        raise ValueError(f"'u' must have shape (N, {udim}), got {u.shape}")
    return list(rest.float32_columns(u[:, :udim], float(_BELOW_ONE)))


#: a direction whose length is 1 within this (about 8 float32 ulps) is rounded to float32 as
#: given; Mitsuba's float32 normalisation leaves at most a few ulps.  The slack of the float32
#: columns the check's cubature hands ``float32_pdf`` (Float32DirectionPdf's contract), so the
#: two agree whatever its value
UNIT_SLACK = FLOAT32_UNIT_SLACK


def unit_columns(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Direction columns (3, N) as float32 (rows of length 1 within UNIT_SLACK as given, others
    normalised in float64 first) and the rows that are finite non-zero vectors (the others
    become +z): one pass in the core (reference_estimators.float32_unit_rows)."""
    return rest.float32_unit_rows(x, UNIT_SLACK)


def _to_numpy(value: Any, n: int, widen: bool = True) -> np.ndarray:
    """A drjit result as float64 (N,) or (N, channels) in C order (a vector's or colour's
    (channels, N) transposed in the same pass as the cast, by the core
    (:func:`reference_estimators.float64_rows`): the check's core passes read directions in
    C order, and copied a transposed view a pass each).  A JIT vector's or colour's
    components are read in place where each holds N values (drjit's (channels, N) copy cost a
    million directions 1.7 ms, more than the cast).  A literal (width 1) becomes N
    copies of its value, except a vector's or colour's (a constant weight: a phase function's),
    which stays a read-only broadcast view of it (24 MB a million samples
    that only :class:`SampleBatch`'s weight holds).  ``widen`` False: a JIT variant's float32
    scalars (N,) as they are (drjit's memory, no copy)."""
    import drjit as dr

    if (dr.depth_v(value) == 2 and dr.size_v(value) > 0 and dr.type_v(value) == dr.VarType.Float32
            and dr.width(value) == n):
        columns = [np.asarray(value[c]) for c in range(dr.size_v(value))]
        if all(c.shape == (n,) for c in columns):
            return rest.float64_rows(columns)
    a = np.asarray(value)
    if not widen and a.ndim == 1 and a.dtype == np.float32 and a.shape == (n,):
        return a
    if a.ndim == 2 and a.dtype == np.float32:     # a JIT vector or colour: (channels, N)
        out = rest.float64_rows(a)
    elif a.ndim == 2:                             # a double variant's
        out = np.ascontiguousarray(a.T, dtype=np.float64)
    else:
        out = a.astype(np.float64)
    if out.shape[:1] == (n,):
        return out
    view = np.broadcast_to(out, (n,) + out.shape[1:])
    return view if out.ndim == 2 else view.copy()


def exact_json(value: Any) -> Any:
    """value as JSON that holds its numbers exactly, for fingerprints: dicts and sequences item by
    item, numpy arrays and scalars as Python numbers, a Mitsuba transform as its matrix and
    inverse transpose (a transform's str rounds to 6 digits, so two transforms 1e-7 apart had
    keyed the same results; a translation's inverse is exact, a matrix's computed, and the two
    may differ in their last bits), a Mitsuba bitmap as its pixels' SHA-256 and its format
    (pixel format, sRGB gamma, premultiplied alpha), a Mitsuba plugin object (a BSDF, texture
    or emitter a spec holds already built) as :func:`_plugin_json`'s, a drjit complex value as
    its real and imaginary parts, another drjit or Mitsuba array (a colour, a vector, a
    quaternion) as its numbers, Mitsuba ``Properties`` as their plugin name, id and entries,
    and any other Mitsuba value (a bounding box or sphere, a ray, a frame) as its data fields,
    each the same way; anything else as it is.  A drjit or Mitsuba value with neither numbers
    nor fields raises ValueError: its ``str`` (rounded) would key results it does not fix."""
    if isinstance(value, dict):
        return {k: exact_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [exact_json(v) for v in value]
    if isinstance(value, (np.ndarray, np.generic)):
        return value.tolist()
    if hasattr(value, "pixel_format") and hasattr(value, "srgb_gamma"):   # a mi.Bitmap: its bytes
        pixels = np.ascontiguousarray(value)
        return {"bitmap_sha256": hashlib.sha256(pixels.tobytes()).hexdigest(),
                "shape": list(pixels.shape), "dtype": str(pixels.dtype),
                "pixel_format": str(value.pixel_format()), "srgb_gamma": bool(value.srgb_gamma()),
                "premultiplied_alpha": bool(value.premultiplied_alpha())}
    if hasattr(value, "matrix") and hasattr(value, "inverse_transpose"):
        return {"matrix": np.asarray(value.matrix, dtype=float).tolist(),
                "inverse_transpose": np.asarray(value.inverse_transpose, dtype=float).tolist()}
    library = {c.__module__.split(".")[0] for c in type(value).__mro__} & {"drjit", "mitsuba"}
    if not library:
        return value
    if "mitsuba" in library and hasattr(value, "parameters_changed"):   # a plugin, a Python-defined one too
        return _plugin_json(value)
    return _value_json(value)


def _value_json(value: Any) -> Any:
    """exact_json of a drjit or Mitsuba value that is neither a plugin, a bitmap nor a transform."""
    import drjit as dr

    if dr.is_complex_v(value):   # numpy's float cast keeps only the real part
        return {"real": exact_json(dr.real(value)), "imag": exact_json(dr.imag(value))}
    try:
        return np.asarray(value, dtype=float).tolist()
    except (TypeError, ValueError, RuntimeError):   # not an array: a structure
        pass
    if type(value).__name__ == "Properties":
        names = value.keys() if hasattr(value, "keys") else value.property_names()
        return {"plugin_name": value.plugin_name(), "id": value.id(),
                "entries": {str(k): exact_json(value[k]) for k in names}}
    fields = getattr(type(value), "DRJIT_STRUCT", None)
    names = list(fields) if isinstance(fields, dict) else [
        a for a in dir(value) if not a.startswith("_") and not callable(getattr(value, a))]
    if not names:
        raise ValueError(f"cannot key a {type(value).__module__}.{type(value).__qualname__} exactly "
                         "(neither numbers nor data fields): give its settings as numbers or a plugin dict")
    return {a: exact_json(getattr(value, a)) for a in names}


#: A plugin parameter with more values than this (a texture's pixels, a mesh's vertices) is
#: keyed by the SHA-256 of its bytes rather than listed
_LISTED_VALUES = 64


def _plugin_json(plugin: Any) -> dict[str, Any]:
    """A built Mitsuba plugin object as JSON that tells apart any two that differ: its class
    (module and qualified name), its ``str`` (the settings that are not parameters: a
    microfacet distribution, a filter type) and every parameter ``mi.traverse`` gives, its
    nested plugins' included, with exact numbers (``str`` alone rounds them to 6 digits, so
    two BSDFs 1e-7 apart in roughness had keyed the same results): transforms as
    :func:`exact_json`'s, arrays of up to _LISTED_VALUES values as their numbers, larger ones
    as the SHA-256 of their bytes with their shape and dtype.  A setting a built plugin shows
    neither in its ``str`` nor as a parameter (a bitmap texture's filter and wrap modes, in
    Mitsuba 3.9) is not seen: a spec that gives plugin dicts, as a suite's tables do, is
    keyed by every setting."""
    import mitsuba as mi

    params = mi.traverse(plugin)
    values = {}
    for key in sorted(params.keys()):
        value = params[key]
        if hasattr(value, "matrix") and hasattr(value, "inverse_transpose"):
            values[key] = exact_json(value)
            continue
        a = np.ascontiguousarray(value)
        values[key] = (a.tolist() if a.size <= _LISTED_VALUES else
                       {"sha256": hashlib.sha256(a.tobytes()).hexdigest(), "shape": list(a.shape),
                        "dtype": str(a.dtype)})
    kind = f"{type(plugin).__module__}.{type(plugin).__qualname__}"
    return {"plugin_object": kind, "str": str(plugin), "parameters": values}


def _per_channel(v: np.ndarray) -> np.ndarray:
    """A per-sample value as :func:`run_batch` returns it, (N,) or (N, channels), as (N,
    channels): a scalar's one channel.  (Not reshape(N, -1): with no rows it cannot infer the
    channels, and a weight check of a sampler that produced nothing, or a sample call on no
    uniforms, had raised there.)"""
    return v if v.ndim == 2 else v[:, None]


def run_batch(mi: Any, variant: str, kernel: Callable[..., tuple], columns: list[np.ndarray],
              widen: bool = True) -> list[np.ndarray]:
    """Runs ``kernel(mi, width, *columns)`` once over drjit arrays (JIT variants) or once per
    row with Python floats (scalar variants; width None); returns numpy arrays (N,) or (N, c),
    float64 (``widen`` False: a JIT variant's float32 scalars as drjit returned them)."""
    import drjit as dr

    n = len(columns[0])
    if n == 0:  # drjit arrays of width 0 are not all supported: run one dummy row, keep none
        dummy = [np.zeros(1, dtype=np.float32) for _ in columns]
        return [o[:0] for o in run_batch(mi, variant, kernel, dummy, widen)]
    if is_jit(variant):
        outs = kernel(mi, n, *(mi.Float(c) for c in columns))
        dr.eval(*outs)
        return [_to_numpy(o, n, widen) for o in outs]
    rows = [kernel(mi, None, *(float(c[i]) for c in columns)) for i in range(n)]
    return [np.array([np.asarray(r[k], dtype=np.float64) for r in rows]) for k in range(len(rows[0]))]


def zeros(mi: Any, cls: str, width: int | None) -> Any:
    """``dr.zeros`` of the Mitsuba type ``cls`` (e.g. "Interaction3f"), of ``width`` (None:
    a scalar variant's single value)."""
    import drjit as dr

    t = getattr(mi, cls)
    return dr.zeros(t, width) if width is not None else dr.zeros(t)


def plugin_label(plugin: dict[str, Any]) -> str:
    """A short label of a plugin dict without its incident angle, e.g.
    "roughconductor ggx α=0.1 visible=True"; nested plugins in parentheses, e.g.
    "mask opacity=0.3 (diffuse)"."""
    p = plugin
    parts = [p["type"]]
    if "distribution" in p:
        parts.append(str(p["distribution"]))
    if "alpha" in p:
        parts.append(f"α={p['alpha']:g}")
    for key, short in (("sample_visible", "visible"), ("int_ior", "ior"), ("opacity", "opacity"),
                       ("weight", "weight"), ("g", "g"), ("roughness", "roughness"),
                       ("spec_trans", "spec_trans"), ("metallic", "metallic")):
        if key in p and not isinstance(p[key], dict):
            parts.append(f"{short}={p[key]}")
    nested = [plugin_label(v) for k, v in sorted(p.items()) if isinstance(v, dict) and "type" in v]
    if nested:
        parts.append("(" + ", ".join(nested) + ")")
    return " ".join(parts)


@dataclass(frozen=True)
class SampleBatch:
    """What a sampler returned for uniforms ``u``: directions ``x`` (N, 3) as Mitsuba gave them
    (also where it failed), the weight (N, channels) (None for microfacet distributions; a
    read-only broadcast view where Mitsuba returned one constant weight: copy it to write), the
    pdf the sample call reported (N,), and ``valid``: the rows in the density (weight not all
    zero, pdf > 0, finite direction, not a Dirac lobe).  ``delta``: the rows that sampled a
    Dirac delta lobe (a mask's pass-through, a smooth plastic's coating; None where the
    sampler has none); they are not in ``valid``.  ``extra``: per-row values a sampler adds
    (a BSDF's ``sampled_type`` flags, an emitter's ``dist`` and ``cos``), for planted faults
    and diagnostics."""

    u: np.ndarray
    x: np.ndarray
    weight: np.ndarray | None
    sample_pdf: np.ndarray
    valid: np.ndarray
    delta: np.ndarray | None = None
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def produced(self) -> np.ndarray:
        """The directions with NaN rows where not ``valid``: ``x`` itself when every row is."""
        return self.x if self.valid.all() else rest.nan_rows(self.x, self.valid)


class MitsubaSampler:
    """Base of the adapters: ``sample(u)`` (N, udim) -> directions (N, 3) with NaN rows for
    samples not produced (failed, or of a Dirac lobe), ``sample_with_pdf(u)`` -> (those
    directions, the pdf each sample call reported), ``pdf(x)`` (N, 3) -> (N,) per solid angle
    (0 for non-finite rows), ``sample_batch(u)`` -> SampleBatch, ``eval(x)`` -> (N, channels)
    or None, ``domain``, ``udim``, ``name``, ``fingerprint()``.

    Subclasses define ``_build(mi)`` (the Mitsuba object), ``_sample_kernel`` returning the
    values named by ``sample_outputs`` ("x", "pdf", optionally "weight" and "delta", then any
    extras), ``_pdf_kernel`` and ``_eval_kernel``.

    ``check_threads``: drjit's worker threads while a sampler check runs
    (harness.adapters.mitsuba.checks.check_mitsuba_sampler; None: drjit's own count, one per
    CPU).  One for plugins whose kernels are cheap (BSDFs, phase functions, microfacet
    distributions, environment maps): the check calls some 300 short kernels between its own
    batch calls, and drjit's idle workers spin after each, so its own work, its Python and the
    kernels' launches ran beside them throughout.  On the 2-CPU machine of 2026-12-05 one
    worker took the median check of those 112 catalogue plugins from 0.168 to 0.147 s (its own
    work 0.100 to 0.081 s, a diffuse BSDF's 0.053 to 0.042 s; 30 plugins' own work within 50
    ms, 8 before: benchmarks/check_time_split.py --all), though drjit's kernels alone run
    slower on one; an area light, whose pdf traces a ray a direction, keeps every worker (1.5 s a
    check with two, 1.8 s with one).  A check holds Mitsuba's variant lock throughout, so
    concurrent Mitsuba calls of other threads wait for it.

    ``pdf_batch``: the directions the check's cubature passes the plugin's pdf in one call
    (check_sampler's ``pdf_batch``): 2^19, where the cubature's default 2^16 suits numpy pdfs.
    Each call launches a kernel and goes through Python's layers, and the cubature's float32
    columns (``float32_pdf``) live in memory the core reuses, so larger batches cost fewer
    launches and no page faults: on 2026-12-05's machine a tilted GGX lobe's check took 0.20 s
    at 2^16 and 0.14 s at 2^19, an envmap's 1.25 and 0.93 s, hg g = 0.9's 0.31 and 0.21 s
    (2^18 and 2^20 within a few per cent of 2^19); area lights, through their cap's map, 1.25 s
    at 2^16 and 1.07 at 2^18, and with the float32 columns of the cap's map 1.06-1.28 s at
    2^19, 1.18-1.40 at 2^18 and 1.29-1.41 at 2^17 (three lights, one sitting)."""

    kind = "mitsuba"
    udim = 2
    domain = "sphere"
    sample_outputs: tuple[str, ...] = ("x", "weight", "pdf")
    check_threads: int | None = 1
    pdf_batch: int | None = 2**19

    def __init__(self, variant: str, name: str):
        check_variant(variant)
        self.variant = variant
        self.name = name
        self._obj: Any = None

    def _object(self, mi: Any) -> Any:
        """The Mitsuba object, built once for this sampler's variant; call with the variant set
        (inside ``using_variant(self.variant)``), as every method does."""
        if self._obj is None:
            self._obj = self._build(mi)
        return self._obj

    def _build(self, mi: Any) -> Any:
        raise NotImplementedError

    def _build_checked(self, what: str) -> Any:
        """Builds the Mitsuba object now; Mitsuba's own error becomes a ValueError naming
        'plugin'.  Returns the object (call inside no variant context)."""
        with using_variant(self.variant) as mi:
            try:
                return self._object(mi)
            except Exception as e:  # Mitsuba raises RuntimeError / TypeError for a bad plugin dict
                raise ValueError(f"'plugin': Mitsuba cannot build {what}: {e}") from None

    def _run(self, kernel: Callable[..., tuple], cols: list[np.ndarray],
             widen: bool = True) -> list[np.ndarray]:
        with using_variant(self.variant) as mi:
            obj = self._object(mi)
            return run_batch(mi, self.variant, lambda m, w, *c: kernel(m, obj, w, *c), cols, widen)

    def sample_batch(self, u: np.ndarray) -> SampleBatch:
        """The sample call on uniforms ``u`` (N, udim), everything it returned."""
        out = dict(zip(self.sample_outputs, self._run(self._sample_kernel, uniforms(u, self.udim))))
        x = out.pop("x").reshape(-1, 3)
        spdf = out.pop("pdf").reshape(-1)
        weight = out.pop("weight", None)
        delta = out.pop("delta", None)
        weight = None if weight is None else _per_channel(weight)
        delta = None if delta is None else delta.reshape(-1)
        valid = rest.produced_rows(x, spdf, weight, delta)
        return SampleBatch(np.asarray(u, dtype=float), x, weight, spdf, valid,
                           None if delta is None else delta != 0, out)

    def sample(self, u: np.ndarray) -> np.ndarray:
        """Directions (N, 3) for uniforms ``u``; NaN rows for samples not produced."""
        return self.sample_batch(u).produced

    def sample_with_pdf(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(directions as ``sample`` gives them, the pdf each sample call reported (N,)): the
        pair ``check_sampler`` checks the reported pdf from (harness.samplers.reported)."""
        b = self.sample_batch(u)
        return b.produced, b.sample_pdf

    def pdf(self, x: np.ndarray) -> np.ndarray:
        """Density per solid angle at directions x (N, 3) (0 at non-finite or zero rows; see
        the module for how x is rounded to float32): ``float32_pdf`` at the rounded directions,
        widened, so that the two agree by construction."""
        cols, ok = unit_columns(x)
        p = np.asarray(self.float32_pdf(cols), dtype=np.float64)
        return p if ok.all() else np.where(ok, p, 0.0)

    def float32_pdf(self, columns: np.ndarray) -> np.ndarray:
        """Density per solid angle at float32 unit directions given as columns (3, N), as
        Mitsuba returned it (float32 on JIT variants): ``pdf`` at any directions that round to
        them (the contract of :class:`~harness.samplers.domains.Float32DirectionPdf`, the form
        ``check_mitsuba_sampler`` hands the check's cubature), without the rounding pass or the
        float64 copy of the result."""
        (p,) = self._run(lambda m, o, w, *c: (self._pdf_kernel(m, o, w, *c),), list(columns), widen=False)
        return p.reshape(-1)

    def eval(self, x: np.ndarray) -> np.ndarray | None:
        """The value whose ratio to the pdf the sample weight must be (BSDF: f cos theta_o;
        phase function: its value; emitter: radiance), (N, channels); None where the sampler
        has no weight."""
        cols, ok = unit_columns(x)
        (v,) = self._run(lambda m, o, w, *c: (self._eval_kernel(m, o, w, *c),), list(cols))
        return np.where(ok[:, None], _per_channel(v), 0.0)

    def fingerprint(self) -> dict[str, Any]:
        """What the sampler's results depend on: Mitsuba's version, variant, kind and spec
        (JSON, its numbers exact: :func:`exact_json`)."""
        spec = self._spec()   # (an envmap's reads and hashes its file: outside the lock)
        with using_variant(self.variant) as mi:   # a built plugin in the spec is traversed in its variant
            return {"adapter": "mitsuba", "mitsuba": mi.__version__, "kind": self.kind, "name": self.name,
                    "variant": self.variant, **exact_json(spec)}

    def _spec(self) -> dict[str, Any]:
        return {}

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r}, variant={self.variant!r}, domain={self.domain!r})"
