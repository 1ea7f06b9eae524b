"""Fingerprints of the harness's own code, for keys of stored results.

A stored unit's numbers depend on the code that computed them: the core (its build
fingerprint), and the harness's Python that drives it (the adapters that build a scene and
return an image, the sampler checks that compute a payload).  ``code_fingerprint`` hashes the
source of the named parts of the package, so an edited or upgraded harness never reuses a
unit that part computed; random streams do not depend on it (seeds stay put across edits).
"""
from __future__ import annotations

import hashlib
from functools import lru_cache
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

__all__ = ["code_fingerprint", "harness_fingerprint", "harness_version"]

_ROOT = Path(__file__).resolve().parent   # the harness package


def harness_version() -> str:
    """The installed distribution's version ("unknown" if run from a bare checkout)."""
    try:
        return version("mc-harness")
    except PackageNotFoundError:
        return "unknown"


@lru_cache(maxsize=None)
def code_fingerprint(*parts: str) -> str:
    """SHA-256 (24 hex digits) of the source of ``parts`` of the harness package: module files
    ("usercode.py") or sub-packages ("adapters", every .py file under it), paths relative to
    the package.  Read once per process."""
    digest = hashlib.sha256()
    for part in sorted(parts):
        path = _ROOT / part
        files = sorted(path.rglob("*.py")) if path.is_dir() else [path]
        if not files or not all(f.is_file() for f in files):
            raise FileNotFoundError(f"no harness source at {path}")
        for f in files:
            digest.update(f.relative_to(_ROOT).as_posix().encode() + b"\0" + f.read_bytes() + b"\0")
    return digest.hexdigest()[:24]


def harness_fingerprint() -> str:
    """The harness that ran something: its version and the fingerprint of all its source."""
    return f"{harness_version()}+{code_fingerprint('.')}"
