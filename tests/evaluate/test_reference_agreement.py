"""The two-engine comparison of ``cbox reference verify``: region means, z from both variances, Šidák, χ²."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cornell_harness.evaluate.agreement import sidak_level
from cornell_harness.evaluate.reference_agreement import (FAMILY_ALPHA, WHOLE_IMAGE, reference_agreement, region_mean,
                                                  z_scores)

SHAPE = (32, 48, 3)


def _masks():
    left = np.zeros(SHAPE[:2], bool)
    left[:, :16] = True
    right = np.zeros(SHAPE[:2], bool)
    right[8:24, 30:] = True
    return {"left": left, "right": right}


def _pair(rng, sd_ref=0.01, sd_other=0.02, bias=None):
    """A reference and an independent image of the same truth, each with its true variance of the mean."""
    truth = 0.2 + 0.6 * rng.random(SHAPE)
    var_ref, var_other = np.full(SHAPE, sd_ref**2), np.full(SHAPE, sd_other**2)
    ref = truth + sd_ref * rng.standard_normal(SHAPE)
    other = truth + sd_other * rng.standard_normal(SHAPE)
    if bias is not None:
        other = other * bias
    return ref, var_ref, other, var_other


def test_region_mean_and_its_variance_are_sums_over_n_squared():
    image = np.arange(2 * 3 * 3, dtype=float).reshape(2, 3, 3)
    variance = np.ones((2, 3, 3)) * [1.0, 2.0, 4.0]
    mask = np.array([[True, False, True], [False, True, False]])
    mean, var = region_mean(image, variance, mask)
    np.testing.assert_allclose(mean, image[mask].mean(axis=0))
    np.testing.assert_allclose(var, np.array([3.0, 6.0, 12.0]) / 9)  # Σ var / n², n = 3


def test_agreeing_images_pass_and_z_is_the_difference_over_both_variances():
    ref, var_ref, other, var_other = _pair(np.random.default_rng(1))
    a = reference_agreement(ref, var_ref, other, var_other, _masks())
    assert a.passed, a.message()
    assert [r.name for r in a.regions] == [WHOLE_IMAGE, "left", "right"]
    assert a.tests == a.dof == 9 and a.level == pytest.approx(sidak_level(FAMILY_ALPHA, 9))
    left = a.regions[1]
    n = 32 * 16
    expected = (other[:, :16].mean(axis=(0, 1)) - ref[:, :16].mean(axis=(0, 1))) / np.sqrt((0.01**2 + 0.02**2) / n)
    np.testing.assert_allclose(left.z, expected)
    assert a.chi2 == pytest.approx(sum(float((r.z**2).sum()) for r in a.regions))
    # Correct variances on both sides: per-pixel z is standard normal.
    assert a.pixel_z_sd == pytest.approx(1.0, abs=0.03) and a.pixel_z_spread == pytest.approx(1.0, abs=0.05)
    assert a.pixel_z_tail < 0.01


def test_a_two_percent_bias_in_one_region_fails_there():
    rng = np.random.default_rng(2)
    ref, var_ref, other, var_other = _pair(rng)
    masks = _masks()
    other[masks["right"]] *= 1.02  # 16 × 18 pixels of sd 0.022 around 0.5: the region mean's relative sd is 0.26%
    a = reference_agreement(ref, var_ref, other, var_other, masks)
    assert not a.passed
    assert a.failures[0][0] == "right" and "left" not in {f[0] for f in a.failures}
    assert a.failures[0][2] > 0  # the engine is the brighter one
    assert a.chi2_p < 1e-6


def test_false_alarms_stay_below_the_family_wise_rate():
    """200 verifications of agreeing images: failures follow Binomial(200, ≤ 0.01); 6 or more has p < 0.02."""
    rng = np.random.default_rng(3)
    fails = sum(not reference_agreement(*_pair(rng), _masks()).passed for _ in range(200))
    assert fails <= 5


def test_no_information_passes_and_a_noise_free_difference_or_nan_fails():
    z = z_scores(np.array([0.0, 1.0, -1.0, np.nan]), np.array([0.0, 0.0, 0.0, 1.0]))
    assert z[0] == 0 and z[1] == math.inf and z[2] == -math.inf and np.isnan(z[3])
    zeros = np.zeros(SHAPE)
    assert reference_agreement(zeros, zeros, zeros, zeros, {}).passed  # a black, noise-free image: nothing to test
    other = zeros.copy()
    other[0, 0, 1] = 1e-6
    a = reference_agreement(zeros, zeros, other, zeros, {})
    assert not a.passed and a.max_abs_z == math.inf
    ref, var_ref, other, var_other = _pair(np.random.default_rng(4))
    other[3, 3, 0] = np.nan
    assert not reference_agreement(ref, var_ref, other, var_other, {}).passed


def test_empty_regions_are_left_out_and_the_whole_image_name_is_reserved():
    ref, var_ref, other, var_other = _pair(np.random.default_rng(5))
    a = reference_agreement(ref, var_ref, other, var_other, {"none": np.zeros(SHAPE[:2], bool)})
    assert [r.name for r in a.regions] == [WHOLE_IMAGE]
    with pytest.raises(ValueError, match="whole image"):
        reference_agreement(ref, var_ref, other, var_other, {WHOLE_IMAGE: np.ones(SHAPE[:2], bool)})


def test_summary_is_strict_json_and_the_table_has_a_row_per_region():
    import json

    ref, var_ref, other, var_other = _pair(np.random.default_rng(6))
    a = reference_agreement(ref, var_ref, other, var_other, _masks())
    s = a.summary()
    json.dumps(s, allow_nan=False)
    assert s["passed"] and s["tests"] == 9 and list(s["regions"]) == [WHOLE_IMAGE, "left", "right"]
    lines = a.table()
    assert len(lines) == 4 and lines[0].startswith("region") and lines[2].startswith("left")


def test_three_verdicts_fail_exactly_where_the_z_test_rejects():
    """Over seeds of clean and 1%/3%-biased pairs: a region-channel fails the three-way verdict exactly where its
    z-test rejects (its Fieller interval excludes 0 at the same level), passes only inside its margin."""
    from cornell_harness.evaluate.reference_agreement import expected_pixel_z_sd

    rng = np.random.default_rng(7)
    seen = set()
    for bias in (None, 1.01, 1.03) * 4:
        a = reference_agreement(*_pair(rng, bias=bias), _masks())
        margins = a.margins({"image": 0.02, "left": 0.002})
        v = a.verdicts(margins)
        rejects = np.array([r.p < a.level for r in a.regions])
        assert ((v == "fail") == rejects).all()
        b = a.bias()
        inside = (b.low >= -margins) & (b.high <= margins)
        assert ((v == "pass") == (inside & ~rejects)).all()
        seen |= set(v.ravel().tolist())
    assert seen == {"pass", "fail", "inconclusive"}
    assert a.margins({})[0].tolist() == [0.01] * 3 and a.margins({})[1].tolist() == [0.05] * 3
    assert expected_pixel_z_sd(16) == pytest.approx(1.074, abs=1e-3) and expected_pixel_z_sd(1) == 1.0


def _batch_means(rng, truth, batches, spp, p, bright):
    """``batches`` means of ``spp`` samples per pixel-channel: an exponential of mean ``truth`` plus, with
    probability ``p`` per sample, a rare bright path of value ``bright``."""
    base = truth[..., None] * rng.gamma(spp, 1.0 / spp, (*truth.shape, batches))
    return base + bright[..., None] * rng.binomial(spp, p, (*truth.shape, batches)) / spp


def _rare_path_pair(rng, hits, engine=(16, 16), reference=(256, 128)):
    """A reference and an engine's render of the same per-sample law, each as (mean, variance of the mean) from its
    (batches, spp per batch): a rare bright path carries 95% of each pixel's per-sample variance and is drawn
    ``hits`` times on average in the engine's render. No bias: both images have the same expectation."""
    truth = 0.2 + 0.6 * rng.random(SHAPE)
    p = hits / (engine[0] * engine[1])
    bright = truth * math.sqrt(0.95 / (0.05 * p))  # p · bright² = 19 × the exponential's variance truth²
    out = []
    for batches, spp in (reference, engine):
        x = _batch_means(rng, truth, batches, spp, p, bright)
        out += [x.mean(-1), x.var(-1, ddof=1) / batches]
    return out


