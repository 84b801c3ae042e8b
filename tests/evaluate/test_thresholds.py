"""compare-image's thresholds: parsed against the registry, their direction from it, the pixel fraction."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cornell_harness.evaluate.thresholds import Threshold, ThresholdError, broken, fraction_above, parse_threshold


def test_parse_and_direction():
    t = parse_threshold("delta_e2000_mean=0.1", "fail")
    assert t == Threshold("delta_e2000_mean", 0.1, "fail") and t.direction == "max"
    assert parse_threshold("PSNR=30", "warn") == Threshold("psnr", 30.0, "warn")  # any case, registry spelling
    assert parse_threshold("psnr=30", "warn").direction == "min"
    assert parse_threshold("mean_radiance_rel_error=0.01", "fail").direction == "abs_max"
    assert parse_threshold("region.caustic.rel_mse=0.01", "fail").direction == "max"


@pytest.mark.parametrize("text, words", [("delta_e200_mean=1", "did you mean 'delta_e2000_mean'?"),
                                         ("rmse", "expected METRIC=VALUE"), ("rmse=abc", "is not a number"),
                                         ("rmse=nan", "finite"), ("time_s=3", "unknown metric"),
                                         ("region.caustic.rmsee=1", "did you mean 'rmse'?")])
def test_bad_thresholds_are_refused(text, words):
    with pytest.raises(ThresholdError) as e:
        parse_threshold(text, "fail")
    assert words in str(e.value)


@pytest.mark.parametrize("text, words", [
    ("delta_e2000_mean=-1", "delta_e2000_mean is at least 0, so -1 would fail every image"),
    ("ssim=1.5", "ssim is between -1 and 1, so 1.5 would fail every image"),
    ("ssim=-2", "would pass every image"), ("rmse=-0.1", "rmse is at least 0"), ("rel_mse=-1", "rel_mse"),
    ("flip_mean=1.5", "flip_mean is between 0 and 1, so 1.5 would pass every image"),
    ("flip_mean=-0.5", "flip_mean"), ("nan_count=-1", "nan_count is at least 0"),
    ("delta_e2000_frac_gt_2_3=2", "between 0 and 1"),
    ("mean_radiance_rel_error=-0.1", "|mean_radiance_rel_error| is at least 0"),
    ("region.caustic.rmse=-1", "region.caustic.rmse is at least 0"),
    ("region.caustic.mean_z=-3", "|region.caustic.mean_z| is at least 0"),
])
def test_thresholds_outside_the_metric_range_are_refused(text, words):
    with pytest.raises(ThresholdError) as e:
        parse_threshold(text, "warn")
    assert words in str(e.value) and str(e.value).startswith(repr(text))


@pytest.mark.parametrize("text", ["ssim=1", "ssim=-1", "ssim=0.5", "delta_e2000_mean=0", "flip_mean=1", "psnr=0",
                                  "nan_count=0", "mean_radiance_rel_error=0", "region.caustic.mean_z=3"])
def test_thresholds_at_the_ends_of_the_range_are_accepted(text):
    assert parse_threshold(text, "fail").value == float(text.split("=")[1])


def test_exceeded_each_way():
    assert Threshold("rmse", 0.1, "fail").exceeded(0.2) and not Threshold("rmse", 0.1, "fail").exceeded(0.1)
    assert Threshold("ssim", 0.9, "fail").exceeded(0.5) and not Threshold("ssim", 0.9, "fail").exceeded(0.95)
    signed = Threshold("mean_radiance_rel_error", 0.01, "fail")
    assert signed.exceeded(-0.02) and not signed.exceeded(-0.005)
    assert Threshold("rmse", 0.1, "fail").exceeded(math.nan) and Threshold("rmse", 0.1, "fail").exceeded(None)
    row = {"rmse": 0.2, "ssim": 0.95}
    assert broken([Threshold("ssim", 0.99, "warn"), Threshold("rmse", 0.1, "fail"), Threshold("ssim", 0.9, "fail")],
                  row) == [Threshold("rmse", 0.1, "fail"), Threshold("ssim", 0.99, "warn")]
    assert Threshold("ssim", 0.99, "warn").line("a", 0.95) == "a: ssim = 0.95 < 0.99 (--warn)"


def test_fraction_above():
    errors = np.array([[0.0, 1.0], [2.0, np.nan]])
    assert fraction_above(errors, 1.0) == 0.5  # 2 and NaN (a NaN cannot be shown to pass)
    assert fraction_above(errors, 5.0) == 0.25


def test_a_check_computes_what_it_names_and_the_cheap_metrics():
    from cornell_harness.evaluate.registry import CHEAP_METRICS, IMAGE_METRICS, check_metrics

    assert {"rmse", "rel_mse", "mean_radiance_rel_error", "nan_count"} <= set(CHEAP_METRICS) <= set(IMAGE_METRICS)
    for costly in ("ssim", "psnr", "delta_e2000_mean", "flip_mean", "rel_mse_trimmed", "noise_delta_e2000_mean"):
        assert costly not in CHEAP_METRICS
    chosen = check_metrics(["ssim", "region.caustic.rmse"])
    assert chosen == set(CHEAP_METRICS) | {"ssim", "region.caustic.rmse"} and "psnr" not in chosen
