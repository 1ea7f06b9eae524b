"""Where a mistake is in a suite file: the line of a TOML table or key, so that every error
names ``file:line: key``."""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any

__all__ = ["Locator"]


class Locator:
    """Finds the line of a table or key in a TOML file's raw text (tomllib keeps no positions).

    ``table`` is None (the top level), a table's name ("suite") or (name, index) for the
    index-th ``[[name]]`` of an array of tables."""

    def __init__(self, path: Path, text: str):
        self.path = path
        self.lines = text.splitlines()

    def at(self, table: Any, key: str | None, message: str) -> str:
        """``message`` prefixed with ``file:line: key: `` (the line where one is found)."""
        line = self._find(table, key)
        prefix = f"{self.path}:{line}" if line else f"{self.path}"
        return f"{prefix}: {key + ': ' if key else ''}{message}"

    def _find(self, table: Any, key: str | None) -> int | None:
        start, end = 0, len(self.lines)
        if table is not None:
            name, index = (table, 0) if isinstance(table, str) else table
            header = re.compile(r"^\s*\[\[\s*%s\s*\]\]" % re.escape(name) if not isinstance(table, str)
                                else r"^\s*\[\s*%s\s*\]" % re.escape(name))
            starts = [i for i, line in enumerate(self.lines) if header.match(line)]
            if index >= len(starts):
                return None
            start = starts[index]
            nxt = [i for i, line in enumerate(self.lines) if i > start and re.match(r"^\s*\[", line)]
            end = nxt[0] if nxt else len(self.lines)
            if key is None:
                return start + 1
            start += 1  # a key inside the table, not its header ("sampler" in [[sampler]])
        pattern = re.compile(r"^\s*(\[+\s*)?%s\s*(=|\]|\.)" % re.escape(key or ""))
        for i in range(start, end):
            if pattern.match(self.lines[i]):
                return i + 1
        return None
