"""The AO renderer's reported variance (cornell_harness.renderers.ao.pooled_variance): honest near 0 and 1, along edges, and per
AO band."""

from __future__ import annotations

import numpy as np
import pytest

from cornell_harness.renderers.ao import alike_pixels, pooled_variance, shifted, stabilised


def test_shifted_moves_the_image_and_masks_what_comes_from_outside():
    a = np.arange(30.0).reshape(5, 6, 1)
    out, inside = shifted(a, 1, -2)
    assert out[0, 2, 0] == a[1, 0, 0] and out[3, 5, 0] == a[4, 3, 0]
    assert not inside[4].any() and not inside[:, :2].any() and inside[:4, 2:].all() and np.all(out[~inside[..., 0]] == 0)


def test_alike_pixels_join_across_noise_and_along_an_edge_but_not_across_it():
    """9×9 images of AO 0.5 at 64 samples, with a pixel of 0.55 (0.8 σ off in the stabilised scale: alike).

    - With a row of 0.9 (an edge), from the row's middle the 5×5 window joins the row's five pixels only;
      from the pixel above it, the 0.55 pixel and the pixels of 0.5 above the row, none of the row or below.
    - With a diagonal line of 0.9 a pixel wide (an edge as drawn, 8-connected), from a pixel beside it every
      joined pixel is on its side: 4-neighbour steps cannot cross the line. The line's own pixels are joined
      to none of each other for the same reason (each takes its gain from its own batches).
    """
    n = 64
    assert abs(stabilised(0.55, n) - stabilised(0.5, n)) < 3 / np.sqrt(2 * n) < stabilised(0.9, n) - stabilised(0.5, n)
    row = np.full((9, 9, 1), 0.5)
    row[4], row[2, 3] = 0.9, 0.55
    joined = alike_pixels(row, n, 2)
    assert {o for o, m in joined.items() if m[4, 4, 0]} == {(0, -2), (0, -1), (0, 0), (0, 1), (0, 2)}
    above = {o for o, m in joined.items() if m[3, 4, 0]}
    assert (-1, -1) in above and all(dy < 1 for dy, _ in above) and len(above) == 15  # rows 1-3, five each
    line = np.full((9, 9, 1), 0.5)
    for k in range(9):
        line[k, 8 - k] = 0.9
    line[2, 3] = 0.55
    joined = alike_pixels(line, n, 2)
    beside = {o for o, m in joined.items() if m[3, 4, 0]}  # (3, 4): left of the line, which passes (3, 5)
    assert (-1, -1) in beside and all(3 + dy + 4 + dx < 8 for dy, dx in beside)
    assert {o for o, m in joined.items() if m[4, 4, 0]} == {(0, 0)}


