"""Suite files (TOML): what to measure, with how many samples, from which seed.

A suite has one [suite] table and at least one [[case]], [[sampler]] or [[render]] table;
any other top-level table is an error.  Every key is optional unless marked required:

    [suite]
    name = "default"          # default: the file's stem
    seed = 0                  # >= 0; streams are keyed by (seed, case, replica, chunk)
    samples = 1_000_000       # per bias test (split into `batches` replicas); cases may override it
    threads = 0               # >= 0; 0 or absent: all cores
    alpha = 0.01              # in (0, 1): family-wise false-alarm rate (Holm) of the cases' bias
                              #   tests, of the sampler checks, and of the renders' tests
    batches = 64              # independent replicas the bias test compares, in [8, samples]
    replicas = 32             # >= 2: replicas per budget for convergence and efficiency
    budgets = [1024, 4096, 16384]  # >= 3 positive convergence budgets (default: five geometric,
                              #   samples/4096 .. samples/16 by factors of 4, none below 16)
    measurements = ["bias", "variance", "convergence", "efficiency", "error_vs_time"]  # the default,
                              #   for [[case]] and [[render]] tables that give none

    [[case]]                  # catalogue integrand x techniques; one case per pair, in order
    integrand = "gaussian"    # required: a catalogue name, or "all"
    techniques = "all"        # "all" (the default), one technique name, or a list of them
    samples = 10_000_000      # >= batches; default: the suite's
    measurements = ["bias"]   # some of the five names above; default: the suite's
    target = 1e-4             # with max_samples: double the bias test's samples until its CI
    max_samples = 64_000_000  #   half-width is <= target, up to max_samples (alpha split over looks)

    [[sampler]]               # a catalogue sampler against its pdf (harness.samplers.check)
    name = "ggx"              # required: a registry sampler (not a tabulated one)
    params = { alpha = 0.01 } # numbers; default: the registry's
    domain = "hemisphere"     # interval, half_line, square, disk, hemisphere or sphere; default:
                              #   the sampler's own
    samples = 1_000_000       # >= 1000; default: the suite's samples
    measurements = ["chi_square", "mcmc"]  # default ["chi_square"]

    [[sampler]]               # a renderer's sampler: Mitsuba BSDF, microfacet distribution, envmap
    adapter = "mitsuba"       # required (the only adapter with samplers)
    plugin = { type = "roughconductor", alpha = 0.1 }  # required: a Mitsuba plugin dict
    wi = 45                   # incident direction: polar angle in degrees or a 3-vector (default 0)
    variant = "llvm_ad_rgb"   # the default
    samples = 1_000_000       # >= 1000; default: the suite's samples
    measurements = ["chi_square", "weight"]  # the default (for microfacet distributions: chi_square)

    [[render]]                # renderer configurations measured from replica renders
    adapter = "mitsuba"       # required: one of harness.adapters.ADAPTERS
    spp = 64                  # budget of each of the bias test's renders (default 64)
    replicas = 16             # >= 4 (default 16)
    budgets = [4, 16, 64]     # convergence budgets (default spp/64, spp/16, spp/4, spp, none below 1);
                              #   >= 3 distinct ones for convergence, efficiency or error_vs_time
    reference_spp = 4096      # without an exact answer: total spp of the reference render, a
    reference_parts = 8       #   multiple of reference_parts (>= 2) independent parts
                              #   (defaults: 64 x max(budgets, spp) and 8)
    measurements = ["bias"]   # default: the suite's
    expect = "biased"         # "unbiased" (the default), or the bias test must reject
    scene = "cornell"         # every other key is the adapter's (scene, integrator, variant, ...);
    integrator = ["path", "direct"]  # a list makes one case per element (cross product over lists)

Cases are numbered in order and the number keys their random streams; sampler tables are
numbered after the cases, render cases from 0 on their own.
Every mistake is reported as ``file:line: key: what was expected``.
"""
from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import reference_estimators as rest

from harness.suite.locate import Locator

__all__ = ["Suite", "Case", "SamplerCase", "RenderCase", "SuiteError", "load_suite"]


