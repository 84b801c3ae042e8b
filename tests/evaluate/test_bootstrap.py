"""Intervals of the time-derived figures and of the bias split: coverage on simulated experiments with a known
truth, what an interval covers, the time column, and the bias share's significance."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from cornell_harness.evaluate import bootstrap
from cornell_harness.evaluate import convergence as cv

SIGMA2, C = 0.04, 0.01  # true MSE = SIGMA2 / spp, true time = C · spp
SPPS = (1, 2, 4, 8, 16, 32, 64)
TARGET = 1e-3  # MSE target: reached at spp 40, so at 0.4 s
TRUE_EFFICIENCY = 1 / (SIGMA2 * C)
TRUE_TIME = C * SIGMA2 / TARGET
COL = cv.target_column("rel_mse", TARGET)


def experiment(rng, seeds=3, repeats=3, err_noise=0.05, speed_noise=0.1, repeat_noise=0.1) -> pd.DataFrame:
    """One renderer's converge results: per seed a noisy error curve on the known power law, the seed's cell
    timed on a machine of random speed (log-normal), the final checkpoint re-timed ``repeats`` times (its
    time the median), as helper columns time_repeats / time_samples_s hold them. Every noise is symmetric in
    log, so the median over seeds of each figure is unbiased for the truth."""
    rows = []
    for seed in range(seeds):
        speed = speed_noise * rng.standard_normal()
        for spp in SPPS:
            mse = SIGMA2 / spp * math.exp(err_noise * rng.standard_normal())
            k = repeats if spp == SPPS[-1] else 1
            ts = C * spp * np.exp(speed + repeat_noise * rng.standard_normal(k))
            rows.append({"renderer": "r", "status": "ok", "seed": seed, "spp": spp, "mse": mse,
                         "rmse": math.sqrt(mse), "rel_mse": mse, "time_s": float(np.median(ts)),
                         "time_repeats": k, "time_samples_s": json.dumps(ts.tolist()),
                         "cpu_time_s": 2 * float(np.median(ts)), "cpu_time_samples_s": json.dumps((2 * ts).tolist())})
    return pd.DataFrame(rows)


def test_intervals_cover_the_truth_17_to_20_times_in_20():
    """Issue 30: 20 simulated experiments (3 seeds, 3 timing repeats), the 95% intervals of efficiency and of
    time-to-error contain the known truth 17-20 times. Measured over 200: 199 and 196 (and 194/181 at 2
    seeds, 192/192 without repeats). Not merely wide: the median interval spans less than 4x."""
    rng = np.random.default_rng(30)
    eff_hits = time_hits = 0
    widths = []
    for _ in range(20):
        s = cv.summarize(experiment(rng), targets=(("rel_mse", TARGET),)).iloc[0]
        eff_hits += s["efficiency_low"] <= TRUE_EFFICIENCY <= s["efficiency_high"]
        time_hits += s[COL + "_low"] <= TRUE_TIME <= s[COL + "_high"]
        widths += [s["efficiency_high"] / s["efficiency_low"], s[COL + "_high"] / s[COL + "_low"]]
        assert s["efficiency_low"] < s["efficiency"] < s["efficiency_high"]
    assert 17 <= eff_hits <= 20 and 17 <= time_hits <= 20
    assert np.median(widths) < 4


def test_interval_basis_says_what_it_covers():
    rng = np.random.default_rng(1)
    both = cv.summarize(experiment(rng)).iloc[0]
    assert both["interval_basis"] == "seeds and timing repeats" and both["time_repeats"] == 3
    old = experiment(rng, repeats=1).drop(columns=["time_samples_s", "time_repeats"])  # results from before repeats
    seeds_only = cv.summarize(old).iloc[0]
    assert seeds_only["interval_basis"].startswith("seeds only") and seeds_only["time_repeats"] == 1
    assert seeds_only["efficiency_low"] < seeds_only["efficiency"] < seeds_only["efficiency_high"]
    one = cv.summarize(experiment(rng, seeds=1)).iloc[0]  # compare: one seed, its timing repeats
    assert one["interval_basis"] == "timing repeats only (one seed)"
    assert one["time_at_max_spp_low"] < one["time_at_max_spp"] < one["time_at_max_spp_high"]
    none = cv.summarize(experiment(rng, seeds=1, repeats=1)).iloc[0]
    assert math.isfinite(none["efficiency"]) and math.isnan(none["efficiency_low"])


def test_summary_is_reproducible():
    runs = experiment(np.random.default_rng(2))
    pd.testing.assert_frame_equal(cv.summarize(runs), cv.summarize(runs))


def test_time_column_selects_the_clock():
    runs = experiment(np.random.default_rng(3))
    wall, cpu = cv.summarize(runs).iloc[0], cv.summarize(runs, time_column="cpu_time_s").iloc[0]
    assert cpu["time_column"] == "cpu_time_s"
    assert cpu["efficiency"] == pytest.approx(wall["efficiency"] / 2)  # the CPU clock reads twice the wall here
    assert cv.efficiency(runs, "cpu_time_s") == pytest.approx(cpu["efficiency"])
    assert cv.efficiency(runs) == pytest.approx(wall["efficiency"]) and math.isnan(cv.efficiency(runs, "nope_s"))
    assert cpu["efficiency_high"] == pytest.approx(wall["efficiency_high"] / 2, rel=0.05)
    assert cv.time_to_target(runs, "rel_mse", TARGET, "cpu_time_s") == pytest.approx(
        2 * cv.time_to_target(runs, "rel_mse", TARGET))
    assert cv.slope_over_seeds(runs, "rmse", "cpu_time_s")[0] == pytest.approx(cv.slope_over_seeds(runs, "rmse", "time_s")[0])
    for runs_without in (runs.drop(columns=["cpu_time_s"]), runs.assign(cpu_time_s=math.nan)):
        s = cv.summarize(runs_without, time_column="cpu_time_s").iloc[0]
        for k in ("efficiency", "efficiency_low", "slope_rmse_time", COL if COL in s else "time_at_max_spp"):
            assert math.isnan(s[k]), k
        assert s["slope_rmse_spp"] == pytest.approx(-0.5, abs=0.05)  # the spp figures do not need a clock


def test_samples_column_and_parsing():
    assert bootstrap.samples_column("time_s") == "time_samples_s"
    assert bootstrap.samples_column("cpu_time_s") == "cpu_time_samples_s"
    assert bootstrap.parse_samples("[1.0, 2.0, NaN]", 5.0).tolist() == [1.0, 2.0]
    assert bootstrap.parse_samples(None, 5.0).tolist() == [5.0]
    assert bootstrap.parse_samples("not json", 5.0).tolist() == [5.0]


def _images(rng, bias: float, seeds: int = 2, shape=(64, 64, 3)):
    ref = np.full(shape, 0.5)
    return [ref + bias + 0.1 * rng.standard_normal(shape) for _ in range(seeds)], ref, np.zeros(shape)


def test_bias_share_of_an_unbiased_renderer_is_not_significant():
    """Over 20 unbiased 2-seed experiments the bias share's interval reaches 0 at least 17 times (its point
    estimate is often above 0: the 14.5% of the reference renderer at 2 seeds); a bias of 0.03 against
    noise 0.1 is significant every time, its interval covering the true bias² at least 17 times in 20."""
    rng = np.random.default_rng(6)
    unbiased = [cv.bias_variance(*_images(rng, 0.0)) for _ in range(20)]
    assert sum(not cv.bias_significant(u["bias2_fraction_low"]) for u in unbiased) >= 17
    assert max(u["bias2_fraction"] for u in unbiased) > 0.0  # the point estimate alone would claim a bias
    for u in unbiased:
        assert u["bias2_low"] <= u["bias2"] <= u["bias2_high"] and u["variance_low"] <= u["variance"] <= u["variance_high"]
        assert u["bias2_fraction_low"] <= u["bias2_fraction"] <= u["bias2_fraction_high"]
    biased = [cv.bias_variance(*_images(rng, 0.03)) for _ in range(20)]
    assert all(cv.bias_significant(b["bias2_fraction_low"]) and b["bias2_fraction_low"] > 0.01 for b in biased)
    assert sum(b["bias2_low"] < 0.03**2 < b["bias2_high"] for b in biased) >= 17  # and cover the true bias²
    assert cv.bias_significant(math.nan) is None


def test_region_split_has_intervals():
    rng = np.random.default_rng(7)
    images, ref, ref_var = _images(rng, 0.0)
    images = [im + np.where(np.arange(64)[None, :, None] < 32, 0.04, 0.0) for im in images]  # biased left half
    masks = {"left": np.arange(64)[None, :].repeat(64, 0) < 32, "right": np.arange(64)[None, :].repeat(64, 0) >= 32}
    out = cv.region_bias_variance(images, ref, ref_var, masks)
    assert cv.bias_significant(out["left"]["bias2_fraction_low"])
    assert not cv.bias_significant(out["right"]["bias2_fraction_low"])


def test_compare_rows_equal_time_and_equal_quality():
    """``cbox compare``: one row per renderer (one seed, one spp) re-timed K = 3 times. Equal quality: the time
    the target cost, with the repeats' interval; equal time: the spp the budget buys at the measured speed."""
    ts = [1.9, 2.0, 2.3]
    row = {"renderer": "r", "status": "ok", "seed": 0, "spp": 64, "mse": 1e-3, "rmse": 1e-3**0.5, "rel_mse": 1e-3,
           "time_s": 2.0, "time_repeats": 3, "time_samples_s": json.dumps(ts), "info_time_budget_s": 4.0}
    s = cv.summarize(pd.DataFrame([row])).iloc[0]
    assert s["interval_basis"] == "timing repeats only (one seed)"
    assert s["time_at_max_spp"] == 2.0 and s["time_at_max_spp_low"] < 1.9 and s["time_at_max_spp_high"] > 2.3
    assert s["spp_in_budget"] == pytest.approx(128)
    assert s["spp_in_budget_low"] < 4 * 64 / 2.3 and s["spp_in_budget_high"] > 4 * 64 / 1.9
    assert s["efficiency"] == pytest.approx(1 / (1e-3 * 2.0))
    assert s["efficiency_low"] < 1 / (1e-3 * 2.3) and s["efficiency_high"] > 1 / (1e-3 * 1.9)


def test_with_intervals_for_printing():
    from cornell_harness.evaluate.summary import with_intervals

    table = pd.DataFrame({"renderer": ["a", "b"], "efficiency": [10.0, 20.0], "efficiency_low": [5.0, math.nan],
                          "efficiency_high": [20.0, math.nan], "bias2_fraction": [0.145, 0.5],
                          "bias2_fraction_low": [0.0, 0.2], "bias2_fraction_high": [0.35, 0.7],
                          "slope_rmse_spp": [-0.5, -0.5], "slope_rmse_spp_ci": [0.1, 0.1]})
    out = with_intervals(table)
    assert list(out.columns) == ["renderer", "efficiency", "bias2_fraction", "slope_rmse_spp"]
    assert list(out["efficiency"]) == ["10 (5–20)", "20"]
    assert list(out["bias2_fraction"]) == ["not significant", "0.5 (0.2–0.7)"]
