"""The result family's common surface on small real runs: every result type of harness.stats
(UnbiasedResult, ConvergenceResult, Efficiency, ImageBias) has ``verdict``, ``passed``,
``pvalue``, ``alpha``, ``n``, ``statistic``, ``confidence_interval()`` returning a
``ConfidenceInterval``, ``failures`` as a list of ``Failure``, and a ``str`` that says why;
none has ``__bool__``.  Seeds fixed; each run is small (the whole module takes seconds)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import reference_estimators as rest

from harness import stats
from harness.stats import images
from harness.stats.results import ConfidenceInterval, Failure

GAUSS = rest.integrand("gaussian").reference
BUDGETS = [256, 1024, 4096]


def _image_runs(bias: float = 0.0, bad_pixel: bool = False) -> tuple[np.ndarray, images.Reference]:
    """16 replicas of a 12 x 10 RGB image with normal noise around an exact reference."""
    rng = np.random.default_rng(7)
    truth = rng.random((12, 10, 3)) + 0.5
    x = truth + bias + 0.05 * rng.normal(size=(16, 12, 10, 3))
    if bad_pixel:
        x[3, 4, 5, 1] = np.nan
    return x, images.Reference.exact(truth)


def _results() -> dict[str, object]:
    f = lambda u: np.exp(-u[:, 0] ** 2)  # noqa: E731
    nan_at_start = lambda u: np.where(u[:, 0] < 0.01, np.nan, u[:, 0])  # noqa: E731
    reps = [stats.replicate("gaussian", "uniform", n, 16, seed=1, case_id=i) for i, n in enumerate(BUDGETS)]
    x, ref = _image_runs()
    return {
        "unbiased": stats.check_unbiased(f, 1, GAUSS, sample_count=20_000, seed=1),
        "biased": stats.check_unbiased(lambda u: 1.05 * f(u), 1, GAUSS, sample_count=20_000, seed=1),
        "invalid": stats.check_unbiased(nan_at_start, 1, 0.5, sample_count=20_000, seed=1),
        "technique": stats.check_technique("gaussian", "uniform/sobol", 8192, seed=0),
        "convergence": stats.fit_convergence(reps, seed=1),
        "slow convergence": stats.convergence_rate("gaussian", "clamped:uniform(0.9)", BUDGETS, 16, seed=0),
        "efficiency": stats.efficiency(reps[-1]),
        "image": images.pixel_bias_test(x, ref, 8),
        "biased image": images.pixel_bias_test(_image_runs(bias=0.05)[0], ref, 8),
        "invalid image": images.pixel_bias_test(*_image_runs(bad_pixel=True), 8),
    }


@pytest.fixture(scope="module")
def results() -> dict[str, object]:
    return _results()


FAMILY = ["verdict", "passed", "pvalue", "alpha", "n", "statistic", "failures"]
NAMES = ["unbiased", "biased", "invalid", "technique", "convergence", "slow convergence", "efficiency",
         "image", "biased image", "invalid image"]


@pytest.mark.parametrize("name", NAMES)
def test_every_result_has_the_family_surface(results, name):
    r = results[name]
    assert dataclasses.is_dataclass(r) and not hasattr(type(r), "__bool__"), type(r)
    for attr in FAMILY:
        assert hasattr(r, attr), f"{type(r).__name__} lacks {attr!r}"
    assert isinstance(r.verdict, str) and r.verdict
    assert isinstance(r.passed, bool)
    assert isinstance(r.pvalue, float) and (math.isnan(r.pvalue) or 0 <= r.pvalue <= 1)
    assert isinstance(r.alpha, float) and (math.isnan(r.alpha) or 0 < r.alpha < 1)
    assert isinstance(r.n, int) and r.n > 0
    assert isinstance(r.statistic, float)
    assert isinstance(r.failures, list) and all(isinstance(f, Failure) for f in r.failures)
    for level in (0.95, 0.5):
        ci = r.confidence_interval(level)
        assert type(ci) is ConfidenceInterval and all(isinstance(v, float) for v in ci)
    ci = r.confidence_interval()
    assert np.array_equal(ci, r.confidence_interval(0.95), equal_nan=True)
    lo, hi = ci  # unpacks like a tuple
    assert (math.isnan(lo) and math.isnan(hi)) or lo <= hi
    assert str(r).startswith(r.verdict), str(r)
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.verdict = "changed"  # type: ignore[misc]


@pytest.mark.parametrize("name, verdict, passed", [
    ("unbiased", "consistent", True), ("biased", "biased", False), ("invalid", "invalid", False),
    ("technique", "consistent", True), ("convergence", "as expected", True),
    ("slow convergence", "slower than expected", False), ("efficiency", "measured", True),
    ("image", "consistent", True), ("biased image", "biased", False), ("invalid image", "invalid", False),
])
def test_verdicts_and_passed(results, name, verdict, passed):
    r = results[name]
    assert (r.verdict, r.passed) == (verdict, passed), str(r)


def test_failures_carry_counts_and_examples(results):
    (nan,) = results["invalid"].failures
    assert nan.check == "nan" and nan.count > 100 and nan.detail == "NaN contributions"
    assert nan.examples and all(e["issue"] == "nan" for e in nan.examples)
    assert stats.failure_counts(results["invalid"].failures) == {"nan": nan.count}
    assert Failure.from_dict(nan.to_dict()) == nan
    (px,) = results["invalid image"].failures
    assert (px.check, px.count, px.examples) == ("replicas_nan", 1, ({"replica": 3, "row": 4, "col": 5},))
    assert results["invalid image"].excluded == 1 and "replicas_nan: 1" in str(results["invalid image"])
    for name in ("unbiased", "biased", "convergence", "efficiency", "image"):
        assert results[name].failures == [], name


def test_intervals_cover_what_they_say(results):
    u = results["unbiased"]
    lo, hi = u.confidence_interval(0.99)
    assert lo < GAUSS < hi and lo < u.estimate < hi
    assert all(math.isnan(v) for v in results["invalid"].confidence_interval())
    c = results["convergence"]
    assert c.confidence_interval(0.5).low >= c.confidence_interval(0.95).low
    assert c.alpha == pytest.approx(0.025) and c.n == 16 * len(BUDGETS)
    e = results["efficiency"]
    assert e.confidence_interval().low < e.value < e.confidence_interval().high
    assert math.isnan(e.pvalue) and math.isnan(e.alpha) and math.isnan(e.statistic)
    assert e.n == e.budget * e.replicas == BUDGETS[-1] * 16
    img = results["biased image"]
    assert img.confidence_interval(0.999).low > 0 and img.n == 16 * 8 and math.isnan(img.statistic)
    ratio, (rlo, rhi) = stats.efficiency_ratio(e, e)
    assert ratio == 1.0 and rlo < 1 < rhi


def test_invalid_factory_matches_the_checks(results):
    r = stats.UnbiasedResult.invalid({"nan": 3, "posinf": 1}, [{"issue": "nan", "index": 2}], reference=1.0,
                                     n=640, alpha=0.01, batches=64)
    assert r.verdict == "invalid" and r.df == 63 and r.n == 640 and r.flags == ("contributions with faults",)
    assert [(f.check, f.count, len(f.examples)) for f in r.failures] == [("nan", 3, 1), ("posinf", 1, 0)]
    assert results["invalid"].flags == r.flags and results["invalid"].df == 63


def test_bad_confidence_levels_are_named(results):
    for r in results.values():
        with pytest.raises(ValueError, match=r"'confidence_level' must be in \(0, 1\), got 1.5"):
            r.confidence_interval(1.5)


def test_the_package_exports_every_public_name():
    for name in ("check_unbiased", "check_technique", "judge_batches", "UnbiasedResult", "TailSample", "holm",
                 "Replicates", "replicate", "median_time", "ConvergenceResult", "convergence_rate",
                 "fit_convergence", "Efficiency", "efficiency", "efficiency_ratio", "error_vs_time",
                 "ConfidenceInterval", "Failure", "failure_counts", "failures_from_counts"):
        assert name in stats.__all__ and hasattr(stats, name), name
