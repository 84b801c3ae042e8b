"""cornell_harness.evaluate.ssim (numpy) against skimage's structural_similarity, which it replaces in the metrics."""

from __future__ import annotations

import numpy as np
import pytest
from skimage.metrics import structural_similarity

from cornell_harness.evaluate.ssim import ssim


@pytest.mark.parametrize("shape", [(64, 48, 3), (7, 9, 3), (256, 256, 3)])
def test_as_skimage(shape):
    rng = np.random.default_rng(11)
    x = rng.uniform(0, 1, shape)
    y = np.clip(x + rng.normal(0, 0.1, shape), 0, 1)
    y[: shape[0] // 2] = x[: shape[0] // 2]  # identical half: SSIM 1 there
    expected = structural_similarity(x, y, channel_axis=-1, data_range=1.0)
    assert ssim(x, y) == pytest.approx(expected, rel=1e-12, abs=1e-12)
    assert ssim(x, x) == pytest.approx(1.0, abs=1e-12)


def test_too_small():
    with pytest.raises(ValueError, match="at least 7x7"):
        ssim(np.zeros((6, 8, 3)), np.zeros((6, 8, 3)))
