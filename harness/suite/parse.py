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
    label = "plain"           # one integrand and one technique only: the name tables and baselines use
    baseline = "other"        # the case (label, or integrand/technique) its efficiency is compared with
                              #   (default: uniform MC on the same integrand)
    xfail = "known finding"   # on any [[case]], [[sampler]] or [[render]]: its failure is expected
                              #   (shown as xfailed); the run fails if it passes (strict)

    [[case]]                  # a team's own estimator (harness.stats.estimator.Contributions)
    estimator = "myest:nee"   # required: module:attr or path/file.py:attr, found next to the suite
                              #   file first; a callable u (N, dim) -> contributions (N,)
    dim = 2                   # required: canonical uniforms per sample
    reference = 0.349         # required: the exact value, a number or "module:attr"
    points = "random"         # random (default), stratified or sobol
    label = "nee"             # default: the callable's name
    # samples, measurements, target, max_samples, baseline and xfail as above; a change of the
    # module's source invalidates the case's stored units

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

import hashlib
import math
import tomllib
from pathlib import Path
from typing import Any

import reference_estimators as rest

from harness.stats.estimator import POINT_SETS, Contributions
from harness.suite import parse_renders, parse_samplers
from harness.suite.locate import Locator
from harness.suite.model import MEASUREMENTS, Case, RenderCase, SamplerCase, Suite, SuiteError
from harness.suite.plan import (
    MAX_TAIL_BATCH,
    MAX_UNITS,
    UNIT_CHUNKS,
    bias_budget,
    render_unit_count,
    unit_count,
)
from harness.suite.rules import check_keys, measurements, positive, xfail_reason
from harness.usercode import UserCodeError, load_attr, source_fingerprint

__all__ = ["Suite", "Case", "SamplerCase", "RenderCase", "SuiteError", "MEASUREMENTS", "load_suite",
           "loads_suite"]


_SUITE_KEYS = {"name": str, "seed": int, "samples": int, "threads": int, "alpha": float, "batches": int,
               "replicas": int, "budgets": list, "measurements": list}
_CASE_KEYS = {"integrand": str, "techniques": (str, list), "samples": int, "measurements": list,
              "target": float, "max_samples": int, "label": str, "baseline": str, "xfail": str}
_USER_CASE_KEYS = {"estimator": str, "dim": int, "reference": (int, float, str), "points": str,
                   **{k: v for k, v in _CASE_KEYS.items() if k not in ("integrand", "techniques")}}
#: The most uniforms per sample a team's estimator takes: each call gets rest.CHUNK_SIZE rows of
#: them as float64 (512 MB a call at this many)
MAX_DIM = 1024


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
    return loads_suite(text, path=path)


