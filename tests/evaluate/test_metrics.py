"""Tests for cornell_harness.evaluate.metrics: published CIEDE2000 data, analytic values, properties."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from cornell_harness.evaluate import metrics as m

# Sharma, Wu & Dalal (2005), Table 1: (L1, a1, b1), (L2, a2, b2), ΔE00.
SHARMA_2005 = [
    ((50.0000, 2.6772, -79.7751), (50.0000, 0.0000, -82.7485), 2.0425),
    ((50.0000, 3.1571, -77.2803), (50.0000, 0.0000, -82.7485), 2.8615),
    ((50.0000, 2.8361, -74.0200), (50.0000, 0.0000, -82.7485), 3.4412),
    ((50.0000, -1.3802, -84.2814), (50.0000, 0.0000, -82.7485), 1.0000),
    ((50.0000, -1.1848, -84.8006), (50.0000, 0.0000, -82.7485), 1.0000),
    ((50.0000, -0.9009, -85.5211), (50.0000, 0.0000, -82.7485), 1.0000),
    ((50.0000, 0.0000, 0.0000), (50.0000, -1.0000, 2.0000), 2.3669),
    ((50.0000, -1.0000, 2.0000), (50.0000, 0.0000, 0.0000), 2.3669),
    ((50.0000, 2.4900, -0.0010), (50.0000, -2.4900, 0.0009), 7.1792),
    ((50.0000, 2.4900, -0.0010), (50.0000, -2.4900, 0.0010), 7.1792),
    ((50.0000, 2.4900, -0.0010), (50.0000, -2.4900, 0.0011), 7.2195),
    ((50.0000, 2.4900, -0.0010), (50.0000, -2.4900, 0.0012), 7.2195),
    ((50.0000, -0.0010, 2.4900), (50.0000, 0.0009, -2.4900), 4.8045),
    ((50.0000, -0.0010, 2.4900), (50.0000, 0.0010, -2.4900), 4.8045),
    ((50.0000, -0.0010, 2.4900), (50.0000, 0.0011, -2.4900), 4.7461),
    ((50.0000, 2.5000, 0.0000), (50.0000, 0.0000, -2.5000), 4.3065),
    ((50.0000, 2.5000, 0.0000), (73.0000, 25.0000, -18.0000), 27.1492),
    ((50.0000, 2.5000, 0.0000), (61.0000, -5.0000, 29.0000), 22.8977),
    ((50.0000, 2.5000, 0.0000), (56.0000, -27.0000, -3.0000), 31.9030),
    ((50.0000, 2.5000, 0.0000), (58.0000, 24.0000, 15.0000), 19.4535),
    ((50.0000, 2.5000, 0.0000), (50.0000, 3.1736, 0.5854), 1.0000),
    ((50.0000, 2.5000, 0.0000), (50.0000, 3.2972, 0.0000), 1.0000),
    ((50.0000, 2.5000, 0.0000), (50.0000, 1.8634, 0.5757), 1.0000),
    ((50.0000, 2.5000, 0.0000), (50.0000, 3.2592, 0.3350), 1.0000),
    ((60.2574, -34.0099, 36.2677), (60.4626, -34.1751, 39.4387), 1.2644),
    ((63.0109, -31.0961, -5.8663), (62.8187, -29.7946, -4.0864), 1.2630),
    ((61.2901, 3.7196, -5.3901), (61.4292, 2.2480, -4.9620), 1.8731),
    ((35.0831, -44.1164, 3.7933), (35.0232, -40.0716, 1.5901), 1.8645),
    ((22.7233, 20.0904, -46.6940), (23.0331, 14.9730, -42.5619), 2.0373),
    ((36.4612, 47.8580, 18.3852), (36.2715, 50.5065, 21.2231), 1.4146),
    ((90.8027, -2.0831, 1.4410), (91.1528, -1.6435, 0.0447), 1.4441),
    ((90.9257, -0.5406, -0.9208), (88.6381, -0.8985, -0.7239), 1.5381),
    ((6.7747, -0.2908, -2.4247), (5.8714, -0.0985, -2.2286), 0.6377),
    ((2.0776, 0.0795, -1.1350), (0.9033, -0.0636, -0.5514), 0.9082),
]


def _random_image(seed: int, shape=(16, 16, 3), scale: float = 1.0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(0.0, scale, size=shape)


# -- CIEDE2000 ---------------------------------------------------------------


def test_sharma_table_has_34_pairs():
    assert len(SHARMA_2005) == 34


def test_delta_e2000_lab_matches_sharma_2005_table():
    lab1 = np.array([p[0] for p in SHARMA_2005])
    lab2 = np.array([p[1] for p in SHARMA_2005])
    expected = np.array([p[2] for p in SHARMA_2005])
    np.testing.assert_allclose(m.delta_e2000_lab(lab1, lab2), expected, rtol=0, atol=1e-4)
    # The formula is symmetric; the published pairs must hold either way round.
    np.testing.assert_allclose(m.delta_e2000_lab(lab2, lab1), expected, rtol=0, atol=1e-4)


@pytest.mark.parametrize("s", [0.05, 0.18, 1.0, 3.0])
def test_linear_srgb_grey_is_neutral_in_lab(s):
    lab = m.linear_srgb_to_lab(np.full((1, 1, 3), s))[0, 0]
    expected_l = 116.0 * np.cbrt(s) - 16.0 if s > (6 / 29) ** 3 else s * (29 / 3) ** 3
    assert lab[0] == pytest.approx(expected_l, abs=1e-9)
    assert abs(lab[1]) < 1e-9 and abs(lab[2]) < 1e-9


def test_middle_grey_has_lightness_about_49_5():
    lab = m.linear_srgb_to_lab(np.full((1, 1, 3), 0.18))[0, 0]
    assert lab[0] == pytest.approx(49.496, abs=1e-3)


def test_lab_conversion_is_not_clipped_above_white():
    lab = m.linear_srgb_to_lab(np.full((1, 1, 3), 8.0))[0, 0]
    assert lab[0] == pytest.approx(116.0 * 2.0 - 16.0)


def test_delta_e2000_image_against_itself_is_zero_everywhere():
    img = _random_image(0, scale=5.0)
    mean, de_map = m.delta_e2000(img, img, full=True)
    assert de_map.shape == img.shape[:2]
    assert de_map.dtype == np.float64
    assert mean == 0.0
    assert np.all(de_map == 0.0)


def test_delta_e2000_map_is_symmetric():
    a, b = _random_image(1), _random_image(2)
    exposure = 1.7  # fixed so both orders see the same scale
    _, ab = m.delta_e2000(a, b, exposure=exposure, full=True)
    _, ba = m.delta_e2000(b, a, exposure=exposure, full=True)
    assert np.all(ab > 0)
    np.testing.assert_allclose(ab, ba, rtol=0, atol=1e-9)


def test_delta_e2000_full_path_matches_lab_helper():
    img, ref = _random_image(3), _random_image(4)
    exposure = m.exposure_scale(ref)
    mean, de_map = m.delta_e2000(img, ref, full=True)
    expected = m.delta_e2000_lab(
        m.linear_srgb_to_lab(img * exposure), m.linear_srgb_to_lab(ref * exposure)
    )
    np.testing.assert_allclose(de_map, expected, rtol=0, atol=1e-12)
    assert mean == pytest.approx(float(expected.mean()))
    assert m.delta_e2000(img, ref) == pytest.approx(mean)


def test_delta_e2000_treats_non_finite_pixels_as_black():
    ref = np.full((8, 8, 3), 0.5)
    img = ref.copy()
    img[2, 3] = [np.nan, 0.5, 0.5]
    img[5, 5] = [np.inf, 0.5, 0.5]
    _, de_map = m.delta_e2000(img, ref, full=True)
    assert np.all(np.isfinite(de_map))
    black_vs_ref = m.delta_e2000(np.zeros((1, 1, 3)), ref[:1, :1], exposure=m.exposure_scale(ref))
    assert de_map[2, 3] == pytest.approx(black_vs_ref)
    assert de_map[5, 5] == pytest.approx(black_vs_ref)
    de_map[2, 3] = de_map[5, 5] = 0.0
    assert np.all(de_map == 0.0)


# -- identities and analytic values ------------------------------------------


def test_identical_images_score_perfectly():
    img = _random_image(5, scale=2.0)
    assert m.rmse(img, img) == 0.0
    assert m.rel_mse(img, img) == 0.0
    assert m.psnr(img, img) == math.inf
    assert m.ssim(img, img) == pytest.approx(1.0, abs=1e-12)
    assert m.delta_e2000(img, img) == 0.0


def test_rmse_of_scaled_image_is_analytic():
    ref = _random_image(6)
    # img = 2 ref  =>  img - ref = ref  =>  RMSE = sqrt(mean(ref²)).
    assert m.rmse(2.0 * ref, ref) == pytest.approx(np.sqrt(np.mean(ref**2)), rel=1e-12)
    assert m.rmse(3.0 * ref, ref) == pytest.approx(2.0 * m.rmse(2.0 * ref, ref), rel=1e-12)


def test_rel_mse_of_constant_offset_is_analytic():
    ref = np.full((4, 5, 3), 0.3)
    offset = 0.1
    expected = offset**2 / (0.3**2 + 1e-2)
    assert m.rel_mse(ref + offset, ref) == pytest.approx(expected, rel=1e-12)
    assert m.rel_mse(ref + offset, ref, eps=0.5) == pytest.approx(
        offset**2 / (0.3**2 + 0.5), rel=1e-12
    )


def test_rel_mse_trim_drops_the_worst_pixels():
    ref = np.ones((10, 10, 3))
    img = ref + 0.1
    img[0, :5] = 100.0  # 5 fireflies out of 100 pixels
    clean = m.rel_mse(ref + 0.1, ref)
    assert m.rel_mse(img, ref) > 100 * clean
    assert m.rel_mse(img, ref, trim=0.05) == pytest.approx(clean, rel=1e-12)
    # Trimming fewer than the fireflies still leaves one in.
    assert m.rel_mse(img, ref, trim=0.04) > 10 * clean


def test_rel_mse_rejects_bad_trim():
    ref = np.ones((2, 2, 3))
    with pytest.raises(ValueError):
        m.rel_mse(ref, ref, trim=1.0)


def test_psnr_matches_display_encoded_mse():
    img, ref = _random_image(7), _random_image(8)
    exposure = 0.9
    mse = np.mean((m.display_encode(img, exposure) - m.display_encode(ref, exposure)) ** 2)
    assert m.psnr(img, ref, exposure=exposure) == pytest.approx(-10 * np.log10(mse), rel=1e-12)


def test_ssim_drops_for_noise_and_stays_near_one_for_tiny_noise():
    rng = np.random.default_rng(9)
    y, x = np.mgrid[0:32, 0:32] / 32.0
    ref = np.stack([x, y, 0.5 * (x + y)], axis=-1) * 0.4 + 0.05
    tiny = ref * (1.0 + 1e-5 * rng.standard_normal(ref.shape))
    noisy = ref * (1.0 + 0.3 * rng.standard_normal(ref.shape))
    assert m.ssim(tiny, ref) > 0.9999
    assert m.ssim(noisy, ref) < 0.9
    assert m.psnr(tiny, ref) > m.psnr(noisy, ref)


def test_shape_mismatch_raises_naming_both_shapes():
    a, b = np.zeros((4, 4, 3)), np.zeros((4, 5, 3))
    for fn in (m.rmse, m.rel_mse, m.psnr, m.ssim, m.delta_e2000, m.image_metrics):
        with pytest.raises(ValueError, match=r"\(4, 4, 3\).*\(4, 5, 3\)"):
            fn(a, b)


def test_non_rgb_image_is_rejected():
    with pytest.raises(ValueError):
        m.luminance(np.zeros((4, 4)))


def test_inputs_are_not_modified():
    img = _random_image(10)
    img[1, 1] = [np.nan, np.inf, -1.0]
    ref = _random_image(11)
    img0, ref0 = img.copy(), ref.copy()
    m.image_metrics(img, ref)
    m.display_encode(img, 2.0)
    np.testing.assert_array_equal(img, img0)
    np.testing.assert_array_equal(ref, ref0)


# -- exposure and display ----------------------------------------------------


def test_luminance_uses_bt709_weights():
    img = np.array([[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]]])
    np.testing.assert_allclose(m.luminance(img), [[0.2126, 0.7152, 0.0722, 1.0]], atol=1e-15)


@pytest.mark.parametrize("y", [0.01, 0.5, 40.0])
def test_exposure_scale_of_constant_image_is_analytic(y):
    ref = np.full((6, 7, 3), y)  # grey, so luminance == y
    assert m.exposure_scale(ref) == pytest.approx(0.18 / (y + 1e-4), rel=1e-12)
    assert m.exposure_scale(ref, key=0.36, delta=0.0) == pytest.approx(0.36 / y, rel=1e-12)


def test_exposure_scale_is_the_log_average_and_ignores_non_finite_pixels():
    ref = np.ones((2, 2, 3))
    ref[0, 0] = 4.0
    ref[1, 1] = 0.25
    # Log-average of {4, 1, 1, 0.25} is 1.
    assert m.exposure_scale(ref, delta=0.0) == pytest.approx(0.18, rel=1e-12)
    broken = np.concatenate([ref, np.full((2, 1, 3), np.nan)], axis=1)
    broken[0, 2, 0] = np.nan
    broken[1, 2] = [np.inf, 1.0, 1.0]
    assert m.exposure_scale(broken, delta=0.0) == pytest.approx(0.18, rel=1e-12)


def test_default_exposure_comes_from_the_reference_only():
    ref = _random_image(12)
    exposure = m.exposure_scale(ref)
    for img in (_random_image(13), 50.0 * _random_image(14)):
        assert m.delta_e2000(img, ref) == m.delta_e2000(img, ref, exposure=exposure)
        assert m.ssim(img, ref) == m.ssim(img, ref, exposure=exposure)
        assert m.psnr(img, ref) == m.psnr(img, ref, exposure=exposure)
        assert m.image_metrics(img, ref) == m.image_metrics(img, ref, exposure=exposure)


def test_display_encode_known_values():
    linear = np.array([[[0.0, 1.0, 0.0031308], [0.18, 0.5, 2.0], [-1.0, 0.001, np.nan]]])
    out = m.display_encode(linear, 1.0)
    assert out.dtype == np.float64 and out.shape == linear.shape
    expected = np.array(
        [
            [
                [0.0, 1.0, 12.92 * 0.0031308],
                [1.055 * 0.18 ** (1 / 2.4) - 0.055, 1.055 * 0.5 ** (1 / 2.4) - 0.055, 1.0],
                [0.0, 12.92 * 0.001, 0.0],
            ]
        ]
    )
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-12)
    assert out[0, 1, 0] == pytest.approx(0.4613, abs=1e-4)
    # Both branches of the piecewise OETF meet at the breakpoint.
    assert 1.055 * 0.0031308 ** (1 / 2.4) - 0.055 == pytest.approx(out[0, 0, 2], abs=1e-6)


def test_display_encode_applies_exposure_before_clipping():
    img = np.full((1, 1, 3), 0.09)
    np.testing.assert_allclose(m.display_encode(img, 2.0), m.display_encode(2.0 * img, 1.0))
    # 1.055 * 1 - 0.055 lands one ulp below 1.0 in floating point.
    np.testing.assert_allclose(m.display_encode(img, 100.0), 1.0, rtol=0, atol=1e-15)
    assert np.all(m.display_encode(img, 100.0) <= 1.0)


# -- invalid pixels, stats, the combined dict --------------------------------


def test_invalid_pixel_counts_are_per_pixel():
    img = np.ones((5, 5, 3))
    img[0, 0] = [np.nan, np.nan, np.nan]  # one pixel, three NaN channels
    img[0, 1, 2] = np.nan
    img[1, 0] = [np.inf, -np.inf, 1.0]  # one inf pixel
    img[2, 2] = [-0.1, -0.2, 0.3]  # one negative pixel
    img[3, 3, 0] = -1e-9
    img[4, 4] = [np.nan, -1.0, np.inf]  # counted in all three
    assert m.invalid_pixel_counts(img) == {"nan_count": 3, "inf_count": 2, "negative_count": 3}


def test_mean_radiance_over_finite_pixels():
    img = np.zeros((2, 2, 3))
    img[0, 0] = [1.0, 2.0, 3.0]
    img[0, 1] = [3.0, 2.0, 1.0]
    img[1, 0] = [np.nan, 100.0, 100.0]
    img[1, 1] = [2.0, 2.0, np.inf]
    radiance = m.mean_radiance(img)
    assert radiance.dtype == np.float64
    np.testing.assert_allclose(radiance, [2.0, 2.0, 2.0])


def test_delta_e2000_stats_on_constructed_map():
    de_map = np.arange(100, dtype=np.float64).reshape(10, 10) / 10.0  # 0.0 .. 9.9
    stats = m.delta_e2000_stats(de_map)
    assert set(stats) == {
        "delta_e2000_mean",
        "delta_e2000_p95",
        "delta_e2000_max",
        "delta_e2000_frac_gt_2_3",
    }
    assert stats["delta_e2000_mean"] == pytest.approx(4.95)
    assert stats["delta_e2000_p95"] == pytest.approx(9.405)  # linear interpolation
    assert stats["delta_e2000_max"] == pytest.approx(9.9)
    assert stats["delta_e2000_frac_gt_2_3"] == pytest.approx(0.76)  # 2.4 .. 9.9
    other = m.delta_e2000_stats(de_map, threshold=5.0)
    assert other["delta_e2000_frac_gt_5_0"] == pytest.approx(0.49)
    assert "delta_e2000_frac_gt_2_3" not in other


def test_image_metrics_keys_types_and_json():
    img, ref = _random_image(15), _random_image(16)
    result = m.image_metrics(img, ref)
    assert list(result) == [
        "rmse",
        "mse",
        "rel_mse",
        "rel_mse_trimmed",
        "psnr",
        "ssim",
        "delta_e2000_mean",
        "delta_e2000_p95",
        "delta_e2000_max",
        "delta_e2000_frac_gt_2_3",
        "flip_mean",
        "nan_count",
        "inf_count",
        "negative_count",
        "mean_radiance_r",
        "mean_radiance_g",
        "mean_radiance_b",
        "mean_radiance_rel_error",
    ]
    for key, value in result.items():
        assert type(value) is (int if key.endswith("_count") else float), key
    assert json.loads(json.dumps(result)) == result
    assert result["rmse"] == pytest.approx(m.rmse(img, ref))
    assert result["mse"] == pytest.approx(m.rmse(img, ref) ** 2)
    assert result["rel_mse_trimmed"] == pytest.approx(m.rel_mse(img, ref, trim=m.REL_MSE_TRIM))
    assert result["rel_mse_trimmed"] <= result["rel_mse"]
    assert result["delta_e2000_mean"] == pytest.approx(m.delta_e2000(img, ref))
    expected_rel = img.reshape(-1, 3).mean() / ref.reshape(-1, 3).mean() - 1.0
    assert result["mean_radiance_rel_error"] == pytest.approx(expected_rel, rel=1e-12)


def test_image_metrics_survives_nan_and_reports_it():
    ref = _random_image(17)
    img = ref.copy()
    img[3, 4] = [np.nan, 0.2, 0.2]
    img[7, 7] = [np.inf, np.inf, np.inf]
    img[9, 1, 1] = -0.5
    result = m.image_metrics(img, ref)
    assert result["nan_count"] == 1
    assert result["inf_count"] == 1
    assert result["negative_count"] == 1
    for key in ("rmse", "rel_mse", "psnr", "ssim", "delta_e2000_mean", "delta_e2000_max"):
        assert math.isfinite(result[key]), key
    assert result["rmse"] > 0 and result["delta_e2000_max"] > 0
    # Error metrics see broken pixels as black (the whole pixel, not just the bad channel).
    zeroed = img.copy()
    zeroed[3, 4] = zeroed[7, 7] = 0.0
    assert result["rmse"] == pytest.approx(m.rmse(zeroed, ref), rel=1e-12)


@pytest.mark.parametrize("broken", [False, True])
def test_image_metrics_keys_computes_those_asked_for_with_the_same_values(broken):
    """``keys`` computes only what they need (and what comes free with it), each value bit-identical to the
    full set's, with and without broken pixels (the fast paths of an image without NaN or Inf, and the rest)."""
    img, ref = _random_image(21, (20, 20, 3)), _random_image(22, (20, 20, 3))
    if broken:
        img[2, 3] = [np.nan, 0.2, 0.2]
        img[5, 5, 2] = np.inf
        img[7, 1, 0] = -0.25
    full = m.image_metrics(img, ref, with_flip=False)
    groups = {
        "rmse": {"rmse", "mse"},
        "rel_mse": {"rel_mse"},
        "rel_mse_trimmed": {"rel_mse", "rel_mse_trimmed"},
        "psnr": {"psnr"},
        "ssim": {"ssim"},
        "delta_e2000_p95": set(m.DELTA_E_KEYS),
        "nan_count": {"nan_count", "inf_count", "negative_count"},
        "mean_radiance_rel_error": {"mean_radiance_r", "mean_radiance_g", "mean_radiance_b",
                                    "mean_radiance_rel_error"},
    }
    for key, computed in groups.items():
        got = m.image_metrics(img, ref, with_flip=False, keys=[key])
        assert set(got) == computed, key
        assert all(got[k] == full[k] for k in got), key
    assert m.image_metrics(img, ref, keys=["rmse"]).keys() == {"rmse", "mse"}  # no FLIP unless asked for
    assert "flip_mean" in m.image_metrics(img, ref, keys=["flip_mean"])


def test_all_finite_sees_nan_inf_and_not_an_overflowing_sum():
    from cornell_harness.evaluate.pixels import all_finite, finite_pixels

    assert all_finite(np.ones((2, 2, 3)))
    assert all_finite(np.full((2, 2, 3), 1e308))  # the sum overflows; every value is finite
    for bad in (np.nan, np.inf, -np.inf):
        img = np.ones((2, 2, 3))
        img[1, 0, 2] = bad
        assert not all_finite(img)
        assert finite_pixels(img).tolist() == [[True, True], [False, True]]


def test_channel_mean_is_numpys_mean_over_the_last_axis_bit_for_bit():
    x = np.random.default_rng(23).lognormal(0.0, 3.0, size=(64, 64, 3))
    assert np.array_equal(m.channel_mean(x), np.mean(x, axis=-1))
