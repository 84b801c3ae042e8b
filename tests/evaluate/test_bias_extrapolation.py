"""Bias extrapolation over seeds (cornell_harness.evaluate.bias_extrapolation): the fit recovers a known limit, the
t-test's false-alarm rate on synthetic clean data is its level, and it has power on a synthetic bias."""

from __future__ import annotations

import numpy as np
import pytest

from cornell_harness.evaluate import bias_extrapolation as bx

EFFORTS = (62500, 250000)


def _errors(rng, limit: float, k: int = 8, rate: float = 1.0, c: float = 0.01, shared: float = 0.002,
            own: float = 0.001, efforts=EFFORTS) -> np.ndarray:
    """(k, efforts) errors b∞ + c·(E/E₀)^(−rate) with a per-seed noise shared by the efforts and one per effort."""
    x = (np.asarray(efforts, float) / efforts[0]) ** -rate
    return limit + c * x + rng.normal(0, shared, (k, 1)) + rng.normal(0, own, (k, len(efforts)))


def test_extrapolation_recovers_the_limit_and_coefficient_exactly_without_noise():
    efforts = (8, 16, 32, 64)
    x = (np.asarray(efforts, float) / 8) ** (-1 / 3)
    errors = np.array([0.02 + 0.05 * x, -0.01 + 0.2 * x])
    b, c = bx.extrapolate(errors, efforts, 1 / 3)
    assert b == pytest.approx([0.02, -0.01], abs=1e-12) and c == pytest.approx([0.05, 0.2], abs=1e-12)
    # Two efforts at rate 1 is Richardson's (4·e(4N) − e(N)) / 3.
    e = np.array([[0.03, 0.012]])
    assert bx.extrapolate(e, EFFORTS, 1.0)[0][0] == pytest.approx((4 * 0.012 - 0.03) / 3)


@pytest.mark.parametrize("efforts, rate, why", [((10,), 1.0, "two or more"), ((10, 10), 1.0, "distinct"),
                                                ((0, 10), 1.0, "positive"), ((1, 4), 0.0, "rate")])
def test_design_refuses_what_cannot_be_fitted(efforts, rate, why):
    with pytest.raises(ValueError, match=why):
        bx.design(efforts, rate)


def test_false_alarm_rate_on_clean_synthetic_data_is_the_level():
    """2000 clean seed sets (limit 0, a bias that falls at the fitted rate, correlated noise): the rate of
    failures at level 0.05 is within 0.05 ± 0.015 (binomial sd 0.005: 3 sd)."""
    rng = np.random.default_rng(1)
    fails = sum(not bx.limit_test(_errors(rng, 0.0), EFFORTS, 1.0, 0.05).passed for _ in range(2000))
    assert abs(fails / 2000 - 0.05) < 0.015


def test_power_on_a_synthetic_bias():
    """A limit of −0.6% (a 2% photon-flux error seen in the image mean) against a per-seed sd of the limit of
    0.24% (0.2% shared, 0.1% per effort, ×√17/3 by the fit): noncentrality 7.0 at 7 degrees of freedom against
    the critical |t| 4.03 at level 0.005, power 0.981 (scipy.stats.nct), so at least 185 of 200 seed sets fail
    (binomial sd 1.9 sets: 4 sd); a −0.1% limit (power 0.027) fails at most 15."""
    rng = np.random.default_rng(2)
    tests = [bx.limit_test(_errors(rng, -0.006), EFFORTS, 1.0, 0.005) for _ in range(200)]
    assert sum(not t.passed for t in tests) >= 185
    assert all(t.limit.high < 0 for t in tests if not t.passed)  # a failing interval excludes 0 below it
    small = sum(not bx.limit_test(_errors(rng, -0.001), EFFORTS, 1.0, 0.005).passed for _ in range(200))
    assert small <= 15


def test_the_coefficient_interval_shows_the_bias_falling():
    """The fitted c (bias at the first effort above the limit) is +1% with a 95% interval that holds it."""
    r = bx.limit_test(_errors(np.random.default_rng(3), 0.0, k=12), EFFORTS, 1.0, 0.01)
    assert r.coefficient.low < 0.01 < r.coefficient.high and r.coefficient.low > 0


def test_identical_seeds_pass_a_zero_limit_and_fail_any_other():
    clean = np.tile([0.01, 0.0025], (8, 1))  # 0.01 · (E/E₀)^−1: a limit of 0 up to rounding
    assert bx.limit_test(clean, EFFORTS, 1.0, 0.01).passed
    r = bx.limit_test(clean + 0.001, EFFORTS, 1.0, 0.01)
    assert not r.passed and r.limit.t == np.inf


def test_t_critical_is_students():
    r = bx.limit_test(_errors(np.random.default_rng(4), 0.0), EFFORTS, 1.0, 0.005)
    assert r.t_critical == pytest.approx(4.029, abs=1e-3)  # two-sided 0.005 at 7 degrees of freedom


def test_a_tolerance_passes_a_small_lasting_limit_and_fails_a_larger_one():
    """A limit of −0.07% (photonmap's image at 62 500/250 000 photons, measured) fails at tolerance 0 once the
    seeds are many (48: t ≈ 4.7) and passes at tolerance 0.1%; −0.6% fails at tolerance 0.1% too, on its side."""
    rng = np.random.default_rng(5)
    small = _errors(rng, -0.0007, k=48, shared=0.0005, own=0.0002)
    assert not bx.limit_test(small, EFFORTS, 1.0, 0.005).passed
    r = bx.limit_test(small, EFFORTS, 1.0, 0.005, tolerance=0.001)
    assert r.passed and r.t < 0
    big = bx.limit_test(_errors(rng, -0.006), EFFORTS, 1.0, 0.005, tolerance=0.001)
    assert not big.passed and big.limit.high < -0.001
