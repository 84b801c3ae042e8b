"""Noise yardsticks: z-score calibration and the noise image."""

import numpy as np
import pytest

from cornell_harness.evaluate import noise as stats


def test_mean_radiance_z_is_standard_normal_under_the_noise_model():
    """With channels perfectly correlated (the bound used), z ~ N(0, 1)."""
    rng = np.random.default_rng(1)
    ref = np.full((32, 32, 3), 0.5)
    ref_var = np.full_like(ref, 1e-4)
    ref_spp, spp = 1024, 16
    sd = np.sqrt(stats.difference_variance(ref_var, ref_spp, spp))
    zs = []
    for _ in range(400):
        common = rng.standard_normal((32, 32, 1))  # same deviate for all channels
        zs.append(stats.mean_radiance_z(ref + sd * common, ref, ref_var, ref_spp, spp))
    assert abs(np.mean(zs)) < 4 / np.sqrt(400)  # 4 standard errors: false alarm < 1e-4
    assert 0.85 < np.std(zs) < 1.15


def test_mean_radiance_z_detects_a_one_percent_bias():
    ref = np.full((64, 64, 3), 0.5)
    ref_var = np.full_like(ref, 1e-6)
    assert stats.mean_radiance_z(ref * 1.01, ref, ref_var, 1024, 64) > 10


def test_noise_image_has_the_scaled_variance():
    rng = np.random.default_rng(2)
    ref = np.full((128, 128, 3), 1.0)
    noise = ref + rng.standard_normal(ref.shape) * np.sqrt(1 / 128)  # 128-spp batch of unit variance
    img = stats.noise_image(ref, noise, noise_spp=128, ref_spp=10**9, spp=32)
    assert np.var(img - ref) == pytest.approx(1 / 32, rel=0.02)
