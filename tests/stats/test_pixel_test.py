"""The multi-scale bias test (harness.stats.images.pixel_bias_test) on hand-built replica
images: where it finds a bias and says where, the rendered reference's own error, the exact
cases (zero variance, float32 rounding), bad values and refusals.  Its false-alarm rate and
power over the calibration zoo are in test_image_zoo.py.

alpha = 0.01.  Seeds are fixed before the test was written: numpy's default_rng(seed) for
seed = 0, 1, ..., one generator per simulated configuration.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats as sps

from harness.stats.images import Reference, pixel_bias_test
from harness.stats.scales import FINE_REPLICAS, MIN_SAMPLES

ALPHA = 0.01
R, H, W, C = 16, 32, 32, 3
SIGMA = 0.05                          # per-replica noise; every pixel >= 0.5 = 10 SIGMA, so none is negative
REF = 0.5 + 0.5 * np.add.outer(np.arange(H), np.arange(W))[:, :, None] / (H + W) * np.array([1.0, 0.5, 2.0])
SE = SIGMA / math.sqrt(R)             # standard error of one pixel's replica mean
SPP = 64                              # samples a replica's pixel averages: enough for the pixel scale


def replicas(seed: int, n: int = R, sigma: float = SIGMA) -> np.ndarray:
    return REF + sigma * np.random.default_rng(seed).standard_normal((n, H, W, C))


def test_the_scales_and_their_levels_are_stated():
    b = pixel_bias_test(replicas(0), Reference.exact(REF), SPP)
    names = ["pixels", "2x2 tiles", "4x4 tiles", "8x8 tiles", "16x16 tiles", "image"]
    assert [s.name for s in b.scales] == names
    assert all(s.alpha == pytest.approx(ALPHA / 6) for s in b.scales)
    assert [s.count for s in b.scales] == [H * W * C, 256 * C, 64 * C, 16 * C, 4 * C, 1]
    assert b.pvalue == pytest.approx(min(1.0, 6 * min(s.pvalue for s in b.scales)))
    assert "pixels p = " in str(b) and "image p = " in str(b) and b.verdict == "consistent"


def test_fewer_than_sixteen_replicas_test_only_the_coarse_scales_with_three_df():
    b = pixel_bias_test(replicas(0, FINE_REPLICAS - 1), Reference.exact(REF), SPP)
    assert [s.name for s in b.scales] == ["8x8 tiles", "16x16 tiles", "image"] and math.isnan(b.pvalue_pixels)


def test_scales_whose_tiles_average_too_few_samples_are_not_tested():
    """At 4 spp a pixel is a mean of 4 samples and a 2 x 2 tile of 16: too few for the t law
    on real renders (an area light's edge pixels, fireflies); 4 x 4 tiles average 64."""
    b = pixel_bias_test(replicas(0), Reference.exact(REF), 4)
    assert [s.size for s in b.scales] == [4, 8, 16, 0] and MIN_SAMPLES == 64
    assert math.isnan(b.pvalue_pixels) and b.scales[0].alpha == pytest.approx(ALPHA / 4)


def test_one_pixel_ten_standard_errors_off_is_found_at_the_pixel_scale_where_it_is():
    """One pixel-channel 10 SE too bright: found in 37 of 50 seeds (at 16 replicas t_15 at the
    pixel scale's Bonferroni level, 0.01 / 6 / 3072, needs about 9 SE); every rejection names
    the pixel."""
    planted, found = (20, 5, 1), 0
    for seed in range(50):
        x = replicas(seed)
        x[(slice(None), *planted)] += 10 * SE
        b = pixel_bias_test(x, Reference.exact(REF), SPP)
        if b.verdict == "biased":
            found += 1
            assert b.worst_scale.name == "pixels" and b.worst_pixel == planted, (seed, b.worst_pixel)
    assert found >= 30, found


def test_a_region_one_standard_error_off_is_found_by_the_tile_that_fits_it():
    """An 8 x 8 region 1 pixel-SE too bright: invisible pixel by pixel, 8 SE on an 8 x 8 tile."""
    for seed in range(20):
        x = replicas(seed)
        x[:, 8:16, 8:16] += SE
        b = pixel_bias_test(x, Reference.exact(REF), SPP)
        assert b.verdict == "biased" and b.worst_scale.size in (8, SPP), (seed, b.worst_scale.name)
        assert b.worst_pixel[:2] in ((8, 8), (0, 0)) and b.t_map.shape == (H, W)


def test_a_small_bias_everywhere_is_found_and_measured_by_the_image_mean():
    """0.5 % brighter everywhere (about 0.16 pixel-SE): the image scale finds it in every seed and
    its interval covers the planted bias."""
    for seed in range(20):
        x = replicas(seed) * 1.005
        b = pixel_bias_test(x, Reference.exact(REF), SPP)
        assert b.verdict == "biased" and b.worst_scale.name == "image", seed
        lo, hi = b.confidence_interval(0.999)
        assert lo < 0.005 * REF.mean() < hi, (seed, lo, hi)


def test_a_rendered_reference_counts_its_own_error_at_every_scale():
    """A reference of 8 parts, each with 2 replicas' budget (its variance a quarter of the
    replicas' mean's): with its parts counted the rate holds alpha over 300 seeds; taken as
    exact, the same data reject far more often, and the worst |t| is smaller counted."""
    n, parts = 300, 8
    counted = ignored = 0
    for seed in range(n):
        x = replicas(seed)
        p = replicas(n + seed, parts, SIGMA / math.sqrt(2))
        with_error, as_exact = Reference.from_parts(p), Reference.exact(p.mean(axis=0))
        a, b = pixel_bias_test(x, with_error, SPP), pixel_bias_test(x, as_exact, SPP)
        assert abs(a.scale(1).worst_t) <= abs(b.scale(1).worst_t) + 1e-9, seed
        assert a.bias_mean == pytest.approx(b.bias_mean)
        assert a.reference_parts == parts and b.reference_parts == 0
        counted += a.verdict == "biased"
        ignored += b.verdict == "biased"
    assert sps.binom.sf(counted - 1, n, ALPHA) >= 1e-3, f"{counted} rejections in {n} with the parts counted"
    assert ignored > 3 * counted + 10, (ignored, counted)


def test_zero_variance_renders_equal_to_the_reference_up_to_rounding_are_consistent():
    dyadic = np.broadcast_to(np.array([1.0, 0.5, 0.25]), (H, W, C))
    b = pixel_bias_test(np.repeat(dyadic[None], R, axis=0), Reference.exact(dyadic), SPP)
    assert (b.pvalue, b.bias_mean, b.verdict) == (1.0, 0.0, "consistent")
    low = np.nextafter(REF.astype(np.float32), np.float32(0)).astype(np.float64)   # every pixel 1 ulp low
    b = pixel_bias_test(np.repeat(low[None], R, axis=0), Reference.exact(REF), SPP)
    assert b.verdict == "consistent" and b.bias_mean < 0


def test_zero_variance_renders_off_the_reference_are_biased_where_they_are():
    x = np.repeat(REF[None], R, axis=0)
    x[:, 7, 9, 2] += 1e-3
    b = pixel_bias_test(x, Reference.exact(REF), SPP)
    assert b.pvalue == 0.0 and b.verdict == "biased" and b.worst_pixel == (7, 9, 2)


def test_a_pixel_no_replica_reached_is_left_to_the_coarser_scales():
    """A light tracer that missed one pixel in all 16 replicas (zeros where the reference is
    0.5): the constant pixel is not tested (its spread is unknown); its tiles are."""
    x = replicas(0)
    x[:, 3, 4] = 0.0
    b = pixel_bias_test(x, Reference.exact(REF), SPP)
    pixels = b.scale(1)
    assert pixels.low_untested >= C and pixels.pvalues.reshape(H, W, C)[3, 4].tolist() == [1.0] * C


def test_nan_in_a_reference_part_is_invalid_with_its_position_never_biased():
    p = replicas(1, 8)
    p[5, 2, 3, 1] = np.nan
    b = pixel_bias_test(replicas(0), Reference.from_parts(p), SPP)
    assert b.verdict == "invalid" and b.excluded == 1
    (f,) = b.failures
    assert (f.check, f.count, f.examples) == ("reference_nan", 1, ({"part": 5, "row": 2, "col": 3},))
    assert math.isfinite(b.pvalue) and b.pvalue > ALPHA     # the other pixels are still measured


def test_bad_replica_values_are_invalid_with_counts_and_positions():
    x = replicas(0)
    x[5, 1, 2, 0], x[0, 3, 3, 2], x[2, 3, 3, 1] = math.nan, -1.0, math.inf
    b = pixel_bias_test(x, Reference.exact(REF), SPP)
    assert b.verdict == "invalid" and b.excluded == 2
    assert {f.check: (f.count, f.examples) for f in b.failures} == {
        "replicas_nan": (1, ({"replica": 5, "row": 1, "col": 2},)),
        "replicas_inf": (1, ({"replica": 2, "row": 3, "col": 3},)),
        "replicas_negative": (1, ({"replica": 0, "row": 3, "col": 3},))}


def test_too_few_replicas_or_parts_and_bad_shapes_are_refused():
    with pytest.raises(ValueError, match=r"needs >= 4 replicas, got 3"):
        pixel_bias_test(replicas(0, 3), Reference.exact(REF), SPP)
    with pytest.raises(ValueError, match=r"needs >= 2 independent parts \(K, h, w, c\) to know its own"):
        Reference.from_parts(replicas(0, 1))
    with pytest.raises(ValueError, match=r"replicas \(32, 32, 3\) and reference \(16, 32, 3\) differ"):
        pixel_bias_test(replicas(0), Reference.exact(REF[:16]), SPP)
    with pytest.raises(ValueError, match=r"expected replica images"):
        pixel_bias_test(REF, Reference.exact(REF), SPP)
