"""Shared by the test_mitsuba_*.py modules, which test Mitsuba 3 samplers
(harness.adapters.mitsuba: samplers, checks, faults, catalogue, runtime) against their pdfs
and weights.

Real llvm_ad_rgb objects.  Statistical checks state alpha and use seed 0 (chosen before the
tests were written); 2e5 samples per check there, 1e6 in benchmarks/mitsuba_samplers.py.
"""
from __future__ import annotations

N = 200_000
ALPHA = 0.01
