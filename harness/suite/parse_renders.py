"""[[render]] tables: renderer configurations (harness.adapters) measured from replica renders."""
from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

from harness.suite.locate import Locator
from harness.suite.model import RenderCase, SuiteError
from harness.suite.rules import check_keys, measurements, named_key, positive, xfail_reason

__all__ = ["RENDER_KEYS", "renders"]

RENDER_KEYS = {"adapter": str, "spp": int, "replicas": int, "budgets": list, "reference_spp": int,
               "reference_parts": int, "reference": dict, "measurements": list, "expect": str, "xfail": str}


def renders(raw: list[dict[str, Any]], suite_measurements: tuple[str, ...], base: Path,
             where: Locator) -> tuple[RenderCase, ...]:
    """[[render]] tables: runner keys (RENDER_KEYS) plus the adapter's own keys; a list value
    of an adapter key makes one case per element (cross product over such keys)."""
    from harness.adapters import adapter_names, renderer

    names = adapter_names()

    out: list[RenderCase] = []
    for i, c in enumerate(raw):
        table = ("render", i)
        runner_keys = {k: v for k, v in c.items() if k in RENDER_KEYS}
        check_keys(runner_keys, RENDER_KEYS, where, table)
        if "adapter" not in c:
            raise SuiteError(where.at(table, None,
                                      f"missing key 'adapter' (one of: {', '.join(names)})"))
        adapter = c["adapter"]
        if adapter not in names:
            raise SuiteError(where.at(table, "adapter",
                                      f"expected one of: {', '.join(names)} (or an adapter registered under "
                                      f"the entry-point group 'harness.adapters'), got {adapter!r}"))
        spp = c.get("spp", 64)
        positive(spp, where, table, "spp")
        _sample_count(spp, where, table, "spp")
        replicas = c.get("replicas", 16)
        if replicas < 4:
            raise SuiteError(where.at(table, "replicas", f"expected at least 4 replicas, got {replicas}"))
        ms = measurements(c["measurements"], where, table) if "measurements" in c else suite_measurements
        budgets = c.get("budgets", [max(1, spp >> k) for k in (6, 4, 2, 0)])
        if any(isinstance(b, bool) or not isinstance(b, int) or b <= 0 for b in budgets):
            raise SuiteError(where.at(table, "budgets", f"expected positive integer budgets, got {budgets}"))
        _sample_count(max(budgets), where, table, "budgets")
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
        _sample_count(ref_spp // max(parts, 1), where, table, "reference_spp")
        if ref_spp < parts or ref_spp % parts:
            raise SuiteError(where.at(table, "reference_spp", f"expected a multiple of reference_parts = "
                                      f"{parts}, got {ref_spp}"))
        expect = c.get("expect", "unbiased")
        if expect not in ("unbiased", "biased"):
            raise SuiteError(where.at(table, "expect",
                                      f"expected \"unbiased\" or \"biased\", got {expect!r}"))
        spec = {k: v for k, v in c.items() if k not in RENDER_KEYS}
        axes = [k for k, v in spec.items() if isinstance(v, list)]
        for k in axes:
            if not spec[k]:
                raise SuiteError(where.at(table, k, "expected a value or a non-empty list of values, got []"))
        sibling = _sibling_keys(c, spec, ms, where, table)
        first = len(out)
        for values in itertools.product(*(spec[k] for k in axes)):
            one = {**spec, **dict(zip(axes, values))}
            try:
                r = renderer(adapter, one, base=base)
            except ValueError as e:
                msg = str(e)
                key = named_key(msg, one)
                if key is not None and msg.startswith(f"'{key}'"):
                    msg = msg[len(key) + 2:].lstrip(": ")
                raise SuiteError(where.at(table, key, msg)) from None
            scene, config = r.describe() if hasattr(r, "describe") else ("", "")
            target = tuple(sorted({**one, **sibling}.items()))
            out.append(RenderCase(adapter, tuple(sorted(one.items())), len(out), spp, replicas, budgets,
                                  ref_spp, parts, ms, expect, xfail_reason(c, where, table), str(base),
                                  scene, config, target if sibling and target != tuple(sorted(one.items()))
                                  else None))
        table_specs = [rc.spec for rc in out[first:]]   # a list: specs may hold tables (unhashable)
        for rc in out[first:]:
            if rc.reference_config is not None and rc.reference_config not in table_specs:
                shown = ", ".join(f"{k} = {v!r}" for k, v in sibling.items())
                raise SuiteError(where.at(table, "reference", f"{{{shown}}} names no configuration of this "
                                          f"[[render]] table (from {rc.label})"))
    return tuple(out)


def _sibling_keys(c: dict[str, Any], spec: dict[str, Any], ms: tuple[str, ...], where: Locator,
                  table: Any) -> dict[str, Any]:
    """The ``reference`` table: adapter keys whose values, put into a configuration, name the
    sibling it is compared with (e.g. {integrator = "path"}); {} where absent."""
    sibling = c.get("reference", {})
    unknown = [k for k in sibling if k not in spec]
    if unknown:
        raise SuiteError(where.at(table, "reference", f"expected adapter keys of this table "
                                  f"({', '.join(spec)}), got {', '.join(map(repr, unknown))}"))
    if any(isinstance(v, list) for v in sibling.values()):
        raise SuiteError(where.at(table, "reference", f"expected one value per key, got {sibling!r}"))
    if sibling and "bias" not in ms:
        raise SuiteError(where.at(table, "reference", "a configuration compared with a sibling needs the "
                                  "'bias' measurement (its replicas are the reference)"))
    return dict(sibling)


MAX_SPP = 2**31 - 1   # renderers take 32-bit signed sample counts (Mitsuba's spp, most command lines)


def _sample_count(spp: int, where: Locator, table: Any, key: str) -> None:
    """A render's samples per pixel must fit the renderers' 32-bit sample counts."""
    if spp > MAX_SPP:
        raise SuiteError(where.at(table, key, f"expected at most {MAX_SPP:,} samples per pixel per render "
                                              f"(renderers take 32-bit sample counts), got {spp:,}"))
