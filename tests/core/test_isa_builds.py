"""Bitwise identity across ISAs: the core rebuilt for AVX2 + FMA (-march=haswell) and for
plain x86-64 (SSE2) computes exactly the bits this machine's build computes, for every
catalogue estimate (random, stratified and Sobol' points; 1 and 2 threads) and for the
elementary functions exp, log and sin/cos (benchmarks/isa_builds.py --identity does the
builds and the comparison).  Not statistical: any differing bit fails."""
from __future__ import annotations

import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_avx2_and_sse2_builds_compute_the_same_bits():
    r = subprocess.run([sys.executable, os.path.join(ROOT, "benchmarks", "isa_builds.py"), "--identity",
                        "--march", "haswell", "x86-64"], capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stdout + r.stderr
    lines = r.stdout.splitlines()
    assert any("-march=haswell (AVX2+FMA): bitwise identical" in line for line in lines), r.stdout
    assert any("-march=x86-64 (SSE2): bitwise identical" in line for line in lines), r.stdout