class SuiteError(ValueError):
    """A suite file that cannot be run; the message names file, line and key."""


MEASUREMENTS = ("bias", "variance", "convergence", "efficiency", "error_vs_time")
SAMPLER_MEASUREMENTS = ("chi_square", "mcmc", "weight")


@dataclass(frozen=True)
class SamplerCase:
    """A catalogue sampler checked against its pdf (harness.samplers.check)."""

    name: str
    params: tuple[tuple[str, float], ...]
    domain: str
    samples: int
    case_id: int
    measurements: tuple[str, ...] = ("chi_square",)
    adapter: str | None = None   # "mitsuba": a renderer's sampler (``spec`` holds its keys as JSON)
    spec: str = ""

    @property
    def label(self) -> str:
        if self.adapter:
            return f"{self.adapter}:{self.name}"
        return self.name + ("(" + ", ".join(f"{k}={v:g}" for k, v in self.params) + ")"
                            if self.params else "")


@dataclass(frozen=True)
class RenderCase:
    """A renderer configuration (harness.adapters) measured from replica renders.

    ``spec`` holds the adapter's keys (scene, integrator, points, ...); ``spp`` is the budget
    (samples or frames per pixel) of each of the bias test's ``replicas`` renders; ``budgets``
    those of the convergence renders; a scene without an exact answer is compared with
    ``reference_parts`` independent renders of ``reference_spp`` in total.
    """

    adapter: str
    spec: tuple[tuple[str, Any], ...]
    case_id: int
    spp: int
    replicas: int
    budgets: tuple[int, ...]
    reference_spp: int
    reference_parts: int
    measurements: tuple[str, ...]
    expect: str = "unbiased"           # or "biased": the bias test must then reject

    @property
    def scene(self) -> str:
        return f"{self.adapter}:{dict(self.spec).get('scene', '?')}"

    @property
    def label(self) -> str:
        """The configuration without its scene, e.g. "integrator=path, variant=scalar_rgb"."""
        return ", ".join(f"{k}={v}" for k, v in self.spec if k != "scene") or self.adapter


@dataclass(frozen=True)
class Case:
    integrand: str
    technique: str
    samples: int
    case_id: int  # position in the suite: keys the case's random streams
    measurements: tuple[str, ...] = MEASUREMENTS
    target: float | None = None      # stop the bias test's sample doubling at this CI half-width
    max_samples: int | None = None   # ... or at this many samples

    @property
    def looks(self) -> int:
        """How many budgets a target may try: samples, 2 samples, ... <= max_samples."""
        if self.target is None or self.max_samples is None:
            return 1
        k = 1
        while self.samples << k <= self.max_samples:
            k += 1
        return k


@dataclass(frozen=True)
class Suite:
    name: str
    path: Path
    seed: int
    samples: int
    threads: int | None
    cases: tuple[Case, ...]
    alpha: float = 0.01
    batches: int = 64
    replicas: int = 32
    budgets: tuple[int, ...] | None = None
    samplers: tuple[SamplerCase, ...] = ()
    renders: tuple[RenderCase, ...] = ()

    @property
    def file_name(self) -> str:
        """The name as a safe file name (results/<file_name>.sqlite): letters, digits, '.', '_'
        and '-' only, never a path (``../../x`` becomes ``x``)."""
        return re.sub(r"[^A-Za-z0-9._-]+", "_", self.name).strip("._") or "suite"


_RENDER_KEYS = {"adapter": str, "spp": int, "replicas": int, "budgets": list, "reference_spp": int,
                "reference_parts": int, "measurements": list, "expect": str}
_SUITE_KEYS = {"name": str, "seed": int, "samples": int, "threads": int, "alpha": float, "batches": int,
               "replicas": int, "budgets": list, "measurements": list}
_SAMPLER_KEYS = {"name": str, "params": dict, "domain": str, "samples": int, "measurements": list}
_CASE_KEYS = {"integrand": str, "techniques": (str, list), "samples": int, "measurements": list,
              "target": float, "max_samples": int}


