"""pyrender adapter: Monte Carlo over a rasterizer, with real OSMesa renders at 32x32.

Seeds are fixed and were chosen before the assertions (replica k of budget n uses seed
100 n + k; references use seeds from 5000); a failure is a finding, not a reason to change
them.  Statistical thresholds state what they detect below each test.
"""
from __future__ import annotations

import json
import threading

import numpy as np
import pytest
from scipy import stats as sps

from harness import stats
from harness.adapters import image_faults, renderer
from harness.adapters.pyrender import render as pa

EDGES = {"scene": "edges", "technique": "antialias"}
SHADOW = {"scene": "shadow", "technique": "soft_shadow"}


# --- spec validation -----------------------------------------------------------------------------
@pytest.mark.parametrize("spec, key", [
    ({"technique": "antialias"}, "'scene'"),
    ({"scene": "edges"}, "'technique'"),
    ({**EDGES, "scene": "teapot"}, "'scene'"),
    ({**EDGES, "technique": "path"}, "'technique'"),
    ({**EDGES, "points": "halton"}, "'points'"),
    ({**EDGES, "width": 0}, "'width'"),
    ({**EDGES, "height": 32.0}, "'height'"),
    ({**EDGES, "width": True}, "'width'"),
    ({**EDGES, "spp": 4}, "'spp'"),
    ({**EDGES, "pixel_filter": "gaussian"}, "'pixel_filter'"),
    ({**EDGES, "light_size": 1.0}, "'light_size'"),
    ({**SHADOW, "pixel_filter": "box"}, "'pixel_filter'"),
    ({**SHADOW, "light_size": 0}, "'light_size'"),
    ({**SHADOW, "light_size": float("nan")}, "'light_size'"),
    ({**SHADOW, "light_size": "1"}, "'light_size'"),
    ({**SHADOW, "light_shape": "sphere"}, "'light_shape'"),
    ({"scene": "edges", "technique": "soft_shadow"}, "'scene'"),
])
def test_spec_errors_name_the_key(spec, key):
    with pytest.raises(ValueError, match=key):
        pa.make_renderer(spec)


def test_render_arguments_are_checked():
    r = pa.make_renderer(EDGES)
    with pytest.raises(ValueError, match="'spp'"):
        r.render(0, 1)
    with pytest.raises(ValueError, match="'seed'"):
        r.render(4, -1)
    with pytest.raises(ValueError, match="'u'"):
        r.frame([0.5, 0.5, 0.5])


def test_registry_protocol_and_fingerprint():
    r = renderer("pyrender", {**SHADOW, "points": "sobol", "light_shape": "disk", "light_size": 0.5})
    assert r.exact() is None
    out = r.render(4, 7)
    assert (out.image.shape == (32, 32, 3) and out.image.dtype == np.float64 and out.spp == 4
            and out.seconds > 0)
    assert np.all((out.image >= 0) & (out.image <= 1))
    k = out.image * (255 * 4)   # an average of 4 byte frames is (integer) / (255 * 4)
    assert np.max(np.abs(k - np.round(k))) < 1e-9
    fp = r.fingerprint()
    json.dumps(fp)
    for key, value in {"scene": "shadow", "technique": "soft_shadow", "points": "sobol", "width": 32,
                       "height": 32, "light_shape": "disk", "light_size": 0.5}.items():
        assert fp[key] == value, (key, fp)
    env = fp["environment"]   # part of the store key, not of the seeds
    assert env["pyrender"] == "0.1.45" and env["PyOpenGL"] and env["gl"]["renderer"] and env["core"]
    assert fp["scene_digest"]
    other = pa.make_renderer({**SHADOW, "points": "sobol", "light_shape": "disk",
                              "light_size": 0.6}).fingerprint()
    assert other != fp and other["scene_digest"] == fp["scene_digest"]
    assert pa.make_renderer(EDGES).fingerprint()["scene_digest"] != fp["scene_digest"]
    # the point set changes the images but not their expectation
    same = pa.make_renderer({**SHADOW, "points": "random", "light_shape": "disk",
                             "light_size": 0.5}).fingerprint()
    assert same != fp and same["estimand_digest"] == fp["estimand_digest"] != other["estimand_digest"]


