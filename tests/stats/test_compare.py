"""Two renderers compared without a reference (harness.stats.compare): the false-alarm rate
measured over 200 seeds on nulls a renderer really produces (smooth pixels, a light tracer's
sparse compound-Poisson pixels, float32 images of high dynamic range), and the power side by
side with the peer, Welch per pixel with a Bonferroni correction (Jung et al. 2020 style).
16 replicas a set: the count from which every scale is tested (harness.stats.scales)."""
import numpy as np
import pytest
from scipy import stats as sps

from harness.stats.compare import compare_images

R, H, W, ALPHA = 16, 32, 32, 0.01


def smooth(rng, bias=0.0):
    return (0.5 + 0.05 * rng.standard_normal((R, H, W, 3)),
            0.5 + bias + 0.05 * rng.standard_normal((R, H, W, 3)))


def sparse(rng, bias=0.0, hits=2.0):
    """A light tracer's pixels: N ~ Poisson(hits) splats per pixel and replica, Gamma-distributed sums."""
    def one(scale):
        n = rng.poisson(hits, (R, H, W, 3))
        return scale * rng.gamma(np.maximum(n, 1e-9), 1.0) / hits * (n > 0)
    return one(1.0), one(1.0 + bias)


def float32(rng, bias=0.0):
    base = rng.uniform(0.2, 5.0, (H, W, 3))
    noise = lambda: 0.02 * rng.standard_normal((R, H, W, 3))   # noqa: E731
    return (base + noise()).astype(np.float32), (base * (1 + bias) + noise()).astype(np.float32)


def peer(a, b):
    """Welch per pixel-channel, Bonferroni over all of them."""
    _, p = sps.ttest_ind(a, b, axis=0, equal_var=False)
    return np.nan_to_num(p, nan=1.0).min() * p.size <= ALPHA


@pytest.mark.parametrize("null", [smooth, sparse, float32])
def test_false_alarms_hold_alpha_over_200_seeds(null):
    alarms = sum(not compare_images(*null(np.random.default_rng(s)), alpha=ALPHA).passed for s in range(200))
    assert alarms <= 6      # binomial(200, 0.01): P(X > 6) < 0.5 %


@pytest.mark.parametrize("null, bias, least",
                         [(smooth, 0.004, 95), (sparse, 0.05, 95), (float32, 0.0015, 95)])
def test_a_spread_bias_is_found_where_per_pixel_welch_misses_it(null, bias, least):
    ours = sum(not compare_images(*null(np.random.default_rng(1000 + s), bias), alpha=ALPHA).passed
               for s in range(100))
    theirs = sum(peer(*null(np.random.default_rng(1000 + s), bias)) for s in range(100))
    assert ours >= least and theirs <= 10, (ours, theirs)


def test_a_local_bias_is_found_by_the_pixel_test_and_located():
    rng = np.random.default_rng(7)
    a, b = smooth(rng)
    b[:, 20, 5, 1] += 0.3           # one pixel-channel 12 standard errors off (t_14 needs ~8.6 here)
    r = compare_images(a, b)
    assert r.verdict == "differ" and r.pvalue_pixels < 1e-4 and r.worst_pixel == (20, 5, 1)


def test_faulty_pixels_are_excluded_and_reported():
    a, b = smooth(np.random.default_rng(3))
    a[2, 4, 4, 0] = np.nan
    b[0, 9, 9, 2] = -1.0
    r = compare_images(a, b)
    assert r.verdict == "invalid" and r.excluded == 2
    nan, negative = r.failures
    assert (nan.check, nan.count, nan.examples) == ("set_a_nan", 1, ({"replica": 2, "row": 4, "col": 4},))
    assert (negative.check, negative.count, negative.examples) == ("set_b_negative", 1,
                                                                   ({"replica": 0, "row": 9, "col": 9},))


def test_identical_constant_images_agree_and_rounding_is_not_a_difference():
    a = np.full((4, 8, 8, 3), 0.25, np.float32)
    b = a * np.float32(1 + 2**-23)      # one ulp apart: rounding, not a difference
    assert compare_images(a, b).passed
    assert not compare_images(a, a + 0.01).passed


def test_bad_inputs_are_refused():
    a, b = smooth(np.random.default_rng(0))
    with pytest.raises(ValueError, match="at least 4 replicas of each, got 3 and 16"):
        compare_images(a[:3], b)
    with pytest.raises(ValueError, match=r"of one size, got \(16, 32, 32, 3\) and \(16, 16, 32, 3\)"):
        compare_images(a, b[:, :16])
