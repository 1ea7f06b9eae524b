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
from typing import TYPE_CHECKING, Any, Protocol

from harness.suite.execute import Job
from harness.suite.store import Store

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["CaseKind", "Outcome"]


@dataclass(frozen=True)
class Outcome:
    """One kind's measured cases, in the suite's order.

    ``noun``: what the kind's cases are called in counts ("cases", "sampler checks", ...);
    ``names``: each case's name (pytest items, FAILED lines); ``results``: the kind's result
    per case; ``verdicts``: measurement -> verdict word per case (harness.suite.verdicts);
    ``failures``: why each case fails a CI run, "" where it passes; ``rows``: the measurement
    rows for the store; ``table``: the kind's table, one dict per case (:attr:`frame` as a
    DataFrame, ``--csv``); ``text``: the table as aligned text with its heading (empty when the
    kind has no cases); ``xfail``: each case's ``xfail`` reason, "" where none (a known finding:
    its failure is expected).

    A case's :meth:`status` is "passed", "failed", "xfailed" (failed, as its xfail says) or
    "xpassed" (has an xfail reason but passed: strict, like pytest's ``xfail(strict=True)``,
    so a fixed finding is noticed and its xfail removed); "failed" and "xpassed" fail a run.
    """

    kind: str
    noun: str
    names: tuple[str, ...]
    results: tuple[Any, ...]
    verdicts: tuple[dict[str, str], ...]
    failures: tuple[str, ...]
    rows: tuple[dict[str, Any], ...]
    table: tuple[dict[str, Any], ...]
    text: str
    xfail: tuple[str, ...] = ()

    @property
    def frame(self) -> pd.DataFrame:
        """The kind's table as a DataFrame, one row per case."""
        # pandas is imported here, not with the module: a run prints its tables without it,
        # and its import is a third to a half of a resumed run's time as a command
        import pandas as pd
        return pd.DataFrame(list(self.table))

    def status(self, i: int) -> str:
        reason = self.xfail[i] if self.xfail else ""
        if reason:
            return "xfailed" if self.failures[i] else "xpassed"
        return "failed" if self.failures[i] else "passed"

    def problem(self, i: int) -> str:
        """Why case i fails a run ("" where it does not)."""
        status = self.status(i)
        if status == "failed":
            return self.failures[i]
        if status == "xpassed":
            return (f"[XPASS(strict)] expected to fail ({self.xfail[i]}) but passed: if the finding is "
                    "fixed, remove the case's xfail key")
        return ""

    @property
    def failed(self) -> int:
        """How many cases fail a CI run (failed, or passed against their xfail)."""
        return sum(1 for i in range(len(self.names)) if self.status(i) in ("failed", "xpassed"))

    @property
    def xfailed(self) -> int:
        """How many cases failed as expected."""
        return sum(1 for i in range(len(self.names)) if self.status(i) == "xfailed")


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
