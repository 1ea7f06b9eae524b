"""Reference Monte Carlo estimators with exact answers, implemented in C++.

    >>> import reference_estimators as rest
    >>> est = rest.integrate("gaussian", "uniform", 1_000_000, seed=1)
    >>> abs(est.z_score()) < 5
    True

``reference_estimators.sampling`` holds the samplers' pbrt-style triples by name and
``reference_estimators.kernels`` the raw streams and elementary functions, for tests.
"""
from . import _core, sobol

_core.set_sobol_directions(sobol.direction_numbers())

from . import kernels, sampling  # noqa: E402  (sampling's functions are built from the registry)
from .api import *  # noqa: E402,F403
from .api import __all__ as _api_all  # noqa: E402
from .check_cubature import *  # noqa: E402,F403
from .check_cubature import __all__ as _cubature_all  # noqa: E402
from .checks import *  # noqa: E402,F403
from .checks import __all__ as _checks_all  # noqa: E402
from .estimate import ERROR_ISSUES, Estimate  # noqa: E402

CHUNK_SIZE: int = _core.CHUNK_SIZE
from importlib.metadata import version as _version  # noqa: E402

__version__: str = _version("mc-harness")


def core_fingerprint() -> str:
    """SHA-256 of the compiled core: stored results are only reused by the same build."""
    global _FINGERPRINT
    if _FINGERPRINT is None:
        import hashlib

        with open(_core.__file__, "rb") as f:
            _FINGERPRINT = hashlib.sha256(f.read()).hexdigest()[:16]
    return _FINGERPRINT


_FINGERPRINT: str | None = None
__all__ = [*_api_all, *_checks_all, *_cubature_all, "Estimate", "ERROR_ISSUES", "CHUNK_SIZE",
           "core_fingerprint", "kernels", "sampling"]