def test_rare_bright_paths_give_a_one_sided_pixel_z_tail_that_the_regions_do_not_have():
    """The mechanism behind a per-pixel z sd of 2.6 on cornell-box-caustics (docs/references.md): where the
    engine draws a pixel's rare path about once in its render, most of its pixels have not drawn it, so they are
    low and their batch variance misses it: a one-sided tail, far past t's, with no bias; the regions' z, which
    sum many pixels' samples, stay standard normal. 16 batches, as `cbox reference verify`'s default."""
    rng = np.random.default_rng(8)
    region_z = []
    for _ in range(12):
        a = reference_agreement(*_rare_path_pair(rng, hits=0.5), _masks())
        assert a.pixel_z_sd > 2.0 and a.pixel_z_below > 0.15 and a.pixel_z_above < 0.005
        region_z += [z for r in a.regions for z in r.z]
    assert a.pixel_z_tail == pytest.approx(a.pixel_z_below + a.pixel_z_above)
    assert float(np.sqrt(np.mean(np.square(region_z)))) == pytest.approx(1.0, abs=0.25)  # 108 region z
    remark = a.spread_remark(16)
    assert remark.startswith(f"remark: the per-pixel z sd {a.pixel_z_sd:.2f} is far from the 1.07 expected")
    assert "one-sided, the engine is the lower image" in remark and "more spp, not more batches" in remark
    # Many draws per pixel: the batch means are normal again and z is t-like: no remark.
    near = reference_agreement(*_rare_path_pair(rng, hits=100), _masks())
    assert near.spread_remark(16) is None and near.pixel_z_sd < 1.25 * 1.074