def load_suite(path: str | Path) -> Suite:
    """Parse and validate a suite file; raises SuiteError naming file, line and key."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise SuiteError(f"{path}: cannot read suite file: {e.strerror}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise SuiteError(f"{path}: not UTF-8 text: byte {raw[e.start]:#04x} at offset {e.start}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SuiteError(f"{path}: not valid TOML: {e}") from None
    where = Locator(path, text)
    _check_tables(data, where)
    head = data.get("suite", {})
    _check_keys(head, _SUITE_KEYS, where, "suite")
    samples = head.get("samples", 1_000_000)
    _positive(samples, where, "suite", "samples")
    seed = head.get("seed", 0)
    if not 0 <= seed < 2**64:
        raise SuiteError(where.at("suite", "seed", f"expected an integer in [0, 2**64), got {seed}"))
    threads = head.get("threads")
    if threads is not None and threads < 0:
        raise SuiteError(where.at("suite", "threads",
                                  f"expected an integer >= 0 (0: all cores), got {threads}"))
    alpha = head.get("alpha", 0.01)
    if not 0 < alpha < 1:
        raise SuiteError(where.at("suite", "alpha", f"expected a false-alarm rate in (0, 1), got {alpha}"))
    batches = head.get("batches", 64)
    if not 8 <= batches <= samples:
        raise SuiteError(where.at("suite", "batches",
                                  f"expected an integer in [8, samples = {samples}], got {batches}"))
    replicas = head.get("replicas", 32)
    if replicas < 2:
        raise SuiteError(where.at("suite", "replicas", f"expected at least 2 replicas, got {replicas}"))
    budgets = head.get("budgets")
    if budgets is not None:
        if len(budgets) < 3 or any(isinstance(b, bool) or not isinstance(b, int) or b <= 0 for b in budgets):
            raise SuiteError(where.at("suite", "budgets",
                                      f"expected at least 3 positive integer budgets, got {budgets}"))
        budgets = tuple(sorted(set(budgets)))

    measurements = _measurements(head.get("measurements", list(MEASUREMENTS)), where, "suite")

    raw_cases = data.get("case", [])
    if not isinstance(raw_cases, list) or (not raw_cases and not data.get("sampler")
                                           and not data.get("render")):
        raise SuiteError(where.at(None, "case",
                                  "expected at least one [[case]], [[sampler]] or [[render]] table"))
    cases: list[Case] = []
    for i, c in enumerate(raw_cases):
        table = ("case", i)
        _check_keys(c, _CASE_KEYS, where, table)
        if "integrand" not in c:
            raise SuiteError(where.at(table, None, "missing key 'integrand' (a catalogue name or \"all\")"))
        names = [f.name for f in rest.catalogue()] if c["integrand"] == "all" else [c["integrand"]]
        case_measurements = (_measurements(c["measurements"], where, table) if "measurements" in c
                             else measurements)
        case_samples = c.get("samples", samples)
        _positive(case_samples, where, table, "samples")
        if case_samples < batches:
            raise SuiteError(where.at(table if "samples" in c else "suite", "samples",
                                      f"expected at least batches = {batches} samples, got {case_samples}"))
        for name in names:
            try:
                known = rest.techniques(name)
            except ValueError as e:
                raise SuiteError(where.at(table, "integrand", str(e))) from None
            wanted = c.get("techniques", "all")
            if wanted == "all":
                wanted = list(known)
            elif isinstance(wanted, str):
                wanted = [wanted]
            if not wanted:
                raise SuiteError(where.at(table, "techniques", "expected \"all\", a technique or a non-empty "
                                                               "list of techniques, got []"))
            for t in wanted:
                if not isinstance(t, str) or t not in known:
                    raise SuiteError(where.at(table, "techniques",
                                              f"unknown technique {t!r} for integrand {name!r}; "
                                              f"expected one of: {', '.join(known)}"))
                target, max_samples = _target(c, case_samples, rest.integrand(name), where, table)
                cases.append(Case(name, t, case_samples, len(cases), case_measurements, target, max_samples))
    samplers = _samplers(data.get("sampler", []), samples, len(cases), where)
    renders = _renders(data.get("render", []), measurements, where)
    return Suite(head.get("name", path.stem), path, seed, samples, threads or None, tuple(cases),
                 float(alpha), batches, replicas, budgets, samplers, renders)


def _renders(raw: list[dict[str, Any]], measurements: tuple[str, ...],
             where: Locator) -> tuple[RenderCase, ...]:
    """[[render]] tables: runner keys (_RENDER_KEYS) plus the adapter's own keys; a list value
    of an adapter key makes one case per element (cross product over such keys)."""
    import itertools

    from harness.adapters import ADAPTERS, renderer

    out: list[RenderCase] = []
    for i, c in enumerate(raw):
        table = ("render", i)
        runner_keys = {k: v for k, v in c.items() if k in _RENDER_KEYS}
        _check_keys(runner_keys, _RENDER_KEYS, where, table)
        if "adapter" not in c:
            raise SuiteError(where.at(table, None,
                                      f"missing key 'adapter' (one of: {', '.join(ADAPTERS)})"))
        adapter = c["adapter"]
        if adapter not in ADAPTERS:
            raise SuiteError(where.at(table, "adapter",
                                      f"expected one of: {', '.join(ADAPTERS)}, got {adapter!r}"))
        spp = c.get("spp", 64)
        _positive(spp, where, table, "spp")
        replicas = c.get("replicas", 16)
        if replicas < 4:
            raise SuiteError(where.at(table, "replicas", f"expected at least 4 replicas, got {replicas}"))
        ms = _measurements(c["measurements"], where, table) if "measurements" in c else measurements
        budgets = c.get("budgets", [max(1, spp >> k) for k in (6, 4, 2, 0)])
        if any(isinstance(b, bool) or not isinstance(b, int) or b <= 0 for b in budgets):
            raise SuiteError(where.at(table, "budgets", f"expected positive integer budgets, got {budgets}"))
        if len(set(budgets)) < 3 and set(ms) & {"convergence", "error_vs_time", "efficiency"}:
            key = "budgets" if "budgets" in c else "spp"
            raise SuiteError(where.at(table, key, f"expected at least 3 distinct budgets for "
                                      f"{', '.join(ms)}, got {sorted(set(budgets))}"
                                      + ("" if "budgets" in c else " (give budgets)")))
        budgets = tuple(sorted(set(budgets)))
        parts = c.get("reference_parts", 8)
        if parts < 2:
            raise SuiteError(where.at(table, "reference_parts",
                                      f"expected at least 2 independent parts, got {parts}"))
        ref_spp = c.get("reference_spp", 64 * max(budgets[-1], spp))
        if ref_spp < parts or ref_spp % parts:
            raise SuiteError(where.at(table, "reference_spp", f"expected a multiple of reference_parts = "
                                      f"{parts}, got {ref_spp}"))
        expect = c.get("expect", "unbiased")
        if expect not in ("unbiased", "biased"):
            raise SuiteError(where.at(table, "expect",
                                      f"expected \"unbiased\" or \"biased\", got {expect!r}"))
        spec = {k: v for k, v in c.items() if k not in _RENDER_KEYS}
        axes = [k for k, v in spec.items() if isinstance(v, list)]
        for k in axes:
            if not spec[k]:
                raise SuiteError(where.at(table, k, "expected a value or a non-empty list of values, got []"))
        for values in itertools.product(*(spec[k] for k in axes)):
            one = {**spec, **dict(zip(axes, values))}
            try:
                renderer(adapter, one)
            except ValueError as e:
                msg = str(e)
                key = _named_key(msg, one)
                if key is not None and msg.startswith(f"'{key}'"):
                    msg = msg[len(key) + 2:].lstrip(": ")
                raise SuiteError(where.at(table, key, msg)) from None
            out.append(RenderCase(adapter, tuple(sorted(one.items())), len(out), spp, replicas, budgets,
                                  ref_spp, parts, ms, expect))
    return tuple(out)


def _samplers(raw: list[dict[str, Any]], samples: int, first_id: int,
              where: Locator) -> tuple[SamplerCase, ...]:
    from harness.samplers import DOMAINS

    out = []
    registry = {s["name"]: s for s in rest.samplers()}
    for i, c in enumerate(raw):
        table = ("sampler", i)
        if "adapter" in c:
            out.append(_adapter_sampler(c, samples, first_id + i, where, table))
            continue
        _check_keys(c, _SAMPLER_KEYS, where, table)
        if "name" not in c:
            raise SuiteError(where.at(table, None, "missing key 'name' (a catalogue sampler, see "
                                                   "`harness list`) or 'adapter'"))
        name = c["name"]
        if name not in registry:
            raise SuiteError(where.at(table, "name", f"unknown sampler {name!r}; expected one of: "
                                      f"{', '.join(registry)}"))
        if registry[name]["needs_table"]:
            raise SuiteError(where.at(table, "name",
                                      f"sampler {name!r} needs a table of values: test it from Python"))
        params = c.get("params", {})
        try:
            rest.sampler(name, **params)
        except (ValueError, TypeError) as e:
            raise SuiteError(where.at(table, "params", str(e))) from None
        domain = c.get("domain", registry[name]["domain"])
        if domain not in DOMAINS:
            raise SuiteError(where.at(table, "domain",
                                      f"expected one of: {', '.join(DOMAINS)}, got {domain!r}"))
        n = c.get("samples", samples)
        if n < 1000:
            raise SuiteError(where.at(table, "samples", f"expected at least 1000 samples, got {n}"))
        ms = c.get("measurements", ["chi_square"])
        for m in ms:
            if m == "weight":
                raise SuiteError(where.at(table, "measurements",
                                          "'weight' (sample weight == eval/pdf) applies to "
                                          "renderer samplers ([[sampler]] with adapter = \"mitsuba\")"))
            if m not in SAMPLER_MEASUREMENTS:
                raise SuiteError(where.at(table, "measurements", f"unknown sampler measurement {m!r}; "
                                          f"expected some of: {', '.join(SAMPLER_MEASUREMENTS)}"))
        out.append(SamplerCase(name, tuple(sorted((k, float(v)) for k, v in params.items())), domain, n,
                               first_id + i, tuple(dict.fromkeys(ms)) or ("chi_square",)))
    return tuple(out)


_ADAPTER_SAMPLER_KEYS = {"adapter": str, "plugin": dict, "wi": (int, float, list), "variant": str,
                         "samples": int, "measurements": list}


def _adapter_sampler(c: dict[str, Any], samples: int, case_id: int, where: Locator,
                     table: Any) -> SamplerCase:
    """A renderer's sampler (a Mitsuba BSDF, microfacet distribution or environment map):
    chi-square with failed samples accounted for, and the weight == eval/pdf check."""
    import json

    _check_keys(c, _ADAPTER_SAMPLER_KEYS, where, table)
    if c["adapter"] != "mitsuba":
        raise SuiteError(where.at(table, "adapter", f"expected \"mitsuba\" (samplers of other adapters are "
                                  f"not supported), got {c['adapter']!r}"))
    from harness.adapters.mitsuba.samplers import make_sampler

    spec = {k: c[k] for k in ("plugin", "wi", "variant") if k in c}
    try:
        s = make_sampler(spec)
    except (ValueError, TypeError, RuntimeError) as e:
        msg = str(e)
        raise SuiteError(where.at(table, _named_key(msg, spec) or "plugin", msg.splitlines()[0])) from None
    n = c.get("samples", samples)
    if n < 1000:
        raise SuiteError(where.at(table, "samples", f"expected at least 1000 samples, got {n}"))
    ms = c.get("measurements", ["chi_square"] + (["weight"] if s.kind != "microfacet" else []))
    for m in ms:
        if m not in ("chi_square", "weight"):
            raise SuiteError(where.at(table, "measurements",
                                      f"expected some of: chi_square, weight for a renderer's sampler (it "
                                      f"may fail to produce samples, which MCMC cannot use), got {m!r}"))
    if "weight" in ms and s.kind == "microfacet":
        raise SuiteError(where.at(table, "measurements",
                                  "a microfacet distribution returns no weight to check"))
    label = s.name if spec.get("variant", "llvm_ad_rgb") == "llvm_ad_rgb" else f"{s.name} [{spec['variant']}]"
    return SamplerCase(label, (), s.domain, n, case_id, tuple(dict.fromkeys(ms)) or ("chi_square",),
                       "mitsuba", json.dumps(spec, sort_keys=True))


def _named_key(message: str, keys: Any) -> str | None:
    """The key an adapter's error message names first (quoted as 'key'), or None."""
    named = sorted((message.find(f"'{k}'"), k) for k in keys if f"'{k}'" in message)
    return named[0][1] if named else None


