"""The cases and helpers shared by the test_samplers_*.py modules, which test the sampler
catalogue: sample / pdf / invert triples, draw(), the rejection method, and the argument
checks of the Python API.

For every registry sampler (defaults and a few harder parameter sets) they check that
sample() reports pdf(x), that points lie in the domain, that invert() undoes sample(), that
the pdf integrates to 1 (by quadrature, independently of the sampler's own code), that the
pdf is 0 and the inverse NaN outside the support, and, for the 1-D inversion samplers, that
draw() follows the exact CDF (Kolmogorov-Smirnov, CDFs written there from the formulas).

Statistical tests state their false-alarm rate alpha and use fixed seeds chosen before the
tests were written; a failure is a finding, not a reason to try another seed.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

import reference_estimators as rest

CHUNK = rest.CHUNK_SIZE
REGISTRY = {s["name"]: s for s in rest.samplers()}
DIRECTION_DOMAINS = ("hemisphere", "sphere")


# draws of the thread-count tests (test_samplers_draw, test_samplers_rejection)
THREAD_N = 3 * CHUNK + 4321  # not a multiple of the chunk size


# --- the cases ---------------------------------------------------------------------------
PC1D_TABLE = (1.0, 1.0, 0.87, 0.25)
# Zero bins at both ends and inside, an odd bin count, and a domain other than [0, 1].
PC1D_ZERO_TABLE = (0.0, 1.0, 0.0, 2.0, 0.0, 0.0, 3.0, 0.5, 0.0)
PC2D_TABLE = tuple(tuple(1.0 + ((5 * r + c) % 7) for c in range(5)) for r in range(4))
PC2D_ZERO_ROW = 3
PC2D_ZERO_TABLE = tuple(
    tuple(0.0 if r == PC2D_ZERO_ROW else 0.25 + ((3 * r + 5 * c) % 11) / 4 for c in range(16))
    for r in range(8)
)


@dataclass(frozen=True)
class Case:
    id: str
    name: str
    params: dict[str, float] = field(default_factory=dict)
    table: Any = None

    def make(self) -> rest.Sampler:
        table = None if self.table is None else np.array(self.table, dtype=float)
        return rest.sampler(self.name, table=table, **self.params)

    @property
    def p(self) -> dict[str, float]:
        """All parameters: the registry defaults overridden by this case's."""
        return {**REGISTRY[self.name]["params"], **self.params}

    @property
    def domain(self) -> str:
        return REGISTRY[self.name]["domain"]

    @property
    def is_direction(self) -> bool:
        return self.domain in DIRECTION_DOMAINS

    @property
    def is_1d(self) -> bool:
        return self.domain in ("interval", "half_line")

    def __str__(self) -> str:
        return self.id


CASES = [
    # registry defaults
    Case("exponential", "exponential"),
    Case("linear", "linear"),
    Case("power", "power"),
    Case("lomax", "lomax"),
    Case("trimmed_logistic", "trimmed_logistic"),
    Case("piecewise_constant_1d", "piecewise_constant_1d", table=PC1D_TABLE),
    Case("piecewise_constant_2d", "piecewise_constant_2d", table=PC2D_TABLE),
    Case("uniform_hemisphere", "uniform_hemisphere"),
    Case("cosine_hemisphere", "cosine_hemisphere"),
    Case("uniform_sphere", "uniform_sphere"),
    Case("uniform_cone", "uniform_cone"),
    Case("ggx", "ggx"),
    # harder parameter sets
    Case("ggx-alpha0.01", "ggx", {"alpha": 0.01}),
    Case("ggx-alpha0.5", "ggx", {"alpha": 0.5}),
    Case("uniform_cone-cos_max-0.5", "uniform_cone", {"cos_max": -0.5}),
    Case("uniform_cone-cos_max0.99", "uniform_cone", {"cos_max": 0.99}),
    Case("power-k-0.9", "power", {"k": -0.9}),
    Case("power-k2", "power", {"k": 2.0}),
    Case("linear-a0-b1", "linear", {"a": 0.0, "b": 1.0}),
    Case("trimmed_logistic-narrow", "trimmed_logistic", {"s": 1e-3}),
    Case("piecewise_constant_1d-zero_bins", "piecewise_constant_1d", {"a": -1.0, "b": 2.0}, PC1D_ZERO_TABLE),
    Case("piecewise_constant_2d-8x16-zero_row", "piecewise_constant_2d", table=PC2D_ZERO_TABLE),
]
ONE_D = [c for c in CASES if c.is_1d]
DIRECTIONS = [c for c in CASES if c.is_direction]


def cases(selection=CASES):
    return pytest.mark.parametrize("case", selection, ids=str)


# --- helpers -------------------------------------------------------------------------------
def canonical(m) -> np.ndarray:
    """The canonical uniform with 52-bit index m: (m + 0.5) 2^-52, in the open (0, 1)."""
    return (np.asarray(m, dtype=np.float64) + 0.5) * 2.0**-52


def breakpoint_u(cdf_values) -> np.ndarray:
    """Canonical uniforms at and next to each given CDF value (where tables switch bins)."""
    m = np.floor(np.asarray(cdf_values, dtype=float) * 2.0**52)
    near = (m[:, None] + np.arange(-3, 4)[None, :]).ravel()
    return canonical(near[(near >= 0) & (near < 2**52)])


def table_cdf(values) -> np.ndarray:
    v = np.asarray(values, dtype=float)
    c = np.concatenate([[0.0], np.cumsum(v)])
    return c / c[-1]


def fmt(*columns, limit: int = 5) -> str:
    """First few offending rows, for failure messages."""
    rows = list(zip(*[np.asarray(c)[:limit].tolist() for c in columns]))
    return "\n  ".join(str(r) for r in rows)
