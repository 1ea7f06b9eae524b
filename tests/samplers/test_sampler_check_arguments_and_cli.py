"""check_sampler's domains by name, its argument errors, and the check-sampler command line."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from harness.samplers import Domain, as_domain, check_sampler
from tests.samplers.zoo_samplers import CORRECT, correct


def test_domains_by_name():
    assert as_domain("disk") == Domain("disk")
    assert as_domain(("interval", -1, 2)) == Domain("interval", -1.0, 2.0)
    d = Domain("hemisphere")
    s = np.array([[0.3, 0.2], [0.9, 0.7]])
    back, inside = d.to_params(d.to_points(s))
    np.testing.assert_allclose(back, s)
    assert inside.all()


@pytest.mark.parametrize("kwargs, error, message", [
    ({"domain": "cube"}, ValueError,
     r"'domain' must be one of \('interval', 'half_line', 'square', 'disk', 'hemisphere', 'sphere'\)"),
    ({"domain": ("interval", 2, 1)}, ValueError, r"\('interval', a, b\) with finite a < b"),
    ({"sample_count": 10}, ValueError, r"'sample_count' must be from 1000 to 100,000,000 \(a check holds its "
                                       r"samples in memory\), got 10"),
    ({"sample_count": 2**40}, ValueError, r"'sample_count' must be from 1000 to 100,000,000"),
    ({"sample_count": 1500.5}, ValueError, r"'sample_count' must be a positive whole number, got 1500.5"),
    ({"alpha": 0.0}, ValueError, r"'alpha' must be in \(0, 1\)"),
    # each had been taken: an infinite end made every cell NaN, udim 0 was the default, True a total
    ({"domain": ("interval", 0, np.inf)}, ValueError, r"with finite a < b, got \('interval', 0, inf\)"),
    ({"domain": ("interval", "a", "b")}, ValueError, r"with finite a < b"),
    ({"udim": 0}, ValueError, r"'udim' must be an integer in \[1, 1024\], got 0"),
    ({"udim": 2.0}, ValueError, r"'udim' must be an integer in \[1, 1024\], got 2.0"),
    ({"udim": 1000, "sample_count": 10**6}, ValueError, r"1,000,000 samples of 1000 uniforms each"),
    ({"total": True}, ValueError, r"'total' must be the pdf's integral over the domain, in \(0, 1\], "
                                  r"got True"),
])
def test_bad_arguments(kwargs, error, message):
    s = correct(CORRECT[0])
    args = {"domain": s.domain, **kwargs}
    with pytest.raises(error, match=message):
        check_sampler(s.sample, s.pdf, **args)


def test_a_domain_of_an_unknown_kind_is_refused_where_it_is_made():
    # a sampler object's own domain (Domain(name), as check-sampler builds it) had failed later
    # with a KeyError
    with pytest.raises(ValueError, match=r"'domain' must be one of \('interval', .*\), got 'torus'"):
        Domain("torus")


def test_a_domains_ends_are_finite_and_for_the_interval_only():
    assert Domain("interval", np.int64(1), 2) == Domain("interval", 1.0, 2.0)
    with pytest.raises(ValueError, match=r"the half line is 'half_line'\), got \(0.0, inf\)"):
        Domain("interval", 0.0, np.inf)
    with pytest.raises(ValueError, match="ends are for the interval only; the disk has none"):
        Domain("disk", 0.0, np.inf)
    for ends in ((0, 10 ** 400), (-1e308, 1e308)):   # an OverflowError, and a length past the doubles
        with pytest.raises(ValueError, match=r"finite numbers a < b, b - a a double"):
            Domain("interval", *ends)


def test_wrong_point_shapes_are_named():
    with pytest.raises(ValueError,
                       match=r"<lambda> returned points of shape \(5000, 2\) for uniforms of shape "
                             r"\(5000, 2\); expected shape \(5000, 3\) on the hemisphere"):
        check_sampler(lambda u: u, lambda x: np.ones(len(x)), "hemisphere", sample_count=5000)


def test_cli_check_sampler(tmp_path):
    mod = tmp_path / "my_sampler.py"
    mod.write_text("import numpy as np, math\n"
                   "import reference_estimators as rest\n"
                   "_s = rest.sampler('ggx', alpha=0.1)\n"
                   "def good():\n    return (lambda u: _s.sample(u)[0], _s.pdf, 'hemisphere')\n"
                   "def bad():\n"
                   "    return (lambda u: _s.sample(u)[0], lambda w: 1.01 * _s.pdf(w), 'hemisphere')\n"
                   "class Turned:\n"   # GGX about +y, on the sphere with its pole at +y
                   "    domain, pole = 'sphere', 'y'\n"
                   "    def sample(self, u):\n        return _s.sample(u)[0][:, [1, 2, 0]]\n"
                   "    def pdf(self, w):\n        return _s.pdf(w[:, [2, 0, 1]])\n"
                   "class BadBreaks(Turned):\n    breaks = ([2.0], None)\n")
    (tmp_path / "raises.py").write_text("raise RuntimeError('no GPU here')\n")
    harness = str(Path(sys.executable).with_name("harness"))

    def run(*args: str) -> subprocess.CompletedProcess:  # as a user runs it: in the repository, no PYTHONPATH
        return subprocess.run([harness, "check-sampler", *args], capture_output=True, text=True, cwd=tmp_path,
                              timeout=300)

    for target in ("my_sampler:good", "./my_sampler.py:good"):
        r = run(target, "--samples", "200000")
        assert r.returncode == 0 and "PASSED" in r.stdout, r.stdout + r.stderr
        assert "summary: 1 passed, 0 failed" in r.stdout, r.stdout + r.stderr
    r = run("my_sampler:bad", "--samples", "200000")
    assert r.returncode == 1 and "normalization" in r.stdout and "1.010000" in r.stdout
    r = run("my_sampler:Turned", "--samples", "200000")
    assert r.returncode == 0 and "PASSED" in r.stdout, r.stdout + r.stderr
    r = run("my_sampler:BadBreaks", "--samples", "200000")
    assert r.returncode == 2 and "harness: 'breaks'[0]: 1 of 1 coordinates are not finite numbers in [0, 1]" \
        in r.stderr and "Traceback" not in r.stderr, r.stderr
    for target, said in [("my_sampler:nope", "'my_sampler:nope': my_sampler has no attribute 'nope'"),
                         ("nothere:good", "'nothere:good': cannot import 'nothere'"),
                         ("./nothere.py:good", "'./nothere.py:good': no file"),
                         ("raises:good",
                          "'raises:good': importing 'raises' raised RuntimeError: no GPU here"),
                         ("my_sampler", "'my_sampler': expected module:attribute")]:
        r = run(target)
        assert r.returncode == 2 and f"harness: cannot load {said}" in r.stderr, r.stderr
        assert "Traceback" not in r.stderr


def test_points_with_their_axes_swapped_are_refused_not_reshaped():
    # a correct sampler returning (2, N) had been reshaped into scrambled points and failed
    sample = lambda u: np.stack([np.sqrt(u[:, 0]), u[:, 1]])      # noqa: E731
    with pytest.raises(ValueError, match=r"<lambda> returned points of shape \(2, 5000\) for uniforms of "
                                         r"shape \(5000, 2\); expected shape \(5000, 2\) on the square"):
        check_sampler(sample, lambda x: 2 * x[:, 0], "square", sample_count=5000)
    with pytest.raises(ValueError, match=r"<lambda> returned an empty tuple"):
        check_sampler(lambda u: (), lambda x: np.ones(len(x)), "square", sample_count=5000)
    one_column = check_sampler(lambda u: u[:, :1], lambda x: np.ones(len(x)), "interval", sample_count=5000)
    assert one_column.passed                                     # an interval's (N, 1) is N points