def loads_suite(text: str, *, path: str | Path = "suite.toml") -> Suite:
    """A suite from TOML text (e.g. built in Python): ``path`` names it in errors, gives its
    default name (the stem), and its folder is where a user's code is loaded from."""
    path = Path(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SuiteError(f"{path}: not valid TOML: {e}") from None
    where = Locator(path, text)
    _check_tables(data, where)
    head = data.get("suite", {})
    check_keys(head, _SUITE_KEYS, where, "suite")
    samples = head.get("samples", 1_000_000)
    positive(samples, where, "suite", "samples")
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

    suite_measurements = measurements(head.get("measurements", list(MEASUREMENTS)), where, "suite")

    raw_cases = data.get("case", [])
    if not isinstance(raw_cases, list) or (not raw_cases and not data.get("sampler")
                                           and not data.get("render")):
        raise SuiteError(where.at(None, "case",
                                  "expected at least one [[case]], [[sampler]] or [[render]] table"))
    cases, tables = _cases(raw_cases, samples, batches, suite_measurements, path.parent, where)
    samplers = parse_samplers.samplers(data.get("sampler", []), samples, len(cases), path.parent, where)
    renders = parse_renders.renders(data.get("render", []), suite_measurements, path.parent, where)
    suite = Suite(head.get("name", path.stem), path, seed, samples, threads or None, tuple(cases),
                  float(alpha), batches, replicas, budgets, samplers, renders,
                  hashlib.sha256(text.encode()).hexdigest())
    _check_size(suite, [raw_cases[t[1]] for t in tables], tables, where)
    return suite


def _check_size(suite: Suite, raw: list[dict[str, Any]], tables: list[Any], where: Locator) -> None:
    """Refuses a suite whose cases need more than MAX_UNITS work units (counted, not made),
    naming the case that needs the most and the key that sets its budget, or a bias test whose
    batch (held whole for the tail index) exceeds MAX_TAIL_BATCH contributions."""
    for case, table, r in zip(suite.cases, tables, raw):
        batch = bias_budget(suite, case, case.looks - 1)
        if "bias" in case.measurements and batch > MAX_TAIL_BATCH:
            key = "max_samples" if case.max_samples else "samples"
            raise SuiteError(where.at(table if key in r else "suite", key,
                                      f"{case.name}: the bias test's tail sample holds one batch of "
                                      f"{batch:,} contributions in memory; at most {MAX_TAIL_BATCH:,} "
                                      "(2 GiB): raise batches or lower the samples"))
    counts = [unit_count(suite, c) for c in suite.cases]
    renders = [render_unit_count(rc) for rc in suite.renders]
    total = sum(counts) + sum(renders) + sum(len(sc.measurements) for sc in suite.samplers)
    if total <= MAX_UNITS:
        return
    limit = (f"({total:,} in the suite); a suite may plan at most {MAX_UNITS:,} (each is held in memory "
             "and stored as a database row)")
    if renders and max(renders) >= max(counts, default=0):
        rc = suite.renders[max(range(len(renders)), key=renders.__getitem__)]
        raise SuiteError(where.at(None, "render", f"{rc.scene} {rc.label}: {max(renders):,} renders {limit}: "
                                                  "lower its replicas or budgets"))
    i = max(range(len(counts)), key=counts.__getitem__)
    case, table = suite.cases[i], tables[i]
    key = "max_samples" if case.max_samples else "samples"
    per_unit = UNIT_CHUNKS * rest.CHUNK_SIZE
    raise SuiteError(where.at(table if key in raw[i] else "suite", key,
                              f"{case.name}: {getattr(case, key):.3g} samples need {counts[i]:,} work "
                              f"units of up to {per_unit:,} samples {limit}: lower the samples, batches or "
                              "replicas"))


def _cases(raw: list[dict[str, Any]], samples: int, batches: int, suite_measurements: tuple[str, ...],
           base: Path, where: Locator) -> tuple[tuple[Case, ...], list[Any]]:
    """[[case]] tables: catalogue integrand x techniques (one case per pair) or a user's
    estimator; then every ``baseline`` must name the label of another case.  Returns the
    cases and each one's table, ("case", index)."""
    cases: list[Case] = []
    tables: list[Any] = []
    for i, c in enumerate(raw):
        table = ("case", i)
        if "estimator" in c:
            check_keys(c, _USER_CASE_KEYS, where, table)
        else:
            check_keys(c, _CASE_KEYS, where, table)
        if "integrand" not in c and "estimator" not in c:
            raise SuiteError(where.at(table, None, "missing key 'integrand' (a catalogue name or \"all\") "
                                                   "or 'estimator' (module:attr of your own)"))
        case_measurements = (measurements(c["measurements"], where, table) if "measurements" in c
                             else suite_measurements)
        case_samples = c.get("samples", samples)
        positive(case_samples, where, table, "samples")
        if case_samples < batches:
            raise SuiteError(where.at(table if "samples" in c else "suite", "samples",
                                      f"expected at least batches = {batches} samples, got {case_samples}"))
        common = {"label": c.get("label", ""), "baseline": c.get("baseline", ""),
                  "xfail": xfail_reason(c, where, table)}
        if "estimator" in c:
            user = user_estimator(c, base, where, table)
            target, max_samples = _target(c, case_samples, user.reference, user.name, where, table)
            cases.append(Case(user.name, user.label, case_samples, len(cases), case_measurements, target,
                              max_samples, **{**common, "label": user.label}, estimator=user.name,
                              dim=user.dim, reference=user.reference, points=user.points,
                              source=source_fingerprint(user.function)))
            tables.append(table)
            continue
        names = [f.name for f in rest.catalogue()] if c["integrand"] == "all" else [c["integrand"]]
        if common["label"] and (len(names) > 1 or isinstance(c.get("techniques", "all"), list)
                                or c.get("techniques", "all") == "all"):
            raise SuiteError(where.at(table, "label", "a label names one case: give one integrand and one "
                                                      "technique"))
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
                f = rest.integrand(name)
                target, max_samples = _target(c, case_samples, f.reference, f.name, where, table)
                cases.append(Case(name, t, case_samples, len(cases), case_measurements, target, max_samples,
                                  **common))
                tables.append(table)
    _check_labels(cases, tables, where)
    return tuple(cases), tables


def user_estimator(c: dict[str, Any], base: Path, where: Locator, table: Any) -> Contributions:
    """A [[case]] table's own estimator, loaded (next to the suite file first) and called once
    on 4 rows of uniforms, so a wrong signature or output shape is reported here, with the line."""
    target = c["estimator"]
    try:
        fn = load_attr(target, base=base)
    except UserCodeError as e:
        raise SuiteError(where.at(table, "estimator", str(e))) from None
    if not callable(fn):
        raise SuiteError(where.at(table, "estimator", f"{target!r} is a {type(fn).__name__}; expected a "
                                                      "callable u (N, dim) -> contributions (N,)"))
    if "dim" not in c:
        raise SuiteError(where.at(table, None, "missing key 'dim' (canonical uniforms per sample of the "
                                               "estimator)"))
    if not 1 <= c["dim"] <= MAX_DIM:
        raise SuiteError(where.at(table, "dim", f"expected a positive number of uniforms per sample, at most "
                                                f"{MAX_DIM} (each call gets {rest.CHUNK_SIZE} rows of them), "
                                                f"got {c['dim']}"))
    if "reference" not in c:
        raise SuiteError(where.at(table, None, "missing key 'reference' (the exact value: a number or "
                                               "\"module:attr\")"))
    reference = c["reference"]
    if isinstance(reference, str):
        try:
            reference = load_attr(reference, base=base)
        except UserCodeError as e:
            raise SuiteError(where.at(table, "reference", str(e))) from None
    if isinstance(reference, bool) or not isinstance(reference, (int, float)) or not math.isfinite(reference):
        raise SuiteError(where.at(table, "reference", f"expected a finite number, got {reference!r}"))
    points = c.get("points", "random")
    if points not in POINT_SETS:
        raise SuiteError(where.at(table, "points",
                                  f"expected one of: {', '.join(POINT_SETS)}, got {points!r}"))
    user = Contributions(fn, c["dim"], float(reference), c.get("label", ""), points, name=target)
    try:   # the case's own point set (Sobol' points have at most 256 dimensions)
        probe = rest.points(4, user.dim, points, seed=0)
    except ValueError as e:
        raise SuiteError(where.at(table, "dim", str(e))) from None
    try:
        user(probe)
    except UserCodeError as e:
        raise SuiteError(where.at(table, "estimator", str(e))) from None
    return user


def _check_labels(cases: list[Case], tables: list[Any], where: Locator) -> None:
    """Names (labels, or integrand/technique) are unique; a baseline names another case, and
    both measure efficiency.  ``tables[k]``: the [[case]] table case k came from."""
    by_name: dict[str, list[Case]] = {}
    for case in cases:
        by_name.setdefault(case.name, []).append(case)
    for case in cases:
        if case.label and len(by_name[case.name]) > 1:
            raise SuiteError(where.at(tables[case.case_id], "label",
                                      f"two cases are called {case.name!r}; give each its own label"))
    for case in cases:
        if not case.baseline:
            continue
        table = tables[case.case_id]
        found = [c for c in by_name.get(case.baseline, []) if c is not case]
        if len(found) != 1:
            others = ", ".join(n for n, cs in by_name.items() if len(cs) == 1 and n != case.name)
            raise SuiteError(where.at(table, "baseline", f"expected the name of one other case (a label, or "
                                      f"integrand/technique), one of: {others}; got {case.baseline!r}"
                                      + (" (more than one case has it: give it a label)" if found else "")))
        for c in (case, found[0]):
            if "efficiency" not in c.measurements:
                raise SuiteError(where.at(table, "baseline", f"case {c.name!r} does not measure efficiency"))


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


def _target(c: dict[str, Any], samples: int, reference: float, name: str, where: Locator,
            table: Any) -> tuple[float | None, int | None]:
    """A precision target: the half-width of the bias test's interval at which to stop doubling
    the samples, and the most samples to try."""
    if "target" not in c:
        if "max_samples" in c:
            raise SuiteError(where.at(table, "max_samples", "max_samples only applies with a target"))
        return None, None
    target = float(c["target"])
    floor = 16 * 2.0**-52 * abs(reference)
    if not target > floor:
        raise SuiteError(where.at(table, "target",
                                  f"no budget can reach a half-width of {target:g}: it must be > 0 "
                                  f"and above the rounding floor {floor:.3g} of {name!r}"))
    if "max_samples" not in c:
        raise SuiteError(where.at(table, "target", "a target needs max_samples, the most samples to try"))
    if c["max_samples"] < samples:
        raise SuiteError(where.at(table, "max_samples",
                                  f"expected at least samples = {samples}, got {c['max_samples']}"))
    return target, c["max_samples"]
