"""A team's own code named by a string: ``module:attr`` or ``path/to/file.py:attr``.

A module name is imported with ``base`` (the suite file's folder, or the current directory on
the command line) first on the import path, so a user's repository needs no PYTHONPATH; a
``.py`` path is resolved against ``base`` and loaded as a module of its own.  Every failure
(a malformed name, a missing file or module, an exception while importing it, a missing
attribute) is a :class:`UserCodeError` naming the target and the cause in one line.
"""
from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path
from typing import Any

__all__ = ["UserCodeError", "load_attr"]


class UserCodeError(ValueError):
    """User code that cannot be loaded; the message names the target and why."""


def load_attr(target: str, *, base: Path) -> Any:
    """The object ``target`` names (``module:attr`` or ``file.py:attr``, attr may be dotted)."""
    where, sep, attr = target.rpartition(":")
    if not sep or not where or not attr:
        raise UserCodeError(f"{target!r}: expected module:attribute or path/to/file.py:attribute")
    module = _module(where, base, target)
    obj: Any = module
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise UserCodeError(f"{target!r}: {module.__name__} has no attribute {attr!r}") from None
    return obj


def _module(where: str, base: Path, target: str) -> Any:
    try:
        if where.endswith(".py") or "/" in where:
            path = (base / where).resolve()
            if not path.is_file():
                raise UserCodeError(f"{target!r}: no file {path}")
            name = f"harness_user_{path.stem}_{abs(hash(str(path))):x}"
            if name not in sys.modules:
                spec = importlib.util.spec_from_file_location(name, path)
                module = importlib.util.module_from_spec(spec)
                sys.modules[name] = module
                try:
                    spec.loader.exec_module(module)
                except BaseException:
                    del sys.modules[name]
                    raise
            return sys.modules[name]
        folder = str(base.resolve())
        if folder not in sys.path:
            sys.path.insert(0, folder)
        return importlib.import_module(where)
    except UserCodeError:
        raise
    except ImportError as e:
        raise UserCodeError(f"{target!r}: cannot import {where!r} (from {base}): {e}") from None
    except Exception as e:  # the user's module raised while importing: say which and what
        raise UserCodeError(f"{target!r}: importing {where!r} raised {type(e).__name__}: {e}") from None
