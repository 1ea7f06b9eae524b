"""Reproduces the coefficients of fastmath.h's atan2_turns: g(z) = (atan r - r) / (r z), z = r^2
on [0, tan^2(pi/8)], interpolated at Chebyshev nodes in long double (Newton divided
differences, then monomial coefficients), for degrees 8 to 12; prints each degree's largest
relative error of r + r z g(z) against atan r (its series in long double) and the float64
coefficients in hex, highest degree last (fastmath.h evaluates them by Horner from the top).

    .venv/bin/python tools/fit_atan_turns.py
"""
from __future__ import annotations

import numpy as np

L = np.longdouble
ZMAX = (np.sqrt(L(2)) - 1) ** 2  # tan^2(pi/8)


def g(z: np.ndarray) -> np.ndarray:
    """(atan(x) - x) / (x z) for z = x^2: the series sum_{k>=1} (-1)^k z^(k-1) / (2k + 1)."""
    z = np.asarray(z, dtype=L)
    s, p = np.zeros_like(z), np.ones_like(z)
    for k in range(1, 70):
        s += (-1) ** k * p / L(2 * k + 1)
        p *= z
    return s


def fit(degree: int) -> np.ndarray:
    """Monomial coefficients (long double, lowest first) of the interpolant of g at the
    Chebyshev nodes of [0, ZMAX]."""
    k = np.arange(degree + 1, dtype=L)
    nodes = ZMAX / 2 * (1 - np.cos(np.pi * (k + L(0.5)) / (degree + 1)))
    dd = g(nodes).copy()
    for j in range(1, degree + 1):
        dd[j:] = (dd[j:] - dd[j - 1:-1]) / (nodes[j:] - nodes[:-j])
    coef = np.zeros(degree + 1, dtype=L)
    coef[0] = dd[degree]
    for j in range(degree - 1, -1, -1):  # coef <- coef * (z - nodes[j]) + dd[j]
        new = np.zeros(degree + 1, dtype=L)
        new[1:] = coef[:-1]
        new -= nodes[j] * coef
        new[0] += dd[j]
        coef = new
    return coef


def main() -> None:
    print(f"long double mantissa bits: {np.finfo(L).nmant}")
    x = np.linspace(L(0), np.sqrt(ZMAX), 200001)[1:]
    z = x * x
    exact = x + x * z * g(z)
    for degree in range(8, 13):
        c = fit(degree).astype(np.float64)
        p = np.zeros_like(z)
        for v in c[::-1]:
            p = p * z + L(v)
        err = np.max(np.abs((x + x * z * p) - exact) / exact)
        print(degree, float(err), [float.hex(float(v)) for v in c])


if __name__ == "__main__":
    main()
