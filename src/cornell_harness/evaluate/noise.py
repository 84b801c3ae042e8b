"""Statistics that tell error from noise, using the reference's variance.

The reference stores the per-pixel variance of its mean, ``var_ref``, from
``ref_spp`` samples. A renderer whose per-sample variance equals the
reference renderer's would, at ``spp`` samples, have per-pixel variance
``var_ref * ref_spp / spp``; the difference image (render - reference) then
has variance ``var_ref * (ref_spp / spp + 1)``. These yardsticks assume that
noise model, which holds exactly for the reference renderer itself and is a
scale for any other unbiased renderer. Besides the variance, the reference
stores one independent batch (``noise.exr``), a sample of real noise.
"""

from __future__ import annotations

import math

import numpy as np

from cornell_harness.evaluate import metrics
from cornell_harness.scenes.quantities import has_colour


def render_variance(ref_var: np.ndarray, ref_spp: int, spp: int) -> np.ndarray:
    """Per-pixel variance of a render at ``spp`` under the noise model above (spp = 1: per-sample variance)."""
    return np.asarray(ref_var, dtype=np.float64) * ref_spp / spp


def difference_variance(ref_var: np.ndarray, ref_spp: int, spp: int) -> np.ndarray:
    """Per-pixel variance of (render at ``spp`` - reference), under the noise model above."""
    return np.asarray(ref_var, dtype=np.float64) * (ref_spp / spp + 1.0)


def mean_radiance_z(image: np.ndarray, ref: np.ndarray, ref_var: np.ndarray, ref_spp: int, spp: int) -> float:
    """z-score of the image's mean radiance (mean over pixels and channels) against the reference.

    The difference's variance is :func:`difference_variance`'s; see :func:`mean_difference_z`.
    """
    return mean_difference_z(image, ref, difference_variance(ref_var, ref_spp, spp))


def mean_difference_z(image: np.ndarray, ref: np.ndarray, var: np.ndarray) -> float:
    """z-score of mean(image) − mean(ref) (over pixels and channels), given the difference's per-pixel variance.

    Pixels are independent; a pixel's three channels come from the same paths,
    so their covariance is bounded by the perfectly correlated case
    (Cauchy-Schwarz), which makes this z conservative (|z| never overstated).
    Any (H, W, 3) arrays work, e.g. a region's pixels as (n, 1, 3)
    (:func:`cornell_harness.evaluate.metrics.masked_pixels`).
    """
    var = np.asarray(var, dtype=np.float64)
    n = image.shape[0] * image.shape[1]
    pixel_sd = np.sqrt(var).sum(axis=-1) / 3.0  # sd of the channel mean, correlated bound
    sd = np.sqrt(np.sum(pixel_sd**2)) / n
    values = np.asarray(image, np.float64)
    kept = values[~np.isnan(values)]  # NaN pixels skipped, as nanmean does, without its warning when none is left
    mean = float(kept.mean()) if kept.size else math.nan  # an all-NaN image: the z is NaN
    diff = mean - float(np.mean(ref, dtype=np.float64))
    return diff / sd if sd > 0 else (0.0 if diff == 0 else float(np.sign(diff)) * np.inf)


def noise_image(ref: np.ndarray, noise: np.ndarray, noise_spp: int, ref_spp: int, spp: int) -> np.ndarray:
    """A render at ``spp`` that differs from the reference by noise alone.

    ``noise`` is an independent render of ``noise_spp`` samples (stored with
    the reference); its deviation from the reference is rescaled to the
    standard deviation a render at ``spp`` would have against the reference.
    Real noise keeps the channel correlations and tails a Gaussian model
    misses; its ΔE matches real Mitsuba renders within a few percent from
    about 32 spp up, and overstates it below that (a 1-spp image is far
    more skewed than a rescaled 128-spp one).
    """
    scale = np.sqrt((1.0 / spp + 1.0 / ref_spp) / (1.0 / noise_spp + 1.0 / ref_spp))
    ref = np.asarray(ref, np.float64)
    return ref + scale * (np.asarray(noise, np.float64) - ref)


def noise_yardsticks(image: np.ndarray, reference, spp: int, exposure: float | None = None) -> dict:
    """What noise alone would give at this spp, to read the real metrics against.

    ``reference`` is a :class:`cornell_harness.store.references.Reference`; ``exposure``, the reference's
    :func:`cornell_harness.evaluate.metrics.exposure_scale` where the caller has it already (the ΔE's exposure).

    - ``noise_rmse``: expected RMSE from noise alone;
    - ``noise_delta_e2000_mean``: ΔE mean of :func:`noise_image`;
    - ``noise_mean_radiance_z``: z-score of the mean-radiance difference.
    """
    ref, ref_var, ref_spp = reference.image, reference.variance, reference.spp
    var = difference_variance(ref_var, ref_spp, spp)
    out = {
        "noise_rmse": float(np.sqrt(np.mean(var))),
        "noise_mean_radiance_z": float(mean_radiance_z(image, ref, ref_var, ref_spp, spp)),
    }
    if has_colour(reference.quantity):
        noisy = noise_image(ref, reference.noise, reference.noise_spp, ref_spp, spp)
        out["noise_delta_e2000_mean"] = float(metrics.delta_e2000(noisy, ref, exposure=exposure))
    return out
