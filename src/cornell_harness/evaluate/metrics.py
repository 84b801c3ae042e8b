"""Image-error metrics of a rendered image against a reference.

This module owns the numbers that say how far a renderer's image is from the
reference. Like ``skimage.metrics`` it is a set of small pure functions on
arrays: no I/O, no state, inputs are never modified, all maths is float64.

Inputs
------
``img`` and ``ref`` are HDR radiance images in linear sRGB (ITU-R BT.709
primaries, D65 white, no transfer function; see ``cornell_harness.scenes.model``), float
arrays of shape ``(H, W, 3)``. Every two-image function checks that the shapes
match and raises ``ValueError`` naming both otherwise.

Conventions
-----------
- **Exposure.** HDR radiance has no natural scale, so perceptual metrics need
  one. We use the key-value exposure of Reinhard et al. 2002, "Photographic
  Tone Reproduction for Digital Images", eq. 1-2: the log-average luminance
  ``L̄ = exp(mean(log(δ + Y)))`` is mapped to the key ``a = 0.18``, i.e.
  ``exposure = a / L̄`` with ``δ = 1e-4``. It is derived from the *reference
  only* (finite pixels), and this one scale is shared by every renderer for
  ΔE, SSIM, PSNR and display, so a renderer cannot improve its score by being
  uniformly too bright or too dark -- that error stays visible.
- **Display encoding** (:func:`display_encode`): multiply by the exposure,
  NaN -> 0 (black; NaNs are still counted by :func:`invalid_pixel_counts`),
  clip to [0, 1], then the piecewise sRGB OETF of IEC 61966-2-1. SSIM, PSNR
  and the HTML report all see exactly this encoding, with data range 1.
- **CIEDE2000** (Sharma, Wu & Dalal 2005, "The CIEDE2000 color-difference
  formula: implementation notes, supplementary test data, and mathematical
  observations"). Both images are multiplied by the shared exposure, taken
  linear sRGB -> XYZ -> CIELAB with the D65 white of the CIE 1931 2°
  observer, *without* clipping: L* may exceed 100 on the light source, and
  that is a real difference we want to see. ΔE00 is then computed per pixel
  (:mod:`cornell_harness.evaluate.ciede2000`: colour-science's arithmetic, rearranged for speed in numpy).
  Summary statistics report the fraction above 2.3, the just-noticeable
  difference (Sharma 2003, *Digital Color Imaging Handbook*; Mahy et al.
  1994).
- **SSIM** (Wang et al. 2004, "Image quality assessment: from error
  visibility to structural similarity"), as
  ``skimage.metrics.structural_similarity`` computes it with its defaults
  (uniform 7x7 window), per channel, on the display-encoded images
  (:mod:`cornell_harness.evaluate.ssim`, in numpy).
- **HDR-FLIP** (Andersson et al. 2021, "Visualizing Errors in Rendered High
  Dynamic Range Images"), its mean over pixels, on the linear images with
  its own exposure range from the reference: :mod:`cornell_harness.evaluate.flip`.
- **RMSE** and **relMSE** are on linear radiance, over all channels.
  relMSE = mean((img - ref)² / (ref² + ε)) with ε = 1e-2, the value used by
  Rousselle et al. 2011 and much of the denoising literature: it stops
  near-black reference pixels from dominating the mean.
- **Invalid pixels** (NaN, ±Inf, negative) are counted per pixel. In
  :func:`image_metrics` (and for the ΔE map) a pixel with any non-finite
  channel is replaced by black before the error metrics are computed,
  so one broken pixel is reported as a count instead of poisoning every mean.
"""

from __future__ import annotations

from typing import Collection

import numpy as np

from cornell_harness.evaluate import ciede2000, flip
from cornell_harness.evaluate import ssim as structural_similarity
from cornell_harness.evaluate.pixels import all_finite, as_image, as_pair, finite_pixels, luminance, zero_broken_pixels
from cornell_harness.scenes.quantities import DEFAULT_QUANTITY, has_colour

# No colour-science or skimage: `import colour` costs ~1.5 s and skimage.metrics pulls in scipy.stats (~2 s)
# and SSIM scipy.ndimage (~0.4 s), which `cbox compare-image` cannot afford. CIEDE2000 and the sRGB
# transfer are cornell_harness.evaluate.ciede2000, SSIM cornell_harness.evaluate.ssim: the same arithmetic, in numpy.

