"""A team's own samplers in a suite ([[sampler]] sampler = "module:attr"): an object, a tuple
or a factory with params, checked against its pdf (missing samples allowed for with total),
xfail for known findings, and every mistake named with file, line and key."""
import re
import textwrap

import pytest

from harness.suite.parse import SuiteError, load_suite
from harness.suite.plan import sampler_key
from harness.suite.run import run_suite

MODULE = '''
import numpy as np


class Linear:
    """x = sqrt(u) on [0, 1], pdf 2x; with absorb, that fraction of the u give no sample."""
    domain = "interval"

    def __init__(self, absorb=0.0, power=0.5):
        self.absorb, self.power = absorb, power
        self.total = 1 - absorb if absorb else None

    def sample(self, u):
        keep = u < 1 - self.absorb
        v = np.where(keep, u / (1 - self.absorb), 0.5)
        return np.where(keep, v ** self.power, np.nan)

    def pdf(self, x):
        return (1 - self.absorb) * 2 * x


linear = Linear()
pair = (lambda u: u, lambda x: np.ones(len(x)), "interval")


class Steps:
    """A density stepping 1:2.5 at x = 1/3, by inversion, the step declared as a break."""
    domain = "interval"
    breaks = ([1 / 3],)

    def sample(self, u):
        return np.where(u < 1 / 6, 2 * u, 1 / 3 + (u - 1 / 6) / 1.25)

    def pdf(self, x):
        return np.where(x < 1 / 3, 0.5, 1.25)


class PoleY:
    """theta = pi u0 about +y (pdf 1 / (2 pi^2 sin theta)), checked with its pole at +y."""
    domain, pole = "sphere", "y"

    def sample(self, u):
        th, ph = np.pi * u[:, 0], 2 * np.pi * u[:, 1]
        return np.column_stack([np.sin(th) * np.sin(ph), np.cos(th), np.sin(th) * np.cos(ph)])

    def pdf(self, w):
        return 1 / (2 * np.pi**2 * np.sqrt(np.maximum(1 - w[:, 1] ** 2, 1e-300)))


class BadBreaks(Steps):
    breaks = ([1 / 3], [0.5])


class BadPole(Steps):
    pole = "y"


class ExitingDomain(Steps):
    @property
    def domain(self):
        import sys
        sys.exit(3)


class BrokenTotal(Steps):
    @property
    def total(self):
        return self._total


class ManyUniforms(Steps):
    udim = 500


class TooManyUniforms(Steps):
    udim = 2000


def broken_factory(**params):
    raise RuntimeError("no such roughness")


def scalar_pdf():
    return (lambda u: u, lambda x: 1.0, "interval")
'''

SUITE = '''
[suite]
samples = 50_000

[[sampler]]
sampler = "mysampler:linear"

[[sampler]]
sampler = "mysampler.py:Linear"
params = { absorb = 0.25 }

[[sampler]]
sampler = "mysampler:pair"
measurements = ["chi_square", "mcmc"]

[[sampler]]
sampler = "mysampler:Linear"
params = { power = 0.55 }
xfail = "a known finding: too many samples near 0"

[[sampler]]
sampler = "mysampler:Steps"

[[sampler]]
sampler = "mysampler:PoleY"
'''


@pytest.fixture
def repo(tmp_path):
    (tmp_path / "mysampler.py").write_text(MODULE)
    (tmp_path / "suite.toml").write_text(SUITE)
    return tmp_path


def test_user_samplers_are_checked_and_xfailed(repo):
    suite = load_suite(repo / "suite.toml")
    assert [s.label for s in suite.samplers] == ["mysampler:linear", "mysampler.py:Linear(absorb=0.25)",
                                                 "mysampler:pair", "mysampler:Linear(power=0.55)",
                                                 "mysampler:Steps", "mysampler:PoleY"]
    assert suite.samplers[1].total == 0.75
    s = run_suite(suite, repo / "r.sqlite", threads=2)
    o = s["sampler"]
    assert [o.status(i) for i in range(6)] == ["passed", "passed", "passed", "xfailed", "passed", "passed"]
    assert s.failed == 0
    checks = o.results[1].checks["chi_square"]
    assert any(t["test"] == "failed samples" for t in checks["tests"])
    # PoleY's pole reached its check: the conditional's table about +y is as tight as the zoo's
    # about +z (8.7e-7; with the pole at +z the singular axis crosses the strips: 1.7e-4)
    u1 = next(t for t in o.results[5].checks["chi_square"]["tests"]
              if t["test"].startswith("Cramer-von Mises u1"))
    assert float(re.search(r"CDF error bound ([0-9.e+-]+) carried", u1["detects"]).group(1)) < 1e-5
    assert run_suite(load_suite(repo / "suite.toml"), repo / "r.sqlite", threads=2).units_run == 0
    # a change of the module's source gives every check a new key: its stored units are not reused
    before = [sampler_key(suite, sc) for sc in suite.samplers]
    (repo / "mysampler.py").write_text(MODULE + "\n# changed\n")
    changed = load_suite(repo / "suite.toml")
    assert all(a != b for a, b in zip(before, (sampler_key(changed, sc) for sc in changed.samplers)))