# --- point maps ----------------------------------------------------------------------------------
def test_offset_and_light_point_maps():
    """Moments of the maps from 2^16 Sobol' points, against closed forms: box offsets have
    variance 1/12, tent offsets 1/6 on [-1, 1]; a disk of diameter 2 has E r^2 = 1/2 and a
    square of side 2 E x^2 = 1/3.  Tolerance 2e-3 is ~10x the Sobol' error at this n."""
    from reference_estimators import points
    u = points(2**16, 2, "sobol", seed=1)
    box, tent = pa.frame_offsets(u, "box"), pa.frame_offsets(u, "tent")
    assert np.all(np.abs(box) <= 0.5) and np.all(np.abs(tent) <= 1.0)
    assert abs(box.var() - 1 / 12) < 2e-3 and abs(tent.var() - 1 / 6) < 2e-3 and abs(tent.mean()) < 2e-3
    disk, square = pa.light_points(u, "disk", 2.0), pa.light_points(u, "rectangle", 2.0)
    r2 = (disk ** 2).sum(axis=1)
    assert np.all(r2 <= 1 + 1e-12) and abs(r2.mean() - 0.5) < 2e-3 and np.all(np.abs(square) <= 1)
    assert abs((square[:, 0] ** 2).mean() - 1 / 3) < 2e-3
    # quadrant strata of u land in quadrants of the disk (the concentric map keeps strata compact)
    q = pa.light_points(np.array([[0.75, 0.6], [0.25, 0.4]]), "disk", 2.0)
    assert q[0, 0] > 0 and q[1, 0] < 0


def test_principal_point_shift_moves_the_frame_exactly():
    """A shift of (1, 0) or (0, 1) pixel moves the frame bitwise by one column or row: the
    camera offset is an exact translation of the image plane (the box filter's offsets are
    the same map at sub-pixel amounts)."""
    for spec in (EDGES, {"scene": "shadow", "technique": "antialias"}):
        r = pa.make_renderer(spec)
        centre = r.frame([0.5, 0.5])
        with pa._GL_LOCK:
            gl = r._current()
            r._camera.cx, r._camera.cy = r._cx + 1.0, r._cy
            right = gl.render(r._scene, flags=r.flags)[0] / 255.0
            r._camera.cx, r._camera.cy = r._cx, r._cy + 1.0
            down = gl.render(r._scene, flags=r.flags)[0] / 255.0
        assert np.array_equal(right[:, 1:], centre[:, :-1]) and np.array_equal(down[1:], centre[:-1])
        assert not np.array_equal(right, centre)


# --- determinism, sharing, faults ----------------------------------------------------------------
@pytest.mark.parametrize("spec", [EDGES, {**SHADOW, "points": "stratified"},
                                  {"scene": "shadow", "technique": "antialias+soft_shadow", "points": "sobol",
                                   "pixel_filter": "tent", "light_shape": "disk"}])
def test_same_seed_same_image_other_seed_differs_at_edges(spec):
    r = pa.make_renderer(spec)
    a, b, c = r.render(8, 11).image, r.render(8, 11).image, r.render(8, 12).image
    assert np.array_equal(a, b)
    assert image_faults(a).total == 0
    differ = np.any(a != c, axis=2)
    assert differ.sum() >= 10, f"only {differ.sum()} pixels change with the seed"
    # where every frame is the same (inside shapes, background, umbra) the seed changes nothing
    assert differ.sum() < differ.size