def _batches(p: np.ndarray, n: int, rng, k: int = 8, per_batch: np.ndarray | None = None):
    """Pixel means of iid Bernoulli(p) samples in k batches, and the film's batch variance of the mean.

    ``per_batch`` (samples per batch per pixel, default n/k) models stratification: a batch mean of m ≥ n/k
    samples has the variance of n/k stratified ones with gain (n/k)/m."""
    m = np.full(p.shape, n // k) if per_batch is None else per_batch
    means = rng.binomial(m[None], p[None], size=(k,) + p.shape) / m[None]
    return means.mean(axis=0), means.var(axis=0, ddof=1) / k


def test_pooled_variance_is_right_on_average_and_not_zero_near_one():
    """iid Bernoulli samples (gain 1) in 8 batches, 64 per pixel, 64×64 pixels at p = 0.3 and 0.995, seed 0.

    - At p = 0.3 the mean reported variance is p(1 − p)/64 within 3% (4096 pixels, ~25·7 dof each window).
    - At p = 0.995, 73% of pixels read 1 with batch variance 0; pooled, each reports a variance > 0, and the
      squared errors over the region are 0.5-1.25 of the reported variances (the Jeffreys half sample
      overstates where every sample agreed, 0.56: conservative, not 4× off).
    """
    rng = np.random.default_rng(0)
    n = 64
    for p, tol in ((0.3, 0.03), (0.995, 0.25)):
        truth = np.full((64, 64, 1), p)
        mean, bvar = _batches(truth, n, rng)
        v = pooled_variance(mean, bvar, n)
        if p < 0.5:
            assert v.mean() == pytest.approx(p * (1 - p) / n, rel=tol)
        else:
            assert (bvar == 0).mean() > 0.6 and np.all(v > 0)
            ratio = ((mean - p) ** 2).sum() / v.sum()
            assert 0.5 < ratio < 1 + tol, ratio  # measured 0.56: the half sample overstates, never understates


def test_agreeing_pixels_report_the_half_sample_and_pooling_keeps_the_sum():
    """A window of pixels whose samples all read 1 reports the half-sample variance (no gain: nothing varies
    there to measure one). With one gain window over the whole image the reported variances sum to the batch
    estimates' sum exactly, over all pixels where all are alike (sigmas = inf) and over each of two AO levels
    where they are not (pooling moves variance between alike pixels, never adds or removes any); pixels
    marked exact report 0."""
    n = 64
    mean = np.ones((12, 12, 1))
    bvar = np.zeros_like(mean)
    half = 0.5 / (8 * n + 1) * (8 * n + 0.5) / (8 * n + 1) / n  # half a sample in the neighbours' 8n
    assert np.allclose(pooled_variance(mean, bvar, n)[1:-1, 1:-1], half, rtol=1e-12, atol=0)
    rng = np.random.default_rng(1)
    mean, bvar = _batches(rng.uniform(0.0, 1.0, (12, 12, 1)), n, rng)
    mean[:2], bvar[:2] = 0.0, 0.0
    exact = np.zeros(mean.shape, bool)
    exact[:2] = True
    v = pooled_variance(mean, bvar, n, exact, gain_radius=11, sigmas=np.inf)
    assert np.all(v[:2] == 0) and np.all(v[2:] > 0)
    assert v.sum() == pytest.approx(bvar.sum(), rel=1e-12)
    mean = np.where(np.arange(12)[None, :, None] < 6, 0.2, 0.9) * np.ones((12, 1, 1))  # two halves, unlike
    bvar = rng.uniform(0.0, 1e-3, mean.shape)
    v = pooled_variance(mean, bvar, n, gain_radius=11)
    for half in (slice(0, 6), slice(6, 12)):
        assert v[:, half].sum() == pytest.approx(bvar[:, half].sum(), rel=1e-12)


def test_an_edge_row_gets_its_own_gain_and_its_neighbours_theirs():
    """Five rows of 512 pixels, 64 samples in 8 batches, seeds 0-3: AO 0.94 with no stratification gain, a
    one-pixel edge row at AO 0.2 with gain ½, and AO 0.9 with gain ¼ (cornell-box-ao's ceiling edge,
    measured: 0.19 with 0.55 between 0.94 with 0.7 and 0.9 with 0.2). Per row, the mean reported variance is
    its true g·p(1 − p)/64 within 10% (measured 0.97-1.05), and the mean z² is within 1 ± 0.3 (measured
    0.92-1.23; its standard error over 512 pixels is about 0.07, and an estimated variance's own spread
    raises E z², most in the edge row, whose gain has 5 × 7 dof). Pooled across the edge, as before
    (sigmas = inf), the edge row reports 0.72 of its variance and the row below it 2.5 times its own."""
    n = 64
    rows = np.array([[0.94, 8], [0.94, 8], [0.2, 16], [0.9, 32], [0.9, 32]])  # AO, samples per batch (gain 8/m)
    p = rows[:, 0, None, None] * np.ones((5, 512, 1))
    per_batch = (rows[:, 1, None, None] * np.ones((5, 512, 1))).astype(int)
    true = p * (1 - p) / (8 * per_batch)
    for seed in range(4):
        mean, bvar = _batches(p, n, np.random.default_rng(seed), per_batch=per_batch)
        v = pooled_variance(mean, bvar, n)
        assert np.allclose(v.mean(axis=(1, 2)) / true.mean(axis=(1, 2)), 1.0, atol=0.1)
        assert np.allclose((((mean - p) ** 2) / v).mean(axis=(1, 2)), 1.0, atol=0.3)
        across = pooled_variance(mean, bvar, n, sigmas=np.inf).mean(axis=(1, 2)) / true.mean(axis=(1, 2))
        assert across[2] < 0.8 and across[3] > 2.0


@pytest.mark.slow
def test_ao_z_spread_per_band_over_8_seeds():
    """ao on cornell-box-ao at 64 spp, 256², seeds 0-7 (about 20 s): per band of the reference's AO, the spread of
    z = d/√(reported + reference variance) over seeds (within pixel; exact pixels, d = 0, left out), in every
    band with pixels, within the band's window (benchmarks.variance_honesty.band_window): the issue's 0.9-1.1
    for every band of 62 pixels or more, widened for a smaller band by its own sampling error: [0.78, 1.25]
    for the 39 pixels of [0.1, 0.2) (the ceiling's front edge, half outside the box, and three corners). A
    renderer whose z spread is 1 misses a window with probability below 0.1% each side (normal z); the old
    pooling, across edges, read 1.38 in that band. Measured (benchmarks/variance_honesty.py): 0.950-1.031,
    1.023 in [0.1, 0.2)."""
    from benchmarks.variance_honesty import BANDS, band_spreads, band_window
    from cornell_harness.adapters.registry import resolve
    from cornell_harness.scenes.library import resolve_scene
    from cornell_harness.store.references import load_reference

    scene = resolve_scene("cornell-box-ao")
    ref = load_reference(scene)
    r0 = ref.image[..., 0].astype(np.float64)
    renderer = resolve(["ao"])[0].renderer
    zs = []
    for s in range(8):
        r = renderer.render(scene, 64, s)
        d = r.image[..., 0].astype(np.float64) - r0
        v = r.variance[..., 0].astype(np.float64) + ref.variance[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            zs.append(np.where(d == 0, np.nan, d / np.sqrt(v)))
    spread, rms, counts, worst = band_spreads(np.array(zs), r0)
    tested = [(lo, n, sp, band_window(n, 8)) for lo, sp, n in zip(BANDS, spread, counts) if n > 0]
    assert len(tested) >= 9 and sum(n for _, n, _, _ in tested) > 0.7 * r0.size, counts
    assert all(w[0] <= sp <= w[1] for _, _, sp, w in tested), tested