@pytest.mark.parametrize("table, message", [
    ('sampler = "mysampler:nothing"', "bad.toml:2: sampler: 'mysampler:nothing': mysampler has no attribute"),
    ('sampler = "mysampler:broken_factory"\nparams = { alpha = 0.1 }',
     "bad.toml:3: params: mysampler:broken_factory(alpha=0.1) raised RuntimeError: no such roughness"),
    ('sampler = "mysampler:linear"\nparams = { alpha = 0.1 }',
     "bad.toml:2: sampler: mysampler:linear: params were given, but it is a Linear, not a factory"),
    ('sampler = "mysampler:scalar_pdf"\ndomain = "cube"', "bad.toml:3: domain: expected one of: interval"),
    ('sampler = "mysampler:linear"\ntotal = 1.5',
     "bad.toml:3: total: expected the pdf's integral, in (0, 1]"),
    ('sampler = "mysampler:Linear"\nparams = { absorb = 0.5 }\nmeasurements = ["mcmc"]',
     "bad.toml:4: measurements: 'mcmc' needs a sampler that always produces a sample"),
    ('sampler = "mysampler:linear"\nmeasurements = ["weight"]',
     "bad.toml:3: measurements: expected some of: chi_square, mcmc for a sampler of your own, "
     "got 'weight'"),
    ('sampler = "mysampler:linear"\nxfail = ""', "bad.toml:3: xfail: expected the reason"),
    ('sampler = "mysampler:BadBreaks"', "bad.toml:2: sampler: mysampler:BadBreaks: 'breaks' must be a "
                                        "sequence of 1 coordinate sequence(s)"),
    ('sampler = "mysampler:BadPole"',
     "bad.toml:2: sampler: mysampler:BadPole: 'pole' 'y' is for the sphere only"),
    # a property that calls sys.exit had ended the harness
    ('sampler = "mysampler:ExitingDomain"',
     "bad.toml:2: sampler: mysampler:ExitingDomain.domain called sys.exit(3)"),
    # a property's own AttributeError had read as "no total"
    ('sampler = "mysampler:BrokenTotal"',
     "bad.toml:2: sampler: mysampler:BrokenTotal.total raised AttributeError: 'BrokenTotal' object has no "
     "attribute '_total'"),
    # the check's limit on the uniforms it holds: had loaded, then stopped the run with a traceback
    ('sampler = "mysampler:ManyUniforms"\nsamples = 1_000_000',
     "bad.toml:3: samples: 1,000,000 samples of 500 uniforms each (mysampler:ManyUniforms.udim): a check "
     "holds at most 400,000,000 uniforms"),
    ('sampler = "mysampler:TooManyUniforms"',
     "bad.toml:2: sampler: mysampler:TooManyUniforms: 'udim' must be an integer from 1 to 1024, got 2000"),
])
def test_user_sampler_mistakes_name_file_line_and_key(repo, table, message):
    (repo / "bad.toml").write_text(textwrap.dedent(f"[[sampler]]\n{table}\n"))
    with pytest.raises(SuiteError) as e:
        load_suite(repo / "bad.toml")
    assert message in str(e.value)


def test_a_scalar_pdf_fails_the_run_with_its_name(repo):
    (repo / "s.toml").write_text('[suite]\nsamples = 5000\n[[sampler]]\nsampler = "mysampler:scalar_pdf"\n')
    with pytest.raises(ValueError, match=r"returned shape \(\) for points of shape \(\d+,\), float64; "
                                         r"expected shape \(\d+,\), one density per point"):
        run_suite(load_suite(repo / "s.toml"), repo / "r.sqlite", threads=1)