def _check_tables(data: dict[str, Any], where: Locator) -> None:
    """The document's shape: at most a [suite] table and arrays of [[case]], [[sampler]] and
    [[render]] tables, nothing else."""
    for key, value in data.items():
        if key == "suite":
            if not isinstance(value, dict):
                raise SuiteError(where.at(None, "suite", f"expected a [suite] table, got {value!r}"))
        elif key in ("case", "sampler", "render"):
            if isinstance(value, dict):
                raise SuiteError(where.at(None, key, f"expected [[{key}]] tables (an array of tables), "
                                                     f"got a single [{key}] table"))
            if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
                raise SuiteError(where.at(None, key, f"expected [[{key}]] tables, got {value!r}"))
        else:
            raise SuiteError(where.at(None, key, f"unknown table {key!r}; expected [suite], [[case]], "
                                                 "[[sampler]] and [[render]] tables"))


def _check_keys(table: dict[str, Any], spec: dict[str, Any], where: Locator, name: Any) -> None:
    for key, value in table.items():
        if key not in spec:
            raise SuiteError(where.at(name, key, f"unknown key {key!r}; expected one of: {', '.join(spec)}"))
        want = (int, float) if spec[key] is float else spec[key]
        if isinstance(value, bool) or not isinstance(value, want):
            kinds = " or ".join(t.__name__ for t in (want if isinstance(want, tuple) else (want,)))
            raise SuiteError(where.at(name, key, f"expected {kinds}, got {type(value).__name__} {value!r}"))


