"""Repeated timings: the median's 95% interval covers as its docstring says, and the results columns."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from cornell_harness.evaluate.timing_stats import medians, median_interval, repeat_columns

#: Simulated experiments per coverage check: the binomial sd of a 95% coverage is then 0.0049, so a
#: tolerance of 0.015 is 3 sd (a correct rule fails it about once in 370 seeds; this seed is fixed).
TRIALS = 2000
TOLERANCE = 0.015


def _coverage(draw, truth: float, k: int, seed: int = 7) -> float:
    rng = np.random.default_rng(seed)
    hits = 0
    for _ in range(TRIALS):
        _, low, high = median_interval(draw(rng, k))
        hits += low <= truth <= high
    return hits / TRIALS


@pytest.mark.parametrize("k", [2, 3, 5])
def test_interval_covers_the_median_of_lognormal_timings_95_percent(k):
    """Log-normal timings (median 1.3 s, σ = 0.3 in log): the interval holds the true median 95% of the time.
    The order-statistic interval [min, max] would hold it 1 - 2^(1-K) of the time: 50%, 75%, 94%; a z
    quantile in place of t's about 70% at K = 2 and 81% at K = 3: both fail this."""
    coverage = _coverage(lambda rng, n: 1.3 * np.exp(rng.normal(0.0, 0.3, n)), 1.3, k)
    assert abs(coverage - 0.95) <= TOLERANCE, coverage


def test_interval_coverage_with_stalls_is_as_documented():
    """A floor plus exponential stalls (mean 20% of the floor), K = 3: the docstring's 93.4% (20 000 trials);
    here 2000, so within 3 sd of it."""
    truth = 1.0 + 0.2 * math.log(2.0)  # the median of 1 + Exp(mean 0.2)
    coverage = _coverage(lambda rng, n: 1.0 + rng.exponential(0.2, n), truth, 3)
    assert abs(coverage - 0.934) <= 3 * math.sqrt(0.934 * 0.066 / TRIALS), coverage


def test_interval_holds_the_sample_median_and_narrows_with_more_repeats():
    rng = np.random.default_rng(3)
    widths = {}
    for k in (3, 10, 40):
        ratios = []
        for _ in range(200):
            t = np.exp(rng.normal(0.0, 0.1, k))
            median, low, high = median_interval(t)
            assert low <= median <= high and median == np.median(t)
            ratios.append(high / low)
        widths[k] = np.median(ratios)
    assert widths[3] > widths[10] > widths[40] > 1.0, widths


def test_one_timing_or_none_has_no_interval():
    assert median_interval([2.5])[0] == 2.5 and all(math.isnan(x) for x in median_interval([2.5])[1:])
    assert all(math.isnan(x) for x in median_interval([]))
    # No logarithm of a zero time: the median stands, the interval is unknown.
    median, low, high = median_interval([0.0, 0.1, 0.2])
    assert median == 0.1 and math.isnan(low) and math.isnan(high)


def test_identical_timings_give_exactly_that():
    """A renderer with its own clock reports the same time each repeat: the interval is that time, exactly
    (not exp(log(t)), which can land a rounding below it)."""
    assert median_interval([28.0, 28.0, 28.0]) == (28.0, 28.0, 28.0)


def test_repeat_columns_carry_k_the_interval_and_the_raw_timings():
    cols = repeat_columns([1.0, 1.2, 1.1], [2.0, 2.3, 2.2])
    assert cols["time_repeats"] == 3
    assert json.loads(cols["time_samples_s"]) == [1.0, 1.2, 1.1]
    assert json.loads(cols["cpu_time_samples_s"]) == [2.0, 2.3, 2.2]
    assert cols["time_s_low"] < 1.1 < cols["time_s_high"]
    assert cols["cpu_time_s_low"] < 2.2 < cols["cpu_time_s_high"]
    assert medians([1.0, 1.2, 1.1], [2.0, 2.3, 2.2]) == (1.1, 2.2)


def test_repeat_columns_without_repeats_or_cpu_time():
    """The contract of a row without repeats: K = 1, NaN bounds, samples "[t]"; CPU time unknown in any
    timing: NaN bounds, "[]", and no median."""
    cols = repeat_columns([0.5], [None])
    assert cols["time_repeats"] == 1 and cols["time_samples_s"] == "[0.5]" and cols["cpu_time_samples_s"] == "[]"
    assert all(math.isnan(cols[c]) for c in ("time_s_low", "time_s_high", "cpu_time_s_low", "cpu_time_s_high"))
    assert medians([1.0, 2.0, 3.0], [1.0, None, 1.0]) == (2.0, None)
    assert repeat_columns([], [])["time_repeats"] == 0
