"""What every metric does to an image first: the shape check, the broken-pixel rule, luminance.

Below :mod:`cornell_harness.evaluate.metrics` and :mod:`cornell_harness.evaluate.flip`, which
both build on it (the metrics call FLIP, so FLIP cannot import them).
"""

from __future__ import annotations

import numpy as np

#: BT.709 luminance weights (the Y row of the sRGB -> XYZ matrix, as rounded in IEC 61966-2-1).
LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])


def as_image(img) -> np.ndarray:
    """``img`` as a float64 (H, W, 3) array; ValueError for any other shape."""
    arr = np.asarray(img, dtype=np.float64)
    if arr.ndim != 3 or arr.shape[-1] != 3:
        raise ValueError(f"expected an (H, W, 3) image, got shape {arr.shape}")
    return arr


def as_pair(img, ref) -> tuple[np.ndarray, np.ndarray]:
    """``img`` and ``ref`` as float64 (H, W, 3) arrays of one shape; ValueError if they differ."""
    img, ref = np.asarray(img), np.asarray(ref)
    if img.shape != ref.shape:
        raise ValueError(
            f"image shape {img.shape} does not match reference shape {ref.shape}"
        )
    return as_image(img), as_image(ref)


def all_finite(img: np.ndarray) -> bool:
    """Whether every value of ``img`` is finite.

    One sum settles the common case, an image without NaN or Inf, at a tenth
    of the per-value test's cost (whose ``all`` over the last axis of 3 is
    the slow part); a sum that is not finite (a NaN or Inf, or huge finite
    values that overflow) falls back to that test.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        if np.isfinite(np.sum(img)):
            return True
    return bool(np.isfinite(img).all())


def finite_pixels(img: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels whose every channel is finite."""
    if all_finite(img):
        return np.ones(np.shape(img)[:-1], dtype=bool)
    return np.all(np.isfinite(img), axis=-1)


def zero_broken_pixels(img: np.ndarray) -> np.ndarray:
    """The image with every broken pixel (a NaN or Inf in any channel) black: the harness's one rule.

    Whole pixel, not just the bad channel: the other channels of a pixel that
    produced a NaN are not trustworthy either. Broken pixels are counted
    separately (:func:`cornell_harness.evaluate.metrics.invalid_pixel_counts`), and
    every error metric, the gate's agreement test and its slope check score
    them as black.
    """
    return np.where(finite_pixels(img)[..., None], img, 0.0)


def luminance(img) -> np.ndarray:
    """Relative luminance Y of a linear-sRGB image, shape (H, W)."""
    return as_image(img) @ LUMINANCE_WEIGHTS
