"""Relative-bias intervals (cornell_harness.evaluate.relative_bias) and the three verdicts
(cornell_harness.evaluate.equivalence).

Coverage is checked over many fixed-seed draws of synthetic Gaussian sums at a stated nominal level; the
binomial tolerance is 4 sd of the coverage over the draws, so a correct interval fails about once in 30 000 runs
of this file, and an interval that ignores one variance (or the delta method where the reference is noisy) fails
every time.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cornell_harness.evaluate import equivalence
from cornell_harness.evaluate.relative_bias import (critical_z, detectable_bias, fieller, interval_text, region_sums,
                                                    relative_bias, spp_for_half_width)

DRAWS = 20_000


def _coverage(mu_x, vx, mu_y, vy, level, seed=0):
    rng = np.random.default_rng(seed)
    x = mu_x + math.sqrt(vx) * rng.standard_normal(DRAWS)
    y = mu_y + math.sqrt(vy) * rng.standard_normal(DRAWS)
    b = relative_bias(x, np.full(DRAWS, vx), y, np.full(DRAWS, vy), level)
    truth = mu_x / mu_y - 1.0
    return float(np.mean((b.low <= truth) & (truth <= b.high))), b


@pytest.mark.parametrize("level", [0.05, 0.01])
@pytest.mark.parametrize("mu_x, vx, mu_y, vy", [
    (100.0, 4.0, 100.0, 1.0),     # unbiased; the render's variance dominates
    (90.0, 4.0, 100.0, 25.0),     # a 10% bias; the reference's variance dominates
    (110.0, 50.0, 100.0, 150.0),  # the reference's mean is only 8 sd from 0: the ratio is skewed
])
def test_fieller_interval_covers_at_its_nominal_level(mu_x, vx, mu_y, vy, level):
    cover, _ = _coverage(mu_x, vx, mu_y, vy, level)
    tol = 4 * math.sqrt(level * (1 - level) / DRAWS)
    assert abs(cover - (1 - level)) < tol, cover


def test_an_interval_from_one_variance_undercovers():
    """The test can fail: leaving out the reference's variance (the render's alone) covers far too rarely."""
    rng = np.random.default_rng(1)
    x, y = 100 + 2 * rng.standard_normal(DRAWS), 100 + 8 * rng.standard_normal(DRAWS)
    b = relative_bias(x, np.full(DRAWS, 4.0), y, np.zeros(DRAWS), 0.05)
    assert np.mean((b.low <= 0) & (0 <= b.high)) < 0.5


def test_region_sums_from_pixels_cover():
    """Per-pixel means and variances summed over a region (the gate's way): coverage of the true relative
    bias of a region whose render is 3% high, over seeds."""
    rng = np.random.default_rng(2)
    h = w = 16
    mask = np.zeros((h, w), bool)
    mask[4:10, 3:12] = True
    truth_ref = rng.uniform(0.2, 1.0, (h, w, 3))
    var_ref, var_img = np.full((h, w, 3), 0.01), np.full((h, w, 3), 0.04)
    hits, runs = 0, 2000
    truth = (1.03 * truth_ref[mask]).sum(axis=0) / truth_ref[mask].sum(axis=0) - 1
    for _ in range(runs):
        ref = truth_ref + np.sqrt(var_ref) * rng.standard_normal((h, w, 3))
        img = 1.03 * truth_ref + np.sqrt(var_img) * rng.standard_normal((h, w, 3))
        names, x, vx = region_sums(img, var_img, {"spot": mask})
        _, y, vy = region_sums(ref, var_ref, {"spot": mask})
        assert names == ["", "spot"]
        b = relative_bias(x[1], vx[1], y[1], vy[1], 0.05)
        hits += bool(np.all((b.low <= truth) & (truth <= b.high)))
    # all three channels covered together: 0.95^3 = 0.857 for independent channels
    assert abs(hits / runs - 0.95 ** 3) < 4 * math.sqrt(0.143 * 0.857 / runs)


def test_fieller_is_unbounded_where_the_reference_is_lost_in_its_noise():
    low, high = fieller(10.0, 1.0, 1.0, 4.0, 0.05)
    assert low == -math.inf and high == math.inf


def test_exact_and_black_regions():
    b = relative_bias([2.0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 0.0], 0.05)
    assert b.estimate.tolist() == [1.0, 0.0] and b.low.tolist() == [1.0, 0.0] and b.high.tolist() == [1.0, 0.0]


def test_a_nan_proves_nothing():
    b = relative_bias(math.nan, 1.0, 100.0, 1.0, 0.05)
    assert b.low == -math.inf and b.high == math.inf


def test_spp_for_half_width_scales_the_render_share_only():
    """Render share 1: the half-width falls as 1/√spp, so halving it takes 4× the spp; a share the reference
    alone fills is unresolvable (∞)."""
    z = critical_z(0.05)
    assert spp_for_half_width(0.01, 1.0, 100, z * 0.005, 0.05) == pytest.approx(400)
    # half the variance is the reference's: the target z·se/2 needs se² (s/n·100 + 1/2) = se²/4: impossible
    assert spp_for_half_width(0.01, 0.5, 100, z * 0.005, 0.05) == math.inf
    assert spp_for_half_width(0.01, 0.5, 100, z * 0.008, 0.05) == pytest.approx(0.5 * 100 / (0.64 - 0.5))


def test_detectable_bias_has_the_stated_power():
    """A true bias of the detectable size is detected by the z-test at that level with power 1 − β."""
    se, level, beta = 0.01, 0.01, 0.2
    delta = float(detectable_bias(se, level, beta))
    rng = np.random.default_rng(3)
    z = (delta + se * rng.standard_normal(DRAWS)) / se
    assert abs(np.mean(np.abs(z) > critical_z(level)) - (1 - beta)) < 4 * math.sqrt(0.16 / DRAWS)


def test_interval_text():
    assert interval_text("glass-shadow", -0.004, -0.061, 0.053) == "glass-shadow: bias −0.4% [−6.1%, +5.3%]"


def test_three_verdicts():
    low, high = np.array([-0.01, -0.09, 0.06, -0.02]), np.array([0.01, 0.01, 0.08, 0.07])
    v = equivalence.interval_verdicts(low, high, 0.05)
    assert v.tolist() == ["pass", "inconclusive", "fail", "inconclusive"]
    assert equivalence.combine(v) == "fail"
    assert equivalence.combine(v[[0, 1]]) == "inconclusive" and equivalence.combine(v[:1]) == "pass"
    # a tolerance: significant only beyond it
    assert equivalence.interval_verdicts(0.06, 0.08, 0.075, tolerance=0.07).tolist() == "inconclusive"
    assert equivalence.resolving_half_width([0.0, 0.04, 0.1], 0.05).tolist() == pytest.approx([0.05, 0.04, 0.1])
