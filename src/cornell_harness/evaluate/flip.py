"""HDR-FLIP of an image against the reference: its viewing parameters, its per-pixel map and its mean.

FLIP (Andersson et al. 2020, "FLIP: A Difference Evaluator for Alternating
Images", HPG) estimates, per pixel, how visible the difference is when a viewer
flips between two images; 0 is none, 1 the largest. HDR-FLIP (Andersson,
Nilsson, Shirley & Akenine-Möller 2021, "Visualizing Errors in Rendered High
Dynamic Range Images", Eurographics short papers) applies it to linear HDR
images: both are exposed by ``2^c`` for ``N`` exposures ``c`` evenly spaced in
[c_start, c_stop], tone-mapped and scored by LDR-FLIP, and each pixel keeps its
largest error. The paper derives the range from the reference alone:

- ``x_max`` is the input that the tone mapper maps to 0.85
  (:func:`tone_mapper_input_for`);
- ``c_start = log2(x_max / L_max)``: the brightest reference pixel is just
  below white;
- ``c_stop = log2(x_max / L_median)``: so is the median pixel;
- ``N = max(2, ceil(c_stop − c_start))``: about one exposure per stop.

``L`` is luminance with the BT.709 weights
(:func:`cornell_harness.evaluate.pixels.luminance`, FLIP's own), and the median is
the library's: element ``n // 2`` of the sorted luminances.

The map is computed by :mod:`cornell_harness.evaluate.hdr_flip`: the authors' library's arithmetic (the
``flip-evaluator`` package, ``FLIP.h``), with the reference's side of each exposure done once per
reference, so a sweep pays only each image's own side (~16× less CPU than the library at 256²,
BENCHMARKS.md). The library stays a dependency, to check that against (:func:`library_flip_map`). It
would also pick the exposures itself; we compute them here and pass them in
(:func:`flip_parameters`), so the viewing conditions a number was made under
are known and recorded, and so a mostly black reference cannot stretch them:
where half or more of its pixels are black the median is 0, which
``flip-evaluator`` 1.7 replaces by about 1.2e-7 (measured: a brightest
pixel of 8 then gives 26 exposures, most of them of black); here the median
of the non-black pixels stands in. A reference with no light at all has no
exposure range: its FLIP is NaN. The tone mapper and pixels per degree are
the library's defaults, named here: ACES (Narkowicz's fit, with the
library's 0.6 pre-exposure cancelled) and 67 pixels per degree (a 0.7 m
wide 3840-pixel display seen from 0.7 m).

Inputs are linear-sRGB float images of one shape; a pixel with a NaN or Inf
is taken as black (the harness's one rule,
:func:`cornell_harness.evaluate.pixels.zero_broken_pixels`) and negative values as 0
(HDR-FLIP's input is non-negative radiance). :mod:`~cornell_harness.evaluate.hdr_flip` (numba) and
``flip_evaluator`` are imported when first needed: ``cbox --help``, and a command that scores no FLIP,
should not load them.
"""

from __future__ import annotations

import math
import os

import numpy as np

from cornell_harness.evaluate.pixels import as_image, as_pair, luminance, zero_broken_pixels

#: The library's default tone mapper (its name as ``flip_evaluator`` takes it).
TONE_MAPPER = "aces"
#: Tone-mapper coefficients (a, b, c, d, e, f) of t(x) = (a x² + b x + c) / (d x² + e x + f), as in the
#: library (``FLIP::ToneMappingCoefficients``): ACES after Narkowicz 2015, "ACES Filmic Tone Mapping Curve",
#: with the library's 0.6 pre-exposure cancelled.
ACES_COEFFICIENTS = (0.6 * 0.6 * 2.51, 0.6 * 0.03, 0.0, 0.6 * 0.6 * 2.43, 0.6 * 0.59, 0.14)
#: The tone-mapped value the brightest (c_start) and the median (c_stop) reference pixel are exposed to.
EXPOSED_TARGET = 0.85
#: Viewing conditions: distance (m), display width (pixels) and display width (m): the library's defaults.
VIEWING_DISTANCE_M, DISPLAY_WIDTH_PX, DISPLAY_WIDTH_M = 0.7, 3840, 0.7
#: Pixels per degree of visual angle under those conditions (the library's ``calculatePPD``), about 67.
PIXELS_PER_DEGREE = VIEWING_DISTANCE_M * (DISPLAY_WIDTH_PX / DISPLAY_WIDTH_M) * math.pi / 180.0


def tone_mapper_input_for(target: float = EXPOSED_TARGET, coefficients=ACES_COEFFICIENTS) -> float:
    """The input x ≥ 0 that the tone mapper maps to ``target``: the larger root of
    (a − t·d) x² + (b − t·e) x + (c − t·f) = 0."""
    a0, b0, c0, d0, e0, f0 = coefficients
    a, b, c = a0 - target * d0, b0 - target * e0, c0 - target * f0
    if a == 0.0:
        return -c / b
    half = -0.5 * b / a
    return half + math.sqrt(half * half - c / a)


def flip_input(img) -> np.ndarray:
    """``img`` as HDR-FLIP takes it: float32, broken pixels black, negative values 0."""
    return np.ascontiguousarray(np.maximum(zero_broken_pixels(as_image(img)), 0.0),
                                dtype=np.float32)