REINHARD_KEY = 0.18
REINHARD_DELTA = 1e-4
REL_MSE_EPS = 1e-2
#: Fraction of pixels with the largest relMSE terms that ``rel_mse_trimmed`` drops:
#: a handful of fireflies should not decide a comparison (0.1%, as is common in
#: denoising papers' trimmed relMSE).
REL_MSE_TRIM = 1e-3
JND_DELTA_E2000 = 2.3
#: The statistics of one ΔE00 map (:func:`delta_e2000_stats`).
DELTA_E_KEYS = ("delta_e2000_mean", "delta_e2000_p95", "delta_e2000_max", "delta_e2000_frac_gt_2_3")


def exposure_scale(ref, key: float = REINHARD_KEY, delta: float = REINHARD_DELTA) -> float:
    """Reinhard key-value exposure ``key / exp(mean(log(delta + Y)))`` of ``ref``."""
    ref = as_image(ref)
    y = luminance(ref)[finite_pixels(ref)]
    if y.size == 0:
        raise ValueError("reference has no finite pixels; cannot derive an exposure")
    # Reconstruction filters with negative lobes can leave slightly negative
    # luminance; log(delta + Y) would then be NaN.
    y = np.maximum(y, 0.0)
    return float(key / np.exp(np.mean(np.log(delta + y))))


def display_exposure(ref, quantity: str = DEFAULT_QUANTITY) -> float:
    """The exposure of ``ref``'s display and display-referred metrics: :func:`exposure_scale` for radiance.

    An ambient-occlusion image is already a fraction in [0, 1], so it is
    shown as it is (exposure 1: A = 1 is white); a key-value exposure would
    brighten a darker AO image and hide the difference.
    """
    return exposure_scale(ref) if has_colour(quantity) else 1.0


def display_encode(img, exposure: float) -> np.ndarray:
    """Exposed, NaN->0, clipped to [0, 1], sRGB-OETF-encoded float64 image."""
    exposed = as_image(img) * float(exposure)
    if not all_finite(exposed):  # without NaN or Inf, nan_to_num would only copy
        exposed = np.nan_to_num(exposed, nan=0.0)
    np.clip(exposed, 0.0, 1.0, out=exposed)
    return np.asarray(ciede2000.srgb_eotf_inverse(exposed), dtype=np.float64)


def rmse(img, ref) -> float:
    """Root-mean-square error on linear radiance, over all channels."""
    img, ref = as_pair(img, ref)
    return float(np.sqrt(np.mean((img - ref) ** 2)))


def rel_mse(img, ref, eps: float = REL_MSE_EPS, trim: float = 0.0) -> float:
    """Mean of ``(img - ref)² / (ref² + eps)``, dropping the worst ``trim`` fraction of pixels."""
    img, ref = as_pair(img, ref)
    return _trimmed_mean(_rel_mse_terms(img, ref, eps), trim)


def _rel_mse_terms(img: np.ndarray, ref: np.ndarray, eps: float = REL_MSE_EPS) -> np.ndarray:
    """relMSE's per-pixel terms (mean over channels), flat."""
    return channel_mean((img - ref) ** 2 / (ref**2 + eps)).ravel()


def channel_mean(x: np.ndarray) -> np.ndarray:
    """``np.mean(x, axis=-1)`` of an (..., 3) array, the same bits (numpy sums a 3-long axis in order, then
    divides by 3) at a fifth of the cost (numpy's reduction runs its loop once per pixel)."""
    return (x[..., 0] + x[..., 1] + x[..., 2]) / 3


def _trimmed_mean(per_pixel: np.ndarray, trim: float) -> float:
    """The mean of ``per_pixel`` without its largest ``trim`` fraction."""
    if not 0.0 <= trim < 1.0:
        raise ValueError(f"trim must be in [0, 1), got {trim}")
    # The epsilon keeps e.g. 0.29 * 100 = 28.999999999999996 from dropping 28.
    n_drop = int(np.floor(trim * per_pixel.size + 1e-9))
    if n_drop:
        per_pixel = np.sort(per_pixel)[: per_pixel.size - n_drop]
    return float(np.mean(per_pixel))


def psnr(img, ref, exposure: float | None = None) -> float:
    """PSNR in dB of the display-encoded images (data range 1); inf if identical."""
    img, ref = as_pair(img, ref)
    if exposure is None:
        exposure = exposure_scale(ref)
    return _psnr_encoded(display_encode(img, exposure), display_encode(ref, exposure))


