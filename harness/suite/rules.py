"""The rules every suite table's keys follow, each mistake a :class:`SuiteError` naming file,
line and key (shared by harness.suite.parse, .parse_samplers and .parse_renders)."""
from __future__ import annotations

from typing import Any

from harness.suite.locate import Locator
from harness.suite.model import MEASUREMENTS, SAMPLER_MEASUREMENTS, SuiteError

__all__ = ["check_keys", "named_key", "measurements", "positive", "xfail_reason"]


def named_key(message: str, keys: Any) -> str | None:
    """The key an adapter's error message names first (quoted as 'key'), or None."""
    named = sorted((message.find(f"'{k}'"), k) for k in keys if f"'{k}'" in message)
    return named[0][1] if named else None


def check_keys(table: dict[str, Any], spec: dict[str, Any], where: Locator, name: Any) -> None:
    for key, value in table.items():
        if key not in spec:
            raise SuiteError(where.at(name, key, f"unknown key {key!r}; expected one of: {', '.join(spec)}"))
        want = (int, float) if spec[key] is float else spec[key]
        if isinstance(value, bool) or not isinstance(value, want):
            kinds = " or ".join(t.__name__ for t in (want if isinstance(want, tuple) else (want,)))
            raise SuiteError(where.at(name, key, f"expected {kinds}, got {type(value).__name__} {value!r}"))


def measurements(names: list[Any], where: Locator, table: Any) -> tuple[str, ...]:
    for m in names:
        if m not in MEASUREMENTS:
            hint = " (sampler checks go in [[sampler]] tables)" if m in SAMPLER_MEASUREMENTS else ""
            raise SuiteError(where.at(table, "measurements", f"unknown measurement {m!r}; expected some of: "
                                      f"{', '.join(MEASUREMENTS)}{hint}"))
    if not names:
        raise SuiteError(where.at(table, "measurements", "expected at least one measurement"))
    return tuple(dict.fromkeys(names))


def positive(v: int, where: Locator, table: Any, key: str) -> None:
    if v <= 0:
        raise SuiteError(where.at(table, key, f"expected a budget > 0 samples, got {v}"))


def xfail_reason(c: dict[str, Any], where: Locator, table: Any) -> str:
    """The ``xfail`` key of any table: why a failure of it is expected (a known finding).
    Strict, like pytest's xfail(strict=True): the run fails when the check starts to pass."""
    reason = c.get("xfail", "")
    if "xfail" in c and not reason.strip():
        raise SuiteError(where.at(table, "xfail", "expected the reason the failure is expected (a known "
                                                  "finding), got an empty string"))
    return reason.strip()