def test_the_spread_remark_tells_a_one_sided_tail_from_a_two_sided_one():
    rng = np.random.default_rng(9)
    # The reference with the fewer samples: the tail is above +3, the reference the lower image.
    ref_m, ref_v, oth_m, oth_v = _rare_path_pair(rng, hits=0.5)
    swapped = reference_agreement(oth_m, oth_v, ref_m, ref_v, _masks())
    assert swapped.pixel_z_above > 0.15 and swapped.pixel_z_below < 0.005
    assert "one-sided, the reference is the lower image" in swapped.spread_remark(16)
    # Normal noise whose reported variances are a ninth of the truth: z sd 3 on both sides.
    ref, var_ref, other, var_other = _pair(rng)
    understated = reference_agreement(ref, var_ref / 9, other, var_other / 9, _masks())
    assert understated.pixel_z_below == pytest.approx(understated.pixel_z_above, rel=0.2)
    assert "the variances understate the pixels' spread" in understated.spread_remark(1)
    overstated = reference_agreement(ref, var_ref * 4, other, var_other * 4, _masks())
    assert "overstate" in overstated.spread_remark(1) and "one-sided" not in overstated.spread_remark(1)
    assert reference_agreement(ref, var_ref, other, var_other, _masks()).spread_remark(1) is None


def test_pixel_z_sides_count_infinities_on_their_side_and_nan_on_neither():
    from cornell_harness.evaluate.reference_agreement import pixel_z_stats

    z = np.array([-np.inf, -4.0, 0.5, 5.0, np.nan, 0.0])
    sd, spread, tail, below, above, count = pixel_z_stats(z, np.ones(6, bool))
    assert (tail, below, above, count) == (4 / 6, 2 / 6, 1 / 6, 6)
    assert sd == pytest.approx(math.sqrt((16 + 0.25 + 25) / 4))
