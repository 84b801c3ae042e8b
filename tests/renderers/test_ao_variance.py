"""The AO renderer's reported variance (renderers.ao.pooled_variance): honest near 0 and 1, and per AO band."""

from __future__ import annotations

import numpy as np
import pytest

from renderers.ao import box_sum, pooled_variance


def test_box_sum_is_the_clipped_window_sum():
    a = np.arange(30.0).reshape(5, 6, 1)
    s = box_sum(a, 1)
    assert s[0, 0, 0] == a[:2, :2].sum() and s[2, 3, 0] == a[1:4, 2:5].sum() and s[4, 5, 0] == a[3:, 4:].sum()


def _batches(p: np.ndarray, n: int, rng, k: int = 8):
    """Pixel means of n iid Bernoulli(p) samples in k batches, and the film's batch variance of the mean."""
    counts = rng.binomial(n // k, p[None], size=(k,) + p.shape)
    means = counts / (n // k)
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
    there to measure one); with one gain window over the whole image the reported variances sum to the batch
    estimates' sum exactly (pooling moves variance, never adds or removes it), and pixels marked exact report 0."""
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
    v = pooled_variance(mean, bvar, n, exact, gain_radius=100)
    assert np.all(v[:2] == 0) and np.all(v[2:] > 0)
    assert v.sum() == pytest.approx(bvar.sum(), rel=1e-12)


@pytest.mark.slow
def test_ao_z_spread_per_band_over_8_seeds():
    """ao on cornell-box-ao at 64 spp, 256², seeds 0-7 (about 30 s): per band of the reference's AO, the spread of
    z = d/√(reported + reference variance) over seeds (within pixel; exact pixels, d = 0, left out) is within
    0.9-1.1 in every band with ≥ 200 pixels: measured 0.965-1.064 (benchmarks/variance_honesty.py). The one
    smaller band, [0.1, 0.2), is 39 pixels along the ceiling's front edge, half outside the box, whose pooled
    gain comes from neighbours with a lower one: 1.38 there, not met (docs/gate-detection.md). With the film's
    8-batch variance the bands were 1.48-8.5 in rms z, |z| up to 68."""
    from benchmarks.variance_honesty import BANDS, band_spreads
    from harness.adapters.registry import resolve
    from harness.scenes.library import resolve_scene
    from harness.store.references import load_reference

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
    tested = [(lo, sp) for lo, sp, n in zip(BANDS, spread, counts) if n >= 200]
    assert len(tested) >= 8, counts
    assert all(0.9 <= sp <= 1.1 for _, sp in tested), tested
