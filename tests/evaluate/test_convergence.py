"""Derived figures: slopes, time to target, efficiency, bias/variance, spp and target parsing."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from cornell_harness.evaluate import convergence as cv
from cornell_harness.durations import parse_duration
from cornell_harness.workflows.spp_list import parse_spp_list


def _runs(slope: float, seeds=4, noise=0.0, bias=0.0, rng=None) -> pd.DataFrame:
    rng = rng or np.random.default_rng(0)
    rows = []
    for seed in range(seeds):
        for spp in (1, 2, 4, 8, 16, 32):
            rmse = math.sqrt((0.5 * spp**slope * math.exp(noise * rng.standard_normal())) ** 2 + bias**2)
            rows.append({"renderer": "r", "status": "ok", "seed": seed, "spp": spp, "time_s": 0.1 * spp,
                         "rmse": rmse, "mse": rmse**2, "delta_e2000_mean": 10 * rmse, "rel_mse": rmse**2})
    return pd.DataFrame(rows)


def test_loglog_slope_exact():
    x = np.array([1, 2, 4, 8.0])
    assert cv.loglog_slope(x, 3 * x**-0.5) == pytest.approx(-0.5)
    assert math.isnan(cv.loglog_slope([1, 1], [1, 2]))
    assert math.isnan(cv.loglog_slope([1], [1]))


def test_slope_over_seeds_with_ci():
    mean, half = cv.slope_over_seeds(_runs(-0.5, seeds=8, noise=0.05))
    assert mean == pytest.approx(-0.5, abs=3 * half) and 0 < half < 0.05
    exact, zero = cv.slope_over_seeds(_runs(-0.5, seeds=3))
    assert exact == pytest.approx(-0.5) and zero == pytest.approx(0.0, abs=1e-12)


def test_bias_flattens_the_slope():
    assert cv.slope_over_seeds(_runs(-0.5, bias=0.3))[0] > -0.3


def test_time_to_target_interpolates_loglog():
    runs = _runs(-0.5, seeds=1)  # rmse = 0.5 / sqrt(spp), time = 0.1 spp
    # rmse 0.125 is reached at spp 16 exactly -> t = 1.6 s; 0.15 lies between spp 8 and 16.
    assert cv.time_to_target(runs, "rmse", 0.125) == pytest.approx(1.6)
    expected = 0.1 * (0.5 / 0.15) ** 2  # on the power law, interpolation in log-log is exact
    assert cv.time_to_target(runs, "rmse", 0.15) == pytest.approx(expected)
    assert math.isnan(cv.time_to_target(runs, "rmse", 1e-6))


def test_summarize_columns():
    s = cv.summarize(_runs(-0.5))
    assert list(s["renderer"]) == ["r"] and s["max_spp"].iloc[0] == 32 and s["seeds"].iloc[0] == 4
    assert s["slope_rmse_spp"].iloc[0] == pytest.approx(-0.5)
    assert s["slope_rmse_time"].iloc[0] == pytest.approx(-0.5)  # time ∝ spp here
    assert s["efficiency"].iloc[0] == pytest.approx(1 / ((0.5**2 / 32) * 3.2))
    for metric, value in cv.DEFAULT_TARGETS:
        assert cv.target_column(metric, value) in s


def test_bias_variance_separates_bias_from_noise():
    rng = np.random.default_rng(3)
    ref = np.full((64, 64, 3), 0.5)
    ref_var = np.zeros_like(ref)
    unbiased = [ref + 0.1 * rng.standard_normal(ref.shape) for _ in range(4)]
    biased = [ref + 0.05 + 0.1 * rng.standard_normal(ref.shape) for _ in range(4)]
    u = cv.bias_variance(unbiased, ref, ref_var)
    b = cv.bias_variance(biased, ref, ref_var)
    assert u["variance"] == pytest.approx(0.01, rel=0.05) and abs(u["bias2"]) < 2e-4
    assert b["bias2"] == pytest.approx(0.0025, rel=0.1) and b["bias2_fraction"] > 0.15
    det = cv.bias_variance([ref + 0.05], ref, ref_var, deterministic=True)
    assert det["variance"] == 0 and det["bias2"] == pytest.approx(0.0025) and det["bias2_fraction"] == 1
    assert math.isnan(cv.bias_variance([ref], ref, ref_var)["bias2"])


def test_region_bias_variance_finds_the_biased_region():
    """Bias 0.05 on the left half only, noise 0.1 everywhere: the left has bias² 0.0025, the right none; the
    image-wide bias² is their mean, diluted to half. An empty region is NaN; a stacked array works as a list."""
    rng = np.random.default_rng(4)
    ref = np.full((64, 64, 3), 0.5)
    ref_var = np.zeros_like(ref)
    left = np.zeros((64, 64), bool)
    left[:, :32] = True
    bias = np.where(left[..., None], 0.05, 0.0)
    images = np.stack([ref + bias + 0.1 * rng.standard_normal(ref.shape) for _ in range(8)])
    masks = {"left": left, "right": ~left, "none": np.zeros_like(left)}
    out = cv.region_bias_variance(images, ref, ref_var, masks)
    assert list(out) == ["left", "right", "none"]
    assert out["left"]["bias2"] == pytest.approx(0.0025, rel=0.15) and out["left"]["bias2_fraction"] > 0.15
    assert abs(out["right"]["bias2"]) < 2e-4 and out["right"]["bias2_fraction"] < 0.03
    for name in ("left", "right"):
        assert out[name]["variance"] == pytest.approx(0.01, rel=0.05)
    assert all(math.isnan(v) for v in out["none"].values())
    whole = cv.bias_variance(list(images), ref, ref_var)
    assert whole["bias2"] == pytest.approx((out["left"]["bias2"] + out["right"]["bias2"]) / 2)
    det = cv.region_bias_variance(images[:1], ref, ref_var, masks, deterministic=True)
    assert det["left"]["variance"] == 0 and det["right"]["bias2"] == pytest.approx(0.01, rel=0.05)
    assert math.isnan(cv.region_bias_variance(images[:1], ref, ref_var, masks)["left"]["bias2"])


@pytest.mark.parametrize("text, expected", [
    ("1,2,4,...,256", [1, 2, 4, 8, 16, 32, 64, 128, 256]), ("1-16", [1, 2, 4, 8, 16]),
    ("4,1,16", [1, 4, 16]), ("10,20,...,50", [10, 20, 30, 40, 50]), ("1, 2, 4, …, 8", [1, 2, 4, 8])])
def test_parse_spp_list(text, expected):
    assert parse_spp_list(text) == expected


@pytest.mark.parametrize("text", ["a,b", "0,1", "4,2,...,1", "1,...,8", "1,2,...,9,10", ""])
def test_parse_spp_list_errors(text):
    with pytest.raises(ValueError, match="spp list"):
        parse_spp_list(text)


def test_parse_target_and_duration():
    assert cv.parse_target("rel_mse=1e-3") == ("rel_mse", 1e-3)
    assert cv.parse_target("delta_e2000_mean<=1") == ("delta_e2000_mean", 1.0)
    assert cv.parse_target("2") == ("delta_e2000_mean", 2.0)
    assert cv.parse_target("region.glass-shadow.rel_mse=0.05") == ("region.glass-shadow.rel_mse", 0.05)
    for bad in ("rel_msee=1", "region.caustic.pixels=10", "region..rel_mse=1"):
        with pytest.raises(ValueError, match="unknown metric"):
            cv.parse_target(bad)
    targets = [("rel_mse", 0.1), ("region.caustic.rel_mse", 0.05), ("region.floor.rmse", 1.0)]
    assert cv.unknown_target_regions(targets, {"floor": None}) == ["caustic"]
    with pytest.raises(ValueError):
        cv.parse_target("ssim>=0.9")
    assert cv.parse_target("rel_mse=0") == ("rel_mse", 0.0)  # the end of its range: taken
    for bad, words in (("rel_mse=-1e-3", "rel_mse is at least 0"), ("flip_mean=1.5", "between 0 and 1"),
                       ("1e999", "must be finite")):
        with pytest.raises(ValueError, match=words):
            cv.parse_target(bad)
    assert [parse_duration(t) for t in ("10s", "2m", "500ms", "1.5")] == [10, 120, 0.5, 1.5]
    with pytest.raises(ValueError):
        parse_duration("soon")
