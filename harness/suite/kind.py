"""The case-kind protocol: what every kind of case (estimator, sampler check, render) gives
the runner, and the :class:`Outcome` it hands to the CLI, the pytest plugin and the store.

A kind is built from a suite and knows its own cases.  The runner asks it to ``register`` its
cases in the store, to ``plan`` the jobs its measurements need (stored or not: the runner
computes only the missing ones), whether it must ``advance`` to another planning round (a
precision target that was not reached), and finally for its ``outcome`` measured from what is
stored.  Nothing else about a kind is known outside its module.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import pandas as pd

from harness.suite.execute import Job
from harness.suite.store import Store

__all__ = ["CaseKind", "Outcome"]


@dataclass(frozen=True)
class Outcome:
    """One kind's measured cases, in the suite's order.

    ``noun``: what the kind's cases are called in counts ("cases", "sampler checks", ...);
    ``names``: each case's name (pytest items, FAILED lines); ``results``: the kind's result
    per case; ``verdicts``: measurement -> verdict word per case (harness.suite.verdicts);
    ``failures``: why each case fails a CI run, "" where it passes; ``rows``: the measurement
    rows for the store; ``frame``: the kind's table as a DataFrame (``--csv``); ``text``: the
    table as aligned text with its heading (empty when the kind has no cases).
    """

    kind: str
    noun: str
    names: tuple[str, ...]
    results: tuple[Any, ...]
    verdicts: tuple[dict[str, str], ...]
    failures: tuple[str, ...]
    rows: tuple[dict[str, Any], ...]
    frame: pd.DataFrame
    text: str

    @property
    def failed(self) -> int:
        """How many cases fail a CI run."""
        return sum(1 for f in self.failures if f)


class CaseKind(Protocol):
    """A kind of case, built from a suite (``kind(suite)``)."""

    name: str   # "estimator", "sampler" or "render"

    def names(self) -> list[str]:
        """Each case's name, known before anything runs (pytest collects them)."""
        ...

    def register(self, store: Store) -> None:
        """Records the kind's cases (key, labels, definition) in the store."""
        ...

    def plan(self, store: Store) -> list[Job]:
        """A job for every unit the measurements need now, stored or not."""
        ...

    def advance(self, store: Store) -> bool:
        """After the planned units are stored: True if another round of planning is needed."""
        ...

    def outcome(self, store: Store) -> Outcome:
        """The cases measured and judged from what is stored."""
        ...
