"""Reference Monte Carlo estimators with exact answers, implemented in C++.

    >>> import reference_estimators as re
    >>> est = re.integrate("gaussian", "uniform", 1_000_000, seed=1)
    >>> abs(est.z_score()) < 5
    True
"""
from . import _core, sampling
from .api import *  # noqa: F403
from .api import __all__ as _api_all
from .estimate import ERROR_ISSUES, Estimate

CHUNK_SIZE: int = _core.CHUNK_SIZE
__all__ = [*_api_all, "Estimate", "ERROR_ISSUES", "CHUNK_SIZE"]