def _target(c: dict[str, Any], samples: int, f: Any, where: Locator,
            table: Any) -> tuple[float | None, int | None]:
    """A precision target: the half-width of the bias test's interval at which to stop doubling
    the samples, and the most samples to try."""
    if "target" not in c:
        if "max_samples" in c:
            raise SuiteError(where.at(table, "max_samples", "max_samples only applies with a target"))
        return None, None
    target = float(c["target"])
    floor = 16 * 2.0**-52 * abs(f.reference)
    if not target > floor:
        raise SuiteError(where.at(table, "target",
                                  f"no budget can reach a half-width of {target:g}: it must be > 0 "
                                  f"and above the rounding floor {floor:.3g} of integrand {f.name!r}"))
    if "max_samples" not in c:
        raise SuiteError(where.at(table, "target", "a target needs max_samples, the most samples to try"))
    if c["max_samples"] < samples:
        raise SuiteError(where.at(table, "max_samples",
                                  f"expected at least samples = {samples}, got {c['max_samples']}"))
    return target, c["max_samples"]


def _measurements(names: list[Any], where: Locator, table: Any) -> tuple[str, ...]:
    for m in names:
        if m not in MEASUREMENTS:
            hint = " (sampler checks go in [[sampler]] tables)" if m in SAMPLER_MEASUREMENTS else ""
            raise SuiteError(where.at(table, "measurements", f"unknown measurement {m!r}; expected some of: "
                                      f"{', '.join(MEASUREMENTS)}{hint}"))
    if not names:
        raise SuiteError(where.at(table, "measurements", "expected at least one measurement"))
    return tuple(dict.fromkeys(names))


def _positive(v: int, where: Locator, table: Any, key: str) -> None:
    if v <= 0:
        raise SuiteError(where.at(table, key, f"expected a budget > 0 samples, got {v}"))
