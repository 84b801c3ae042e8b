"""The agreement test's named-region z-tests (cornell_harness.evaluate.agreement): same family as the tiles and the image.

The tiled and whole-image tests are tested in tests/gate/test_gate.py; here,
what regions add: a region's summed difference against its summed variance is
a z-test, its size counts in the Šidák family, its failure names it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import norm

from cornell_harness.evaluate import agreement

REF = 0.5
VAR = 1e-4  # per pixel, of the image and of the reference alike


def _spot() -> np.ndarray:
    """A 12 × 12 region straddling the corner of four 16 × 16 tiles (36 of its pixels in each)."""
    mask = np.zeros((64, 64), dtype=bool)
    mask[10:22, 10:22] = True
    return mask


def test_a_shifted_region_fails_with_its_z_where_no_tile_does():
    """The region's mean is shifted by δ in channel G, no noise: z = n δ / √(n · 2 VAR) exactly.

    With n = 144 and δ = 0.006, z = 5.09 on the region, but 0.95 on each of
    the four tiles it straddles (36 δ / √(256 · 2 VAR)) and on the whole image:
    every tile and the image pass, the region fails, and the failure says where.
    """
    ref = np.full((64, 64, 3), REF)
    var = np.full_like(ref, VAR)
    img, mask, delta = ref.copy(), _spot(), 0.006
    img[mask, 1] += delta
    n = int(mask.sum())
    z = n * delta / math.sqrt(n * 2 * VAR)
    assert agreement.agreement_test(img, var, ref, var, tile=16, alpha=0.01).passed  # tiles alone miss it
    a = agreement.agreement_test(img, var, ref, var, tile=16, alpha=0.01, regions={"spot": mask})
    assert not a.passed and len(a.failures) == 1
    f = a.failures[0]
    assert (f["region"], f["channel"]) == ("spot", "G") and f["z"] == pytest.approx(z, rel=1e-12)
    assert f["p"] == pytest.approx(2 * norm.sf(z), rel=1e-9) and f["p"] < a.level
    assert a.z_regions["spot"][1] == pytest.approx(z, rel=1e-12) and a.z_regions["spot"][[0, 2]].tolist() == [0, 0]
    assert np.abs(a.z_tiles).max() == pytest.approx(36 * delta / math.sqrt(256 * 2 * VAR), rel=1e-12)
    assert "region spot (144 pixels), channel G: z = 5.09, region mean off by +1.20%" in a.message()
    assert a.p_min == f["p"]


def test_family_size_counts_each_non_empty_region_three_times():
    ref = np.full((64, 64, 3), REF)
    var = np.full_like(ref, VAR)
    empty = np.zeros((64, 64), dtype=bool)
    a = agreement.agreement_test(ref, var, ref, var, tile=16, alpha=0.01,
                                 regions={"spot": _spot(), "all": ~empty, "none": empty})
    assert a.tests == 16 * 3 + 3 + 2 * 3 and set(a.z_regions) == {"spot", "all"}  # the empty region is no test
    assert a.level == pytest.approx(agreement.sidak_level(0.01, a.tests))
    assert "57 tests: 48 on tiles, 6 on 2 regions, 3 on the whole image" in a.message()
    with pytest.raises(ValueError, match="region 'spot': mask shape"):
        agreement.agreement_test(ref, var, ref, var, tile=16, regions={"spot": np.ones((32, 64), dtype=bool)})


def test_clean_noise_with_regions_keeps_the_family_wise_rate():
    """Pure noise of the assumed variance, with overlapping regions: the family-wise rejection rate is ≤ α = 0.1.

    Regions overlap tiles and each other, so the tests are positively
    correlated and Šidák's level is conservative: the rate is at most α, and
    close to it when a few regions join many independent tiles (measured
    0.103 ± 0.005 over 4000 trials of this setting, seed 12345). 400 trials,
    Binomial(400, 0.1): the assertion [16, 64] fails with probability < 1e-4
    for a correct test.
    """
    rng = np.random.default_rng(2)
    ref = np.full((32, 32, 3), REF)
    var = np.full_like(ref, VAR)
    regions = {"left": np.zeros((32, 32), dtype=bool), "ring": np.zeros((32, 32), dtype=bool)}
    regions["left"][:, :13] = True
    regions["ring"][4:28, 4:28] = True
    regions["ring"][8:24, 8:24] = False
    rejections = sum(not agreement.agreement_test(ref + np.sqrt(2 * VAR) * rng.standard_normal(ref.shape), var, ref,
                                                  var, tile=8, alpha=0.1, regions=regions).passed
                     for _ in range(400))
    assert 16 <= rejections <= 64, rejections


def test_a_region_with_a_nan_variance_rejects():
    """A NaN variance inside a region makes its test fail (p = 0), not pass silently."""
    ref = np.full((64, 64, 3), REF)
    var = np.full_like(ref, VAR)
    bad = var.copy()
    bad[12, 12, 2] = np.nan
    a = agreement.agreement_test(ref, bad, ref, var, tile=16, alpha=0.01, regions={"spot": _spot()})
    assert not a.passed and a.p_regions["spot"][2] == 0.0
    assert any(f.get("region") == "spot" and f["channel"] == "B" for f in a.failures)
