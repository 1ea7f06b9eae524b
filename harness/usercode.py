"""A team's own code named by a string: ``module:attr`` or ``path/to/file.py:attr``.

A module name is imported with ``base`` (the suite file's folder, or the current directory on
the command line) first on the import path, so a user's repository needs no PYTHONPATH; a
``.py`` path is resolved against ``base`` and loaded as a module of its own.  Every failure
(a malformed name, a missing file or module, an exception while importing it, a missing
attribute) is a :class:`UserCodeError` naming the target and the cause in one line.

:func:`call` runs a user's callable on arrays: an exception inside it, or an output of the
wrong shape, is re-raised as a :class:`UserCodeError` naming the callable, what it was called
on (shape and dtype) and what was expected back.  :func:`source_fingerprint` hashes the source
a loaded callable comes from, so stored results of changed code are not reused.
"""
from __future__ import annotations

import hashlib
import importlib
import importlib.util
import inspect
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["UserCodeError", "load_attr", "call", "array_result", "real_array", "describe", "callable_name",
           "source_fingerprint", "USER_ERRORS", "raised"]


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
            name = f"harness_user_{path.stem}_{hashlib.sha256(str(path).encode()).hexdigest()[:12]}"
            if name not in sys.modules:
                spec = importlib.util.spec_from_file_location(name, path)
                if spec is None or spec.loader is None:   # no loader for the suffix: not a .py file
                    raise UserCodeError(f"{target!r}: {path} is not a Python source file (.py)")
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
    except USER_ERRORS as e:  # the user's module raised (or exited) while importing: say which and what
        raise UserCodeError(f"{target!r}: importing {where!r} {raised(e)}") from None


def callable_name(fn: Any) -> str:
    """How messages name a callable: module:qualname where known (a bound method by its
    object's class, so an inherited method names the subclass), else its repr."""
    owner = getattr(fn, "__self__", None)
    if owner is not None and not isinstance(owner, type) and hasattr(fn, "__name__") \
            and not inspect.ismodule(owner):
        cls = type(owner)
        return f"{cls.__module__}:{cls.__qualname__}.{fn.__name__}"
    module, qualname = getattr(fn, "__module__", None), getattr(fn, "__qualname__", None)
    if module and qualname:
        return f"{module}:{qualname}"
    return repr(fn)


def describe(a: Any) -> str:
    """An argument as messages name it: "shape (65536, 2), float64" for arrays."""
    if isinstance(a, np.ndarray):
        return f"shape {a.shape}, {a.dtype}"
    return type(a).__name__


#: What a team's code may raise that the harness reports as that code's failure: any Exception,
#: and SystemExit (a command-line tool's main() called as a function calls sys.exit; escaping, it
#: had ended a run without a word, with exit status 0 after sys.exit(0)).  KeyboardInterrupt
#: still stops the run.
USER_ERRORS: tuple[type[BaseException], ...] = (Exception, SystemExit)


def raised(e: BaseException) -> str:
    """What a team's code did, as messages say it: "raised KeyError: 'x'", or "called
    sys.exit(0)"."""
    if isinstance(e, SystemExit):
        return f"called sys.exit({e.code!r})"
    return f"raised {type(e).__name__}: {e}"


def call(fn: Callable[..., Any], name: str, *args: Any, what: str = "") -> Any:
    """fn(*args); an exception inside it (or a sys.exit: :data:`USER_ERRORS`) becomes a
    UserCodeError naming ``name``, the arguments' shapes and dtypes and ``what`` was expected
    (the original is chained)."""
    try:
        return fn(*args)
    except USER_ERRORS as e:
        given = ", ".join(describe(a) for a in args)
        raise UserCodeError(f"{name} {raised(e)} (called on {given}"
                            + (f"; expected to return {what}" if what else "") + ")") from e


def real_array(value: Any) -> np.ndarray:
    """A user's numbers as a float64 array: booleans, integers and floats of any width (a
    Dr.Jit tensor or a list too), and objects that cast to float64; a ValueError saying what
    it is otherwise: "a list that is no array (...)", "a ndarray of complex128 values" (numpy's
    cast would keep their real part, with only a warning), "a ndarray of <U3 values" (it
    would parse strings).  Shared by every place that takes a team's arrays (contributions,
    points, pdf values, images), so all take the same ones."""
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError) as e:   # a ragged list, an object whose __array__ raises
        raise ValueError(f"a {type(value).__name__} that is no array ({e})") from None
    if raw.dtype.kind not in "biufO":
        raise ValueError(f"a {type(value).__name__} of {raw.dtype} values")
    try:
        return raw.astype(np.float64, copy=False)
    except (TypeError, ValueError) as e:   # objects that are no numbers
        raise ValueError(f"a {type(value).__name__} of objects that are no numbers ({e})") from None


def array_result(value: Any, shape: tuple[int, ...] | None, name: str, given: str) -> np.ndarray:
    """A user's return value as float64 of exactly ``shape`` (any shape where None), or a
    UserCodeError saying what came back, for which input, and what was expected."""
    want = "a float array" + (f" of shape {shape}" if shape is not None else "")
    try:
        a = real_array(value)
    except ValueError as e:
        raise UserCodeError(f"{name} returned {e} for {given}; expected {want}") from None
    if shape is not None and a.shape != shape:
        raise UserCodeError(f"{name} returned shape {a.shape} for {given}; expected shape {shape}")
    return a


def source_fingerprint(obj: Any) -> str:
    """SHA-256 (24 hex digits) of the source files of the module a callable (or object) is
    defined in and, if it differs, of the class or function it was made from: a stored result
    of changed code is not reused.  Objects without a source file hash their repr."""
    files: list[str] = []
    for o in (obj, type(obj), getattr(obj, "__func__", None)):
        try:
            f = inspect.getsourcefile(o) if o is not None else None
        except TypeError:
            f = None
        if f and f not in files:
            files.append(f)
    h = hashlib.sha256()
    for f in files:
        try:
            h.update(Path(f).read_bytes())
        except OSError:
            h.update(f.encode())
    if not files:
        h.update(repr(obj).encode())
    return h.hexdigest()[:24]
