"""The sampler zoo by name, shared by the test_sampler_check_*.py modules."""
from __future__ import annotations

from harness.samplers import zoo

# the zoo by name: the tests build the samplers they use, so that no parameter of a test holds
# a core sampler (pytest keeps deselected tests' parameters to the end of the process, past the
# core's teardown, where nanobind reports them as leaked)
CORRECT = [z.name for z in zoo.correct()]
WRONG = [z.name for z in zoo.wrong()]


def correct(name: str) -> zoo.ZooSampler:
    return next(z for z in zoo.correct() if z.name == name)


def wrong(name: str) -> zoo.ZooSampler:
    return next(z for z in zoo.wrong() if z.name == name)
