"""The result family: what every check of the harness returns.

Every check (a bias test, a sampler check, a render's multi-scale bias test, a convergence fit)
returns a frozen dataclass with the same reading surface, so a caller, the runner, the CLI, the pytest
plugin and the report treat them alike:

``verdict``    one word (or short phrase) from the vocabulary of the check, e.g. "unbiased",
               "biased", "inconclusive", "invalid", "passed", "failed", "as expected",
               "slower than expected";
``passed``     the verdict is not a failure (a CI run passes on it);
``pvalue``     the p-value of the check's null hypothesis (NaN where none was computed);
``alpha``      the level the verdict was taken at;
``n``          the sample count the figures come from;
``statistic``  the test statistic, where one exists (else NaN);
``confidence_interval(confidence_level=0.95)``  a :class:`ConfidenceInterval`;
``failures``   a list of :class:`Failure`: deterministic findings (NaN values, points
               outside the domain, ...) with counts and first examples;
``str(r)``     one paragraph that says why.
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from harness.stats.validate import level

__all__ = ["ConfidenceInterval", "Failure", "failures_from_dicts", "failures_from_counts", "failure_counts",
           "check_confidence_level", "summed_counts"]


class ConfidenceInterval(NamedTuple):
    """A two-sided interval (unpacks as ``low, high``); NaN ends where none can be given."""

    low: float
    high: float

    def __str__(self) -> str:
        return f"[{self.low:.6g}, {self.high:.6g}]"


@dataclass(frozen=True)
class Failure:
    """A deterministic finding of a check: ``count`` occurrences of ``check`` (e.g.
    "outside_domain", "nan_pdf"), what it means (``detail``) and the first ``examples``
    (each a dict naming the sample index, the input and the offending value)."""

    check: str
    count: int
    detail: str = ""
    examples: tuple[Mapping[str, Any], ...] = field(default_factory=tuple)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able form (for stored payloads)."""
        return {"check": self.check, "count": int(self.count), "detail": self.detail,
                "examples": [dict(e) for e in self.examples]}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Failure:
        return cls(str(d["check"]), int(d["count"]), str(d.get("detail", "")),
                   tuple(dict(e) for e in d.get("examples", ())))

    def __str__(self) -> str:
        ex = f"; e.g. {list(self.examples[:2])}" if self.examples else ""
        what = f" ({self.detail})" if self.detail else ""
        return f"{self.check}: {self.count}{what}{ex}"


def failures_from_dicts(items: Sequence[Mapping[str, Any]]) -> list[Failure]:
    """Failures read back from their stored dict form."""
    return [Failure.from_dict(d) for d in items]


def failures_from_counts(counts: Mapping[str, int], examples: Iterable[Mapping[str, Any]] = (),
                         details: Mapping[str, str] | None = None) -> list[Failure]:
    """One Failure per non-zero entry of ``counts`` (in its order), with the ``examples``
    whose ``"issue"`` names that entry and its text from ``details``."""
    examples = list(examples)
    details = details or {}
    return [Failure(check, int(c), details.get(check, ""),
                    tuple(dict(e) for e in examples if e.get("issue") == check))
            for check, c in counts.items() if c]


def summed_counts(parts: Iterable[Mapping[str, int]]) -> dict[str, int]:
    """Counts per key summed over ``parts`` (the fault counts of several batches' estimates,
    say), keys in the order first seen."""
    total: dict[str, int] = {}
    for part in parts:
        for key, c in part.items():
            total[key] = total.get(key, 0) + int(c)
    return total


def failure_counts(failures: Iterable[Failure]) -> dict[str, int]:
    """``{check: count}`` of ``failures`` in their order (the stored form of a result's faults)."""
    return {f.check: f.count for f in failures}


def check_confidence_level(confidence_level: float) -> float:
    """The level, validated: a number strictly between 0 and 1."""
    return level(confidence_level, "confidence_level")


def t_interval(centre: float, stderr: float, df: float, confidence_level: float) -> ConfidenceInterval:
    """The two-sided Student-t interval centre -/+ t((1 + level) / 2, df) stderr (``df``
    infinite: the normal's), the level validated first (:func:`check_confidence_level`)."""
    check_confidence_level(confidence_level)
    from harness.stats import distributions

    half = float(distributions.t_ppf(0.5 + confidence_level / 2, df)) * stderr
    return ConfidenceInterval(float(centre - half), float(centre + half))
