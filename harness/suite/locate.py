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
    index-th ``[[name]]`` of an array of tables.  Besides headers, the other spellings TOML
    allows are found: a dotted key (``suite.samples = 10``), an inline table (``suite = {...}``),
    an inline array of tables (``case = [{...}, {...}]``: its index-th element's line) and a
    key written as a sub-table (``[case.params]``) or a dotted key (``params.alpha = 1``)."""

    def __init__(self, path: Path, text: str):
        self.path = path
        self.lines = text.splitlines()

    def at(self, table: Any, key: str | None, message: str) -> str:
        """``message`` prefixed with ``file:line: key: `` (the line where one is found)."""
        line = self._find(table, key)
        prefix = f"{self.path}:{line}" if line else f"{self.path}"
        return f"{prefix}: {key + ': ' if key else ''}{message}"

    def _find(self, table: Any, key: str | None) -> int | None:
        if table is None:
            return self._key_line(0, len(self.lines), None, key)
        name, index = (table, 0) if isinstance(table, str) else table
        n = re.escape(name)
        header = re.compile((r"^\s*\[\s*%s\s*\]" if isinstance(table, str) else r"^\s*\[\[\s*%s\s*\]\]") % n)
        starts = [i for i, line in enumerate(self.lines) if header.match(line)]
        if index < len(starts):
            start = starts[index]
            # the table runs to the next header that is not one of its own sub-tables
            own = re.compile(r"^\s*\[+\s*%s\s*\." % n)
            nxt = [i for i, line in enumerate(self.lines)
                   if i > start and re.match(r"^\s*\[", line) and not own.match(line)]
            end = nxt[0] if nxt else len(self.lines)
            if key is None:
                return start + 1
            # a key inside the table, not its header ("sampler" in [[sampler]])
            return self._key_line(start + 1, end, name, key)
        return self._inline(name, None if isinstance(table, str) else index - len(starts), key)

    def _key_line(self, start: int, end: int, table: str | None, key: str | None) -> int | None:
        """The first line in [start, end) that sets ``key``: ``key = ``, a dotted ``key.x =``,
        or a header ``[key]``, or ``[table.key]`` for a sub-table of the enclosing ``table``."""
        sub = r"(%s\s*\.\s*)?" % re.escape(table) if table else ""
        pattern = re.compile(r"^\s*(\[+\s*%s)?%s\s*(=|\]|\.)" % (sub, re.escape(key or "")))
        for i in range(start, end):
            if pattern.match(self.lines[i]):
                return i + 1
        return None

    def _inline(self, name: str, index: int | None, key: str | None) -> int | None:
        """The line of table ``name`` written without a header (its ``index``-th element where
        it is an inline array of tables; None for a table), at the top level: ``name.key = ``,
        ``name = {...}`` or ``name = [{...}, ...]``; None where it is not there."""
        n = re.escape(name)
        if key is not None:   # a dotted key at the top level
            dotted = re.compile(r"^\s*%s\s*\.\s*%s\s*(=|\.)" % (n, re.escape(key)))
            for i, line in enumerate(self.lines):
                if dotted.match(line):
                    return i + 1
        assign = re.compile(r"^\s*%s\s*(=|\.)" % n)
        first = next((i for i, line in enumerate(self.lines) if assign.match(line)), None)
        if first is None:
            return None
        element = None if index is None else self._array_element(first, index)
        return (element if element is not None else first) + 1

    def _array_element(self, first: int, index: int) -> int | None:
        """The line where the ``index``-th inline table of the array assigned on line
        ``first`` opens (strings skipped, multi-line ones too: braces inside them do not
        count)."""
        text = "\n".join(self.lines[first:])
        start = text.find("=")
        depth, seen, i, quote = 0, -1, start + 1, ""
        while i < len(text):
            c = text[i]
            if quote:
                if c == "\\" and quote[0] == '"':
                    i += 1
                elif text.startswith(quote, i):
                    i += len(quote) - 1
                    quote = ""
            elif c in "\"'":
                quote = c * 3 if text.startswith(c * 3, i) else c
                i += len(quote) - 1
            elif c == "#":
                i = text.find("\n", i) if "\n" in text[i:] else len(text)
                continue
            elif c in "[{":
                if c == "{" and depth == 1:
                    seen += 1
                    if seen == index:
                        return first + text.count("\n", 0, i)
                depth += 1
            elif c in "]}":
                depth -= 1
                if depth == 0:
                    return None
            i += 1
        return None
