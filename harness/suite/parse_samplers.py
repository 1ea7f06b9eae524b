"""[[sampler]] tables: catalogue samplers and renderers' samplers checked against their pdfs."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import reference_estimators as rest

from harness.samplers.calls import MAX_SAMPLES, MAX_UNIFORMS
from harness.suite.locate import Locator
from harness.suite.model import SAMPLER_MEASUREMENTS, SamplerCase, SuiteError
from harness.suite.rules import check_keys, named_key, xfail_reason
from harness.usercode import UserCodeError, load_attr, source_fingerprint

__all__ = ["samplers"]

_SAMPLER_KEYS = {"name": str, "params": dict, "domain": str, "samples": int, "measurements": list,
                 "xfail": str}


_USER_SAMPLER_KEYS = {"sampler": str, "params": dict, "domain": str, "total": float, "samples": int,
                      "measurements": list, "xfail": str}


def samplers(raw: list[dict[str, Any]], samples: int, first_id: int, base: Path,
             where: Locator) -> tuple[SamplerCase, ...]:
    """[[sampler]] tables: a catalogue sampler (``name``), a user's (``sampler``, loaded next
    to the suite file first) or a renderer's (``adapter``)."""
    from harness.samplers import DOMAINS

    out = []
    registry = {s["name"]: s for s in rest.samplers()}
    for i, c in enumerate(raw):
        table = ("sampler", i)
        if "adapter" in c:
            out.append(_adapter_sampler(c, samples, first_id + i, where, table))
            continue
        if "sampler" in c:
            out.append(_user_sampler(c, samples, first_id + i, base, where, table))
            continue
        check_keys(c, _SAMPLER_KEYS, where, table)
        if "name" not in c:
            raise SuiteError(where.at(table, None, "missing key 'name' (a catalogue sampler, see "
                                                   "`harness list`), 'sampler' (module:attr of your own) "
                                                   "or 'adapter'"))
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
        n = _samples(c, samples, where, table)
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
                               first_id + i, tuple(dict.fromkeys(ms)) or ("chi_square",),
                               xfail=xfail_reason(c, where, table)))
    return tuple(out)


def _user_sampler(c: dict[str, Any], samples: int, case_id: int, base: Path, where: Locator,
                  table: Any) -> SamplerCase:
    """A team's own sampler (harness.samplers.user): loaded, built with ``params`` if it is a
    factory, and checked for sample/pdf and its domain here, so mistakes name the line."""
    from harness.samplers import DOMAINS
    from harness.samplers.domains import checked_breaks
    from harness.samplers.user import resolve_sampler

    check_keys(c, _USER_SAMPLER_KEYS, where, table)
    target = c["sampler"]
    params = c.get("params", {})
    try:
        obj = load_attr(target, base=base)
        user = resolve_sampler(obj, params, name=target)
    except UserCodeError as e:
        raise SuiteError(where.at(table, "params" if "params" in c and "raised" in str(e) else "sampler",
                                  str(e))) from None
    domain = c.get("domain", user.domain)
    if domain is None:
        raise SuiteError(where.at(table, None, f"missing key 'domain' ({target} has no domain attribute); "
                                               f"expected one of: {', '.join(DOMAINS)}"))
    if domain not in DOMAINS:
        raise SuiteError(where.at(table, "domain", f"expected one of: {', '.join(DOMAINS)}, got {domain!r}"))
    try:    # the sampler's own pole and breaks (harness.samplers.user), on this domain
        checked_breaks(user.breaks, user.check_domain(domain))
    except ValueError as e:
        raise SuiteError(where.at(table, "sampler", f"{target}: {e}")) from None
    total = float(c["total"]) if "total" in c else user.total
    if total is not None and not 0 < total <= 1:
        raise SuiteError(where.at(table, "total", f"expected the pdf's integral, in (0, 1], got {total}"))
    n = _samples(c, samples, where, table)
    if user.udim is not None and n * user.udim > MAX_UNIFORMS:   # the check would refuse it in the run
        raise SuiteError(where.at(table, "samples" if "samples" in c else "sampler",
                                  f"{n:,} samples of {user.udim} uniforms each ({target}.udim): a check "
                                  f"holds at most {MAX_UNIFORMS:,} uniforms in memory; take fewer samples"))
    ms = c.get("measurements", ["chi_square"])
    for m in ms:
        if m not in ("chi_square", "mcmc"):
            raise SuiteError(where.at(table, "measurements", f"expected some of: chi_square, mcmc for a "
                                      f"sampler of your own, got {m!r}"))
    if "mcmc" in ms and total is not None:
        raise SuiteError(where.at(table, "measurements", "'mcmc' needs a sampler that always produces a "
                                  "sample (total = 1): the MCMC cross-check compares two full samples"))
    source = source_fingerprint(user.sample) + source_fingerprint(obj)
    return SamplerCase(target, tuple(sorted(params.items())), domain, n, case_id,
                       tuple(dict.fromkeys(ms)) or ("chi_square",), xfail=xfail_reason(c, where, table),
                       target=target, source=source, total=total, udim=user.udim)


def _samples(c: dict[str, Any], samples: int, where: Locator, table: Any) -> int:
    """A sampler table's ``samples`` (default: the suite's), from 1000 to the check's
    MAX_SAMPLES."""
    n = c.get("samples", samples)
    if not 1000 <= n <= MAX_SAMPLES:
        raise SuiteError(where.at(table if "samples" in c else "suite", "samples",
                                  f"expected 1000 to {MAX_SAMPLES:,} samples (a check holds its samples in "
                                  f"memory), got {n:,}"))
    return n


_ADAPTER_SAMPLER_KEYS = {"adapter": str, "plugin": dict, "wi": (int, float, list), "ref": list,
                         "texel_breaks": bool, "variant": str, "samples": int, "measurements": list,
                         "xfail": str}


def _adapter_sampler(c: dict[str, Any], samples: int, case_id: int, where: Locator,
                     table: Any) -> SamplerCase:
    """A renderer's sampler (a Mitsuba BSDF, phase function, microfacet distribution,
    environment map, or an area light on a shape sampled from the point ``ref``): chi-square
    with failed samples accounted for and the reported pdf checked, and the weight == eval/pdf
    check."""
    check_keys(c, _ADAPTER_SAMPLER_KEYS, where, table)
    if c["adapter"] != "mitsuba":
        raise SuiteError(where.at(table, "adapter", f"expected \"mitsuba\" (samplers of other adapters are "
                                  f"not supported), got {c['adapter']!r}"))
    from harness.adapters.mitsuba.samplers import make_sampler

    spec = {k: c[k] for k in ("plugin", "wi", "ref", "texel_breaks", "variant") if k in c}
    try:
        s = make_sampler(spec)
    except (ValueError, TypeError, RuntimeError) as e:
        msg = str(e)
        raise SuiteError(where.at(table, named_key(msg, spec) or "plugin", msg.splitlines()[0])) from None
    n = _samples(c, samples, where, table)
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
                       "mitsuba", json.dumps(spec, sort_keys=True), xfail_reason(c, where, table))
