"""profile_stages: which prefixes of integrate's pipeline each technique has, and that stopping
the pipeline early for a profile leaves the estimate it reports (and integrate's) unchanged.
No timing is asserted (timings belong to benchmarks/)."""
from __future__ import annotations

import math

import pytest

import reference_estimators as rest

N = 3 * rest.CHUNK_SIZE + 1000   # several chunks and a partial one
PREFIXES = ("points", "sampled", "screened", "weighted", "contributions", "full")


@pytest.mark.parametrize("integrand, technique, stages", [
    ("gaussian", "uniform", ()),                                            # uniform on a box: no sampler
    ("gaussian2d", "uniform/sobol", ()),
    ("ggx_lobe", "importance:ggx", ("sampled", "screened")),
    ("ggx_lobe", "uniform", ("sampled", "screened")),                       # uniform on the hemisphere
    ("gaussian2d", "importance:piecewise_constant_2d", ("sampled", "screened")),
    ("ggx_lobe", "mis_balance:cosine_hemisphere+ggx", ("sampled", "screened", "weighted")),
    ("gaussian2d", "mis_balance:uniform_box+piecewise_constant_2d", ("sampled", "screened", "weighted")),
])
def test_each_technique_reports_the_stages_it_has(integrand, technique, stages):
    d = rest.profile_stages(integrand, technique, N, seed=3, threads=2)
    assert set(d) == set(PREFIXES) | {"estimate"}
    for key in ("sampled", "screened", "weighted"):
        assert (d[key] is not None) == (key in stages), key
    for key in PREFIXES:
        if d[key] is not None:
            assert math.isfinite(d[key]) and d[key] >= 0, (key, d[key])
    # the profiled passes stop early in the same code integrate runs whole: its estimate is the
    # one integrate gives, to the bit
    est = rest.integrate(integrand, technique, N, seed=3, threads=2)
    assert (d["estimate"].mean, d["estimate"].variance, d["estimate"].n) == (est.mean, est.variance, est.n)
    assert d["full"] == d["estimate"].seconds


def test_a_rejection_sampler_has_no_separate_points_stage():
    """It draws its own uniforms inside the sampler: points 0, sampling the whole draw."""
    lin = rest.sampler("linear", a=1.0, b=0.37)
    t = rest.importance(rest.rejection_sampler("gaussian", lin, c=1.2))
    d = rest.profile_stages("gaussian", t, 20_000, threads=1)
    assert d["points"] == 0.0
    assert d["sampled"] is not None and d["screened"] is not None and d["weighted"] is None
