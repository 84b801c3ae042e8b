"""α-spending over looks (cornell_harness.evaluate.sequential): the closed forms of Lan & DeMets (1983)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import norm

from cornell_harness.evaluate.sequential import SPENDING, fractions, look_levels, spent


def test_obrien_fleming_spending_is_its_closed_form():
    # 2 - 2Φ(z_{α/2}/√t): at t = 1/2 and α = 0.05, z = 1.96/0.7071 = 2.772, spent 0.00557.
    assert spent(0.5, 0.05, "obrien-fleming") == pytest.approx(2 * norm.sf(norm.isf(0.025) / math.sqrt(0.5)))
    assert spent(0.5, 0.05, "obrien-fleming") == pytest.approx(0.00557, abs=1e-5)
    # Far from the end it spends almost nothing, and still a positive amount (no cancellation to 0).
    assert 0 < spent(1 / 16, 0.00334, "obrien-fleming") < 1e-30


def test_pocock_spending_is_its_closed_form():
    assert spent(0.5, 0.05, "pocock") == pytest.approx(0.05 * math.log(1 + (math.e - 1) * 0.5))


@pytest.mark.parametrize("spending", SPENDING)
def test_spending_runs_from_0_to_the_level(spending):
    t = np.linspace(0, 1, 101)
    s = np.array([spent(x, 0.01, spending) for x in t])
    assert s[0] == 0 and s[-1] == 0.01 and np.all(np.diff(s) > 0)


@pytest.mark.parametrize("spending", SPENDING)
@pytest.mark.parametrize("spps", [[64, 128, 256, 512, 1024], [1, 2, 4, 8, 16, 32, 64, 128, 256], [100, 1000]])
def test_the_looks_spend_exactly_the_level(spending, spps):
    levels = look_levels(fractions(spps), 0.01, spending)
    assert levels.sum() == pytest.approx(0.01, rel=1e-12)
    assert np.all(levels >= 0) and levels[-1] > 0  # a very early OBF look may underflow to 0


def test_obrien_fleming_keeps_the_last_look_near_the_fixed_test_and_pocock_spends_early():
    t = fractions([64, 128, 256, 512, 1024])
    obf, pocock = look_levels(t, 0.01, "obrien-fleming"), look_levels(t, 0.01, "pocock")
    assert obf[-1] > 0.8 * 0.01 > pocock[-1]
    assert pocock[0] > 1000 * obf[0]


@pytest.mark.parametrize("bad", [[], [0.5, 0.25, 1.0], [0.0, 1.0], [0.5, 0.9]])
def test_fractions_must_increase_to_1(bad):
    with pytest.raises(ValueError, match="information fractions"):
        look_levels(bad, 0.01)


def test_unknown_spending_function():
    with pytest.raises(ValueError, match="unknown spending function 'linear'"):
        spent(0.5, 0.01, "linear")