def flip_parameters(ref) -> dict | None:
    """The HDR-FLIP parameters for reference ``ref``, in ``flip_evaluator``'s own names; None if it is black.

    ``ppd``, ``tonemapper``, ``startExposure``, ``stopExposure`` (stops) and
    ``numExposures``: the module docstring says how they are derived. Equal
    to what the library picks itself whenever at least half the reference's
    pixels have light (it computes in float32, so to about 1e-6).
    """
    y = luminance(flip_input(ref)).ravel()
    y_max = float(y.max()) if y.size else 0.0
    if not y_max > 0.0:
        return None
    y_median = float(np.partition(y, y.size // 2)[y.size // 2])
    if not y_median > 0.0:
        lit = y[y > 0.0]
        y_median = float(np.partition(lit, lit.size // 2)[lit.size // 2])
    x_max = tone_mapper_input_for()
    start, stop = math.log2(x_max / y_max), math.log2(x_max / y_median)
    return {"ppd": PIXELS_PER_DEGREE, "tonemapper": TONE_MAPPER, "startExposure": start, "stopExposure": stop,
            "numExposures": max(2, math.ceil(stop - start))}


def flip_library():
    """The ``flip_evaluator`` module, its OpenMP threads set to sleep rather than spin while they wait.

    Its OpenMP runtime (a libgomp of its own) reads ``OMP_WAIT_POLICY`` when
    it loads. Spinning threads cost CPU at every one of its barriers when the
    machine is busy: measured under a load of 7 on 2 cores, 0.5 s of CPU for a
    16 × 16 image against 5 ms sleeping, and 1.1-1.5 s against 0.83 s at
    256 × 256. Nothing else in the harness uses OpenMP; a value the user set
    is kept.
    """
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    import flip_evaluator

    return flip_evaluator


def exposure_scales(parameters: dict) -> list:
    """The factors 2^c of the exposures ``parameters`` name, as the library computes them (float32)."""
    from cornell_harness.evaluate import hdr_flip

    return hdr_flip.exposure_scales(parameters["startExposure"], parameters["stopExposure"],
                                    parameters["numExposures"])


def flip_map(img, ref, parameters: dict | None = None) -> np.ndarray:
    """Per-pixel HDR-FLIP (H, W) float64 of ``img`` against ``ref``, in [0, 1]; NaN everywhere for a black ``ref``.

    ``parameters`` default to :func:`flip_parameters` of ``ref``, cached per reference content. Computed by
    :mod:`cornell_harness.evaluate.hdr_flip` (the library's arithmetic, the reference's side of each exposure
    computed once per reference); ``flip_evaluator`` computes the same map to a few 1e-6 per pixel
    (:func:`library_flip_map`).
    """
    from cornell_harness.evaluate import hdr_flip  # numba: not loaded by a command that scores no FLIP

    img, ref = as_pair(img, ref)
    ref32 = flip_input(ref)
    digest = hdr_flip.SideCache.digest(ref32)
    if parameters is None:
        parameters = _cached_parameters(ref32, digest)
    if parameters is None:
        return np.full(ref.shape[:2], np.nan)
    if parameters["tonemapper"] != TONE_MAPPER:
        raise ValueError(f"HDR-FLIP here tone-maps by {TONE_MAPPER!r} only, not {parameters['tonemapper']!r}")
    fmap = hdr_flip.hdr_flip_map(flip_input(img), ref32, exposure_scales(parameters), ACES_COEFFICIENTS,
                                 parameters["ppd"], digest=digest)
    return fmap.astype(np.float64)


def library_flip_map(img, ref, parameters: dict | None = None) -> np.ndarray:
    """:func:`flip_map` computed by the authors' ``flip_evaluator`` (8 exposures of 256²: ~0.4-0.8 s against
    ~0.05 s), kept to check the harness's own against (tests/evaluate/test_hdr_flip.py, benchmarks/scoring.py)."""
    flip_evaluator = flip_library()
    img, ref = as_pair(img, ref)
    if parameters is None:
        parameters = flip_parameters(ref)
    if parameters is None:
        return np.full(ref.shape[:2], np.nan)
    fmap, _, _ = flip_evaluator.evaluate(flip_input(ref), flip_input(img), "HDR", applyMagma=False,
                                         computeMeanError=False, parameters=dict(parameters))
    return np.asarray(fmap, dtype=np.float64).reshape(ref.shape[:2])


#: :func:`flip_parameters` by reference content (digest of its float32 pixels); a few references at a time.
_PARAMETERS: dict[str, dict | None] = {}


def _cached_parameters(ref32: np.ndarray, digest: str) -> dict | None:
    if digest not in _PARAMETERS:
        if len(_PARAMETERS) >= 16:
            _PARAMETERS.clear()
        _PARAMETERS[digest] = flip_parameters(ref32)
    found = _PARAMETERS[digest]
    return None if found is None else dict(found)


def flip_mean(img, ref, parameters: dict | None = None) -> float:
    """Mean of :func:`flip_map`: the ``flip_mean`` metric."""
    return float(np.mean(flip_map(img, ref, parameters)))