def _psnr_encoded(test: np.ndarray, true: np.ndarray) -> float:
    """PSNR of display-encoded ``test`` against ``true``: skimage's peak_signal_noise_ratio, as it computes it
    (its module imports scipy.stats: seconds)."""
    with np.errstate(divide="ignore"):  # identical images: log10(1/0) = inf, as intended
        value = 10 * np.log10(1.0 / np.mean((true - test) ** 2, dtype=np.float64))
    return float(value)


def ssim(img, ref, exposure: float | None = None) -> float:
    """Mean SSIM of the display-encoded images (skimage's defaults, data range 1: :mod:`cornell_harness.evaluate.ssim`)."""
    img, ref = as_pair(img, ref)
    if exposure is None:
        exposure = exposure_scale(ref)
    return structural_similarity.ssim(display_encode(img, exposure), display_encode(ref, exposure), data_range=1.0)


def linear_srgb_to_lab(img) -> np.ndarray:
    """CIELAB (D65, 2° observer) of a linear-sRGB image, unclipped."""
    return ciede2000.linear_srgb_to_lab(as_image(img))


def delta_e2000_lab(lab1, lab2) -> np.ndarray:
    """CIEDE2000 between CIELAB arrays of shape (..., 3)."""
    return ciede2000.delta_e2000(lab1, lab2)


def delta_e2000(img, ref, exposure: float | None = None, full: bool = False):
    """Mean CIEDE2000 of the exposed images; with ``full=True`` also the (H, W) map."""
    img, ref = as_pair(img, ref)
    if exposure is None:
        exposure = exposure_scale(ref)
    # zero_broken_pixels(img), both exposed, CIELAB and ΔE00 on flat channels: no (H, W, 3) temporaries.
    de_map = ciede2000.delta_e2000_linear(img, ref, exposure)
    mean = float(np.mean(de_map))
    return (mean, de_map) if full else mean


def delta_e2000_stats(de_map, threshold: float = JND_DELTA_E2000) -> dict:
    """Mean, 95th percentile, max and fraction above ``threshold`` of a ΔE00 map."""
    de = np.asarray(de_map, dtype=np.float64).ravel()
    if de.size == 0:
        raise ValueError("empty ΔE map")
    frac_key = f"delta_e2000_frac_gt_{threshold}".replace(".", "_")
    return {
        "delta_e2000_mean": float(np.mean(de)),
        "delta_e2000_p95": float(np.percentile(de, 95)),
        "delta_e2000_max": float(np.max(de)),
        frac_key: float(np.mean(de > threshold)),
    }


def invalid_pixel_counts(img) -> dict:
    """Pixels with any NaN, any ±Inf, and any negative finite channel."""
    img = as_image(img)
    if all_finite(img):  # the common case at a tenth of the cost: no NaN or Inf, and negatives counted only if any
        negative = int(np.count_nonzero(np.any(img < 0, axis=-1))) if np.min(img) < 0 else 0
        return {"nan_count": 0, "inf_count": 0, "negative_count": negative}
    return {
        "nan_count": int(np.count_nonzero(np.any(np.isnan(img), axis=-1))),
        "inf_count": int(np.count_nonzero(np.any(np.isinf(img), axis=-1))),
        "negative_count": int(
            np.count_nonzero(np.any(np.isfinite(img) & (img < 0), axis=-1))
        ),
    }


def mean_radiance(img) -> np.ndarray:
    """Per-channel mean radiance over the finite pixels, shape (3,); NaN if none."""
    img = as_image(img)
    # Without broken pixels, the (n, 3) rows boolean indexing would copy, in the same order: the same sums.
    finite = img.reshape(-1, 3) if all_finite(img) else img[finite_pixels(img)]
    if finite.shape[0] == 0:
        return np.full(3, np.nan)
    return finite.mean(axis=0)


def mean_radiance_rel_error(img, ref) -> float:
    """Relative error of the mean radiance: mean over channels of :func:`mean_radiance`, img over ref, minus 1."""
    return _mean_rel_error(mean_radiance(img), mean_radiance(ref))


def _mean_rel_error(mean_img: np.ndarray, mean_ref: np.ndarray) -> float:
    with np.errstate(divide="ignore", invalid="ignore"):  # a black reference: inf or NaN, not a warning
        return float(np.mean(mean_img) / np.mean(mean_ref) - 1.0)


