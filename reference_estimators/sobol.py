"""Sobol' direction numbers for the core's Owen-scrambled point sets.

The primitive polynomials and initial direction numbers are Joe & Kuo's (new-joe-kuo-6.21201),
as shipped with scipy.stats.qmc; this module derives the 32-bit direction matrix from them
(Bratley & Fox's recurrence) and hands it to the C++ core once, at import.
"""
from __future__ import annotations

import importlib.util
import os

import numpy as np

__all__ = ["DIMENSIONS", "direction_numbers"]

DIMENSIONS = 256  # dimensions made available to point sets


def direction_numbers(dims: int = DIMENSIONS) -> np.ndarray:
    """v[d, k]: the 32-bit direction number of bit k of the index in dimension d."""
    # the file only: importing scipy.stats for it would cost 0.4 s at every start
    scipy_dir = os.path.dirname(importlib.util.find_spec("scipy").origin)
    data = np.load(os.path.join(scipy_dir, "stats", "_sobol_direction_numbers.npz"))
    poly, vinit = data["poly"], data["vinit"]
    if dims > len(poly):
        raise ValueError(f"at most {len(poly)} Sobol' dimensions are available, asked for {dims}")
    v = np.zeros((dims, 32), dtype=np.uint32)
    v[0] = [1 << (31 - k) for k in range(32)]  # dimension 0: van der Corput
    for d in range(1, dims):
        p = int(poly[d])
        s = p.bit_length() - 1  # degree of the primitive polynomial
        a = (p >> 1) & ((1 << (s - 1)) - 1)  # its inner coefficients a_1 .. a_{s-1}
        col = [0] * 32
        for k in range(min(s, 32)):
            col[k] = int(vinit[d, k]) << (31 - k)
        for k in range(s, 32):
            x = col[k - s] ^ (col[k - s] >> s)
            for j in range(1, s):
                if (a >> (s - 1 - j)) & 1:
                    x ^= col[k - j]
            col[k] = x
        v[d] = col
    return v
