"""Shared helpers for the test suite.

Statistical tests here state their false-alarm rate alpha and use fixed seeds chosen before
the test was written (seed 0 unless a test needs several); a failure is a finding, not a
reason to try another seed.
"""
from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def root() -> Path:
    return ROOT