def masked_pixels(img, mask) -> np.ndarray:
    """The pixels of ``img`` where the (H, W) ``mask`` is true, as an (n, 1, 3) image.

    Every per-pixel metric here (RMSE, relMSE, ΔE, mean radiance) then
    applies to a region unchanged; pass the whole reference's exposure to ΔE.
    """
    img = as_image(img)
    mask = np.asarray(mask, dtype=bool)
    if mask.shape != img.shape[:2]:
        raise ValueError(f"mask shape {mask.shape} does not match image shape {img.shape[:2]}")
    return img[mask][:, None, :]


def image_metrics(img, ref, exposure: float | None = None, quantity: str = DEFAULT_QUANTITY,
                  with_flip: bool = True, delta_e_map: np.ndarray | None = None,
                  keys: Collection[str] | None = None) -> dict:
    """Every metric of ``img`` against ``ref`` as one flat, JSON-serialisable dict; with ``keys``, those only.

    Of an image of another quantity than radiance (ambient occlusion: one
    scalar per pixel, written as grey), the colour differences and HDR-FLIP
    (:data:`cornell_harness.evaluate.registry.COLOUR_METRICS`) are left out.
    ``flip_mean`` is :func:`cornell_harness.evaluate.flip.flip_mean`, with its own
    exposures from the reference (``exposure`` does not apply to it); ``with_flip=False`` leaves it out:
    at 8 exposures it costs more than all the others together (~0.8 s of 256²). ``delta_e_map``:
    :func:`delta_e2000`'s ``full`` map of these images at ``exposure``, where the caller has it already.

    ``keys`` (registry names; :func:`cornell_harness.evaluate.registry.check_metrics` chooses them for a check)
    computes only what they need, and gives what comes with it at no cost: the four ``delta_e2000_*``
    statistics of one map, ``rmse`` with ``mse``, the three channel means with their relative error, the
    three pixel counts. Each value is the same, bit for bit, as with every metric.
    """
    img, ref = as_pair(img, ref)
    wanted = None if keys is None else frozenset(keys)

    def want(*names: str) -> bool:
        return wanted is None or not wanted.isdisjoint(names)

    if exposure is None and want("psnr", "ssim", *DELTA_E_KEYS):  # a pass over the reference's logarithms
        exposure = display_exposure(ref, quantity)

    clean = img if all_finite(img) else zero_broken_pixels(img)  # no copy without broken pixels
    out = {}
    if want("rmse", "mse"):
        mse = float(np.mean((clean - ref) ** 2))
        out["rmse"], out["mse"] = float(np.sqrt(mse)), mse
    if want("rel_mse", "rel_mse_trimmed"):
        terms = _rel_mse_terms(clean, ref)
        out["rel_mse"] = _trimmed_mean(terms, 0.0)
        if want("rel_mse_trimmed"):  # a sort: several times relMSE's cost
            out["rel_mse_trimmed"] = _trimmed_mean(terms, REL_MSE_TRIM)
    if want("psnr", "ssim"):  # each image encoded once for both
        test, true = display_encode(clean, exposure), display_encode(ref, exposure)
        if want("psnr"):
            out["psnr"] = _psnr_encoded(test, true)
        if want("ssim"):
            out["ssim"] = structural_similarity.ssim(test, true, data_range=1.0)
    if has_colour(quantity):
        if want(*DELTA_E_KEYS):
            de_map = delta_e_map if delta_e_map is not None else delta_e2000(clean, ref, exposure=exposure,
                                                                                full=True)[1]
            out.update(delta_e2000_stats(de_map))
        if with_flip and want("flip_mean"):
            out["flip_mean"] = flip.flip_mean(clean, ref)
    if want("nan_count", "inf_count", "negative_count"):
        out.update(invalid_pixel_counts(img))
    if want("mean_radiance_r", "mean_radiance_g", "mean_radiance_b", "mean_radiance_rel_error"):
        # Mean radiance skips broken pixels rather than zeroing them: they are
        # counted separately and should not also read as missing energy.
        mean_img = mean_radiance(img)
        out.update(mean_radiance_r=float(mean_img[0]), mean_radiance_g=float(mean_img[1]),
                   mean_radiance_b=float(mean_img[2]),
                   mean_radiance_rel_error=_mean_rel_error(mean_img, mean_radiance(ref)))
    return out