def test_renderers_share_contexts_and_threads():
    """Two configurations of one size share one OSMesa context; alternating between them and
    rendering from two threads gives the images each gives alone."""
    a, b = pa.make_renderer(EDGES), pa.make_renderer({**SHADOW, "points": "sobol"})
    alone = [a.render(4, 1).image, b.render(4, 1).image]
    assert pa._OFFSCREEN[(32, 32)] is pa._offscreen(32, 32)
    again = [a.render(4, 1).image, b.render(4, 1).image]
    assert all(np.array_equal(x, y) for x, y in zip(alone, again))
    out: dict[int, np.ndarray] = {}

    def work(i: int, r: pa.PyrenderRenderer) -> None:
        out[i] = r.render(4, 1).image

    threads = [threading.Thread(target=work, args=(i, r)) for i, r in enumerate((a, b))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert np.array_equal(out[0], alone[0]) and np.array_equal(out[1], alone[1])


def test_nan_frames_reach_the_image_and_are_counted(monkeypatch):
    """A frame source that returns NaN pixels: the estimate keeps them NaN (never averaged
    away) and image_faults reports how many and where, as the runner does."""
    r = pa.make_renderer(EDGES)
    assert image_faults(r.render(4, 3).image).total == 0
    real = r._frame_bytes
    calls = iter(range(10**6))

    def faulty(gl, place):
        f = real(gl, place).astype(np.float64)
        if next(calls) == 2:
            f[3, 5, 1] = np.nan
        return f

    monkeypatch.setattr(r, "_frame_bytes", faulty)
    out = r.render(4, 3)
    faults = image_faults(out.image)
    assert faults.nan == 1 and faults.examples["nan"] == [(3, 5)], str(faults)
    assert np.isfinite(np.delete(out.image.reshape(-1, 3), 3 * 32 + 5, axis=0)).all()


# --- antialiasing: convergence -------------------------------------------------------------------
BUDGETS = (4, 16, 64, 256)
REPLICAS = 8


@pytest.fixture(scope="module")
def edges_reference() -> np.ndarray:
    """2048 Owen-scrambled Sobol' frames: its MSE is below 3 % of the stratified MSE at 256
    frames (RMSE falls as n^-3/4 for both), so it barely flattens the fitted slopes."""
    return pa.make_renderer({**EDGES, "points": "sobol"}).render(2048, 5000).image


@pytest.mark.slow
@pytest.mark.parametrize("points, lo, hi", [("random", -0.6, -0.4), ("stratified", -1.0, -0.65),
                                            ("sobol", -1.0, -0.65)])
def test_antialiasing_converges_at_the_expected_rate(edges_reference, points, lo, hi):
    """Image RMSE against the reference over 8 replicas at 4, 16, 64, 256 frames, log-log slope
    fitted by stats.fit_convergence (one replica's error is its image RMSE).  Expected: random
    -1/2 (an average of iid frames; the reference adds < +0.01);
    jittered-stratified and Owen-scrambled Sobol' -3/4 (in 2-D the variance of a
    discontinuity along a curve falls as n^-3/2: only the ~sqrt(n) strata the edge crosses
    vary).  The ranges are -1/2 +- 0.1 and [-1, -0.65]: 0.1 is about 4 standard errors of
    the slope for random (measured 0.026) and 7-10 for the others (0.010-0.012), and leaves room
    for the pre-asymptotic bend at 4 frames; -0.65 still excludes the random rate by 0.15,
    and -1 (axis-aligned edges under a (0,m,2)-net) bounds what stratification can give."""
    r = pa.make_renderer({**EDGES, "points": points})
    reps = []
    for n in BUDGETS:
        outs = [r.render(n, 100 * n + k) for k in range(REPLICAS)]
        mse = np.array([np.mean((o.image - edges_reference) ** 2) for o in outs])
        reps.append(stats.Replicates("edges", f"antialias/{points}", n, 0.0, np.sqrt(mse),
                                     np.array([o.seconds for o in outs]), np.nan, np.nan, False, 1))
    fit = stats.fit_convergence(reps, expected=-0.5)
    rmse = fit.table["rmse"].to_numpy()
    detail = f"{fit}; RMSE at {list(BUDGETS)}: {np.array2string(rmse, precision=4)}"
    assert np.all(np.diff(rmse) < 0), detail
    assert lo <= fit.slope <= hi, detail


# --- soft shadows --------------------------------------------------------------------------------
REF_PARTS, REF_FRAMES, EST_FRAMES = 8, 256, 64


@pytest.fixture(scope="module")
def shadow_reference() -> np.ndarray:
    """1024 Owen-scrambled Sobol' frames: the precise reference for RMSE (its own RMSE, ~1e-4,
    is below a tenth of the stratified estimates' at 64 frames)."""
    return pa.make_renderer({**SHADOW, "points": "sobol"}).render(1024, 5100).image


@pytest.fixture(scope="module")
def shadow_reference_parts() -> np.ndarray:
    """(8, 32, 32, 3): 8 independent renders of 256 *random* frames each, the reference of the
    bias test.  Random, because each part then averages 256 iid frames and its spread is an
    honest standard error (CLT); a Sobol' part is not: at a shadow edge aligned with the
    net's strata its value is a two-point mixture (one point per 1/n-wide column decides
    shadow or light), and 8 parts can all fall on one side, which makes their spread far too
    small (seen at this scene's penumbra: t = -9.7 for an unbiased Sobol' estimate)."""
    r = pa.make_renderer({**SHADOW, "points": "random"})
    return np.stack([r.render(REF_FRAMES, 5000 + k).image for k in range(REF_PARTS)])


@pytest.fixture(scope="module")
def shadow_replicas() -> dict[str, np.ndarray]:
    """8 replicas of 64 frames per point set (random, stratified, sobol), and of a light 25 %
    too small (random points): the bias test's negative control."""
    out = {}
    for label, spec in (("random", {"points": "random"}), ("stratified", {"points": "stratified"}),
                        ("sobol", {"points": "sobol"}), ("small", {"points": "random", "light_size": 0.75})):
        r = pa.make_renderer({**SHADOW, **spec})
        out[label] = np.stack([r.render(EST_FRAMES, 100 * EST_FRAMES + k).image for k in range(REPLICAS)])
    return out


def pixel_bias(images: np.ndarray, parts: np.ndarray) -> tuple[float, int, int]:
    """Per-pixel-channel Welch t of the replicas' mean against the reference parts' mean:
    returns the Bonferroni-adjusted smallest p-value over the channels with any variance, how
    many those are, and how many constant channels (all frames equal in both) differ."""
    m, v = images.mean(axis=0), images.var(axis=0, ddof=1) / images.shape[0]
    rm, rv = parts.mean(axis=0), parts.var(axis=0, ddof=1) / parts.shape[0]
    se2 = v + rv
    live = se2 > 0
    t = (m - rm)[live] / np.sqrt(se2[live])
    df = se2[live] ** 2 / (v[live] ** 2 / (images.shape[0] - 1) + rv[live] ** 2 / (parts.shape[0] - 1))
    p = 2 * sps.t.sf(np.abs(t), df)
    return min(1.0, float(p.min()) * int(live.sum())), int(live.sum()), int(np.sum(m[~live] != rm[~live]))


def test_penumbra_exists(shadow_reference):
    """Frames with the light at the square's four corners give hard shadows.  Pixels dark from
    one corner and lit from another (a step > 0.1 in display value; moving the light across
    its width changes an unshadowed pixel by < 0.05) are the penumbra: the soft reference must
    lie strictly between their shadowed and lit values (by 0.02, ten times its standard
    error) at 30 of them or more (the slab's shadow outline is ~25 pixels around, its
    penumbra ~5 wide).  Pixels shadowed from all four corners are the umbra: the light never
    reaches them, so the reference equals the shadowed level there exactly."""
    r = pa.make_renderer(SHADOW)
    corners = np.stack([r.frame([x, y]) for x in (0.0, 1.0) for y in (0.0, 1.0)])[..., 1]
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    ref = shadow_reference[..., 1]
    half_lit = hi - lo > 0.1
    between = half_lit & (ref > lo + 0.02) & (ref < hi - 0.02)
    assert half_lit.sum() >= 50 and between.sum() >= 30, (int(half_lit.sum()), int(between.sum()))
    levels, counts = np.unique(lo[half_lit], return_counts=True)
    shadowed = levels[np.argmax(counts)]       # the ground under ambient light only: one byte value
    umbra = hi == shadowed
    assert umbra.sum() >= 4 and np.all(ref[umbra] == shadowed), (int(umbra.sum()), shadowed)


@pytest.mark.slow
@pytest.mark.parametrize("points", ["random", "stratified", "sobol"])
def test_soft_shadow_estimate_is_unbiased(shadow_reference_parts, shadow_replicas, points):
    """Per-pixel-channel Welch t of 8 replicas of 64 frames against the 8 random reference
    parts, Bonferroni over the channels that vary (~3000) at family-wise alpha = 1e-3;
    channels constant in every frame (umbra, faces the light never reaches) must match
    exactly.  The level is nominal: it rests on the t law of the random parts (256 iid frames
    each), whose variance dominates the stratified and Sobol' replicas' wherever those can be
    lopsided mixtures.  Where all frames of one side miss a rare shadow, the other side's
    standard error grows with the square root of its probability and keeps |t| moderate:
    over six seed sets (this one and five others, run once to check the level) the largest
    |t| over all channels was 2.1 to 3.7 for every point set, never near the ~6 that
    Bonferroni needs."""
    p, tested, mismatched = pixel_bias(shadow_replicas[points], shadow_reference_parts)
    assert tested > 1000 and mismatched == 0, (tested, mismatched)
    assert p > 1e-3, f"{points}: Bonferroni p = {p:.3g} over {tested} channels"


@pytest.mark.slow
def test_bias_test_detects_a_wrong_light(shadow_reference_parts, shadow_replicas):
    """The same test, random points, with the light 25 % too small (a wrong scale in the
    light-point map) against the unit light's reference: rejected at alpha = 1e-3.  Measured
    Bonferroni p over four seed sets: 3e-10 to 1e-8, so this is power, not luck.  (A disk of
    the square's width is near the limit: p 1e-6 to 4e-4.)"""
    p, tested, _ = pixel_bias(shadow_replicas["small"], shadow_reference_parts)
    assert p < 1e-3, f"light 25 % too small not detected: Bonferroni p = {p:.3g} over {tested} channels"


@pytest.mark.slow
def test_stratified_beats_random_at_equal_frames(shadow_reference, shadow_replicas):
    """RMSE against the Sobol' reference at 64 frames over 8 replicas.  Jittered light points
    cut the variance of penumbra pixels by ~n^-1/2 (RMSE ratio ~0.35 at 64 frames) and of
    smoothly lit pixels by more, so stratified must at least halve random's RMSE, and Sobol'
    (a (0,m,2)-net, at least as well stratified) must not be worse than stratified x 1.5;
    the printed ratios carry standard errors from the replicas' spread (measured over six
    seed sets: stratified/random 0.27-0.33, Sobol'/random 0.10-0.13)."""
    mse = {k: np.mean((shadow_replicas[k] - shadow_reference) ** 2, axis=(1, 2, 3))
           for k in ("random", "stratified", "sobol")}
    rmse = {k: float(np.sqrt(v.mean())) for k, v in mse.items()}

    def rel_se(v: np.ndarray) -> float:
        return float(v.std(ddof=1) / np.sqrt(v.size) / v.mean() / 2)   # of sqrt(mean MSE)

    def ratio(a: str, b: str) -> str:
        q = rmse[a] / rmse[b]
        return f"{a}/{b} {q:.3f} +- {q * np.hypot(rel_se(mse[a]), rel_se(mse[b])):.3f}"

    detail = f"RMSE {rmse}; {ratio('stratified', 'random')}; {ratio('sobol', 'random')}"
    assert rmse["stratified"] < 0.5 * rmse["random"], detail
    assert rmse["sobol"] < 1.5 * rmse["stratified"], detail
