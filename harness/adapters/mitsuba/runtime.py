"""Mitsuba's process-wide state, handled in one place: the LLVM library drjit loads, the lock
around Mitsuba's variant, switching variants, and which variants the sampler adapters take.

LLVM.  drjit's LLVM backend loads ``libLLVM`` from ``DRJIT_LIBLLVM_PATH`` when drjit is
imported.  :func:`use_libllvm` keeps a path the user set and otherwise points it at Debian's
libLLVM-19 (``/usr/lib/<triplet>/libLLVM-19.so``, the version this project is tested with);
it runs when this module is imported, and every Mitsuba adapter module imports this
one before it imports drjit or Mitsuba (they do so lazily, inside functions).

Threads.  drjit's LLVM kernels run on its own worker threads (nanothread), one per CPU, which
spin for milliseconds after each kernel before they sleep.  :func:`jit_threads` sets their
number for a while (a sampler check's, which calls short kernels every few hundred
microseconds between its own batch calls, and so ran beside spinning workers throughout).

Variants.  ``mi.set_variant`` is process-global, so every public call of an adapter takes
:data:`VARIANT_LOCK`, sets its variant and uses Mitsuba objects built for that variant only.
JIT variants (llvm_ad_*, cuda_ad_*) run a batch as one kernel; scalar variants loop over
samples in Python.  The sampler adapters take RGB and mono variants only: spectral variants
would need sampled wavelengths, polarized ones return Mueller matrices.
"""
from __future__ import annotations

import contextlib
import glob
import os
import threading
from collections.abc import Iterator
from typing import Any

__all__ = ["LIBLLVM_PATTERNS", "VARIANT_LOCK", "activate", "check_variant", "is_jit", "jit_threads",
           "set_jit_threads", "use_libllvm", "using_variant"]

#: Where Debian (and Ubuntu) install libLLVM 19, in the order tried.
LIBLLVM_PATTERNS = ("/usr/lib/*/libLLVM-19.so", "/usr/lib/*/libLLVM.so.19*")

#: Held while a call sets Mitsuba's (process-global) variant and uses its objects.  Reentrant.
VARIANT_LOCK = threading.RLock()


def use_libllvm() -> str | None:
    """The libLLVM drjit will load: ``DRJIT_LIBLLVM_PATH`` if set (left as it is), else the
    first file matching :data:`LIBLLVM_PATTERNS`, which is then written to
    ``DRJIT_LIBLLVM_PATH``; None if neither (drjit then searches on its own).  Has an effect
    only before drjit is first imported."""
    if "DRJIT_LIBLLVM_PATH" in os.environ:
        return os.environ["DRJIT_LIBLLVM_PATH"]
    for pattern in LIBLLVM_PATTERNS:
        found = sorted(glob.glob(pattern))
        if found:
            os.environ["DRJIT_LIBLLVM_PATH"] = found[0]
            return found[0]
    return None


def activate(variant: str) -> Any:
    """Sets Mitsuba's variant (if it is not set already) and returns the ``mitsuba`` module.
    Call it holding :data:`VARIANT_LOCK`, and use the module only while you hold it."""
    import mitsuba as mi  # imported only when a Mitsuba case runs

    if mi.variant() != variant:
        mi.set_variant(variant)
    return mi


@contextlib.contextmanager
def using_variant(variant: str) -> Iterator[Any]:
    """``with using_variant("llvm_ad_rgb") as mi:`` holds :data:`VARIANT_LOCK` and gives the
    ``mitsuba`` module with ``variant`` set."""
    with VARIANT_LOCK:
        yield activate(variant)


def set_jit_threads(count: int) -> int:
    """Sets the number of worker threads drjit runs its JIT kernels on (``dr.set_thread_count``,
    under :data:`VARIANT_LOCK`; nothing where it is ``count`` already); returns the count
    before."""
    with VARIANT_LOCK:
        import drjit as dr

        before = dr.thread_count()
        if count != before:
            dr.set_thread_count(count)
        return before


@contextlib.contextmanager
def jit_threads(count: int | None) -> Iterator[None]:
    """Inside, drjit runs its JIT kernels on ``count`` worker threads (:func:`set_jit_threads`;
    None: as they are), the count before restored after; :data:`VARIANT_LOCK` is held
    throughout (the count is process-global, like the variant)."""
    with VARIANT_LOCK:
        if count is None:
            yield
            return
        before = set_jit_threads(count)
        try:
            yield
        finally:
            set_jit_threads(before)


def is_jit(variant: str) -> bool:
    """True for the JIT variants (llvm_*, cuda_*), which run a batch as one kernel."""
    return variant.startswith(("llvm_", "cuda_"))


def check_variant(variant: str) -> None:
    """Raises ValueError unless ``variant`` is an installed RGB or mono Mitsuba variant (the
    variants the sampler adapters take)."""
    import mitsuba as mi

    if not isinstance(variant, str) or variant not in mi.variants():
        raise ValueError(f"'variant' must be an installed Mitsuba variant ({', '.join(mi.variants())}), "
                         f"got {variant!r}")
    if "spectral" in variant or "polarized" in variant:
        raise ValueError("'variant' must be an RGB or mono variant (e.g. 'llvm_ad_rgb', 'scalar_rgb'), "
                         f"got {variant!r}: spectral variants need sampled wavelengths, polarized ones "
                         "return Mueller matrices")


use_libllvm()  # before drjit is imported: the adapter modules import this module first
