"""The expected mean radiance of each stress variant, and the noise its renders are judged with.

An :class:`Expectation` carries the value, its own standard error, and what
the standard error of a render's mean is taken from. The noise model of
renders against a stored reference (a render at ``spp`` has the reference
renderer's per-sample variance divided by ``spp``) is
:mod:`cornell_harness.evaluate.noise`'s.

Tolerances
----------
Every mean check is a z-test: ``|mean - expected| ≤ Z·SE + allowance·|expected|
+ 1e-6·|expected|``, :data:`Z_CRIT` = 4.5 (two-sided α = 6.8e-6 per check,
~2e-4 family-wise over the ~25 checks of a two-renderer suite); the 1e-6
(:data:`FLOAT_FLOOR`) is for float32 storage. SE² = SE(render)² + SE(expected)²:

- **furnace**: every pixel has the same expectation and pixels are
  independent, so SE(render) = sd(pixels)/√pixels, valid for any renderer with
  a finite-variance estimator (see the findings in
  :mod:`cornell_harness.stress.variants`); the analytic value has no error. At
  albedo 0 SE = 0 and the check is exact.
- **stored reference** (16384 spp): SE(expected) from its variance image;
  SE(render) from the render's own per-pixel variance when the renderer
  returns one (our path tracer, at spp ≥ 2), else from the reference
  renderer's per-sample variance (reference variance × 16384,
  :func:`cornell_harness.evaluate.noise.render_variance`) at the render's spp: exact
  for Mitsuba, a scale for others. At 1×1 a sample lands anywhere in the
  view: its variance is the spread of the reference's pixels plus the mean
  per-pixel variance. At 2048² the same formula divided by 8² is an upper
  bound (finer pixels stratify the samples). A pixel's three channels come
  from the same paths: the channel mean's variance is bounded by the mean of
  the channel variances (Cauchy-Schwarz), so SE is never understated.
- **small-light**: the directly seen light is now a sub-pixel dot hit by a
  few samples per image (its share of the mean cannot be estimated at any
  practical spp), so the mean is taken over the pixels outside the
  footprints of both the small and the original light (projected bounding
  boxes + 1 pixel), in render and reference alike. Equal power makes the
  illumination outside them nearly the same: the light's extent changes that
  mean by -0.035% ± 0.009% (measured with Mitsuba at 2048 spp), so the check
  allows :data:`~cornell_harness.stress.variants.SMALL_LIGHT_ALLOWANCE` = 0.1% on top
  of the z-test.
- **grazing-camera**: SE(expected) from the spread of the reference's 4
  batches (per pixel, summed over 16384 pixels); SE(render) as above, with
  that reference's per-sample variance.

At these spp the tolerances are about ±0.4% (albedo 0.5), ±2% (albedo 0.99,
our path tracer), ±0.3% (scaled), ±0.4% (radiance; small light, with its
allowance), ±0.5% (grazing), ±2.2% (1 spp), ±1.5% (1×1) and ±0.15-0.2% (2048²).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cornell_harness.evaluate.noise import render_variance
from cornell_harness.scenes.analytic import furnace_radiance
from cornell_harness.scenes.model import Scene
from cornell_harness.workflows.sandbox import SandboxOutcome
from cornell_harness.stress.variants import REFERENCE_BATCHES, Variant

#: Critical |z| of every statistical mean check: two-sided α = 6.8e-6 per check, about 2e-4
#: family-wise over the ~25 mean checks of a two-renderer suite (Šidák).
Z_CRIT = 4.5
#: Relative slack on every expected value for float32 image storage and summation.
FLOAT_FLOOR = 1e-6


def pixel_var(var) -> np.ndarray:
    """Per-pixel variance bound of the channel mean, (H, W) float64.

    Var(mean_c X_c) ≤ mean_c Var(X_c) (Cauchy-Schwarz: the channels of a
    pixel come from the same paths and may be correlated), so noise is never
    understated.
    """
    return np.asarray(var, dtype=np.float64).mean(axis=-1)


def region_se(var: np.ndarray, sel: np.ndarray) -> float:
    """SE of the mean over the pixels ``sel`` of an image with per-pixel variance ``var`` (H, W)."""
    return float(np.sqrt(var[sel].sum()) / sel.sum())


def image_se(var: np.ndarray) -> float:
    """SE of the mean over all pixels of an image with per-pixel variance ``var`` (H, W)."""
    return float(np.sqrt(var.sum()) / var.size)


@dataclass
class Expectation:
    """The expected mean radiance of a variant, with what a render's noise is judged by."""

    value: float | None  # None: no mean check (``source`` says why)
    source: str
    basis: str = ""
    se: float = 0.0  # standard error of ``value`` itself
    allowance: float = 0.0  # relative systematic allowance
    keep: np.ndarray | None = None  # (H, W) pixels the mean is taken over; None: all
    pixel_spread: bool = False  # noise from the image's own pixel spread (all pixels alike)
    model_se_1spp: float | None = None  # SE of a 1-spp render's mean under the reference renderer's noise
    scale: float = 1.0
    error: str | None = None  # the expected value could not be made (the rows are errors)


def _region_model(var_of_mean: np.ndarray, ref_spp: int, keep: np.ndarray | None,
                  ref_shape: tuple[int, int], shape: tuple[int, int], ref_image: np.ndarray) -> float | None:
    """SE of a 1-spp render's (region) mean at ``shape``, from a reference's variance of the mean.

    ``var_of_mean · ref_spp`` is the reference renderer's per-sample variance
    of each pixel. At the reference's own resolution the render's mean over
    the region has variance Σ_p v_p / (N² · spp). At k× the resolution
    (k integer, per axis) the same paths are spread over k² finer pixels:
    Σ_p v_p / (N² · k² · spp) is then an upper bound (finer pixels stratify
    the samples more). At 1×1 one sample lands anywhere in the view: its
    variance is the spread of the reference's pixels plus the mean per-pixel
    variance (law of total variance).
    """
    v = render_variance(pixel_var(var_of_mean), ref_spp, 1)
    if shape == ref_shape:
        return region_se(v, np.ones(ref_shape, bool) if keep is None else keep)
    if keep is not None:
        return None
    if shape == (1, 1):
        pix = np.asarray(ref_image, np.float64).mean(axis=-1)
        return float(np.sqrt(pix.var() + v.mean()))
    ky, kx = shape[0] / ref_shape[0], shape[1] / ref_shape[1]
    if ky == kx and ky >= 1 and ky == int(ky):
        return image_se(v) / ky
    return None


def _reference_basis(variant: Variant, ref_spp: int) -> str:
    return (f"|mean - expected| ≤ {Z_CRIT}·SE"
            + (f" + {variant.allowance:.2%}" if variant.allowance else "")
            + f"; SE² = SE(reference, {ref_spp} spp)² + SE(render)², SE(render) from the render's own variance, "
              f"else the reference renderer's per-sample variance at this spp")


def _reference_expectation(variant: Variant, scene: Scene, ref) -> Expectation:
    """The stored reference's (region) mean, times the variant's scale; ``ref`` a stored Reference."""
    img = np.asarray(ref.image, np.float64)
    h, w = img.shape[:2]
    keep = None
    if variant.exclude is not None:
        keep = ~variant.exclude(scene)
    scale = float(variant.reference_scale()) if variant.reference_scale else 1.0
    sel = np.ones((h, w), bool) if keep is None else keep
    value = float(img.mean(axis=-1)[sel].mean()) * scale
    se = region_se(pixel_var(ref.variance), sel) * scale
    shape = (scene.camera.height, scene.camera.width)
    model = _region_model(ref.variance, ref.spp, keep, (h, w), shape, img)
    region = "" if keep is None else f" over the {int(sel.sum())} pixels outside the lights' footprints"
    source = f"{variant.expected_note}: {value:.6g}{region}" + (f" (reference × {scale:.6g})" if scale != 1 else "")
    return Expectation(value, source, _reference_basis(variant, ref.spp), se, variant.allowance, keep, False,
                       None if model is None else model * scale, scale)


def _furnace_expectation(variant: Variant) -> Expectation:
    value = furnace_radiance(variant.albedo, 1.0, -1)
    basis = (f"|mean - expected| ≤ {Z_CRIT}·SE + {FLOAT_FLOOR:g}·expected; SE = sd(pixels)/sqrt(pixels): every "
             "pixel has the same expectation and pixels are independent (exact when the estimator is)")
    return Expectation(value, variant.expected_note, basis, pixel_spread=True)


def _variant_reference_expectation(variant: Variant, scene: Scene, outcome: SandboxOutcome | None,
                                   why_not: str | None, renderer: str) -> Expectation:
    """The mean of a variant reference rendered by the suite with ``renderer`` (``outcome``: its batches), SE
    from their spread."""
    label = f"{renderer}, {REFERENCE_BATCHES} × {variant.reference_spp} spp"
    if outcome is None:
        return Expectation(None, f"no variant reference ({label}): {why_not}")
    problem = outcome.problem()
    if problem:
        return Expectation(None, f"variant reference ({label}) failed", error=f"variant reference ({label}): {problem}")
    stack = np.stack([np.asarray(i, np.float64) for i in outcome.images])
    if not np.all(np.isfinite(stack)):
        return Expectation(None, f"variant reference ({label}) failed",
                           error=f"variant reference ({label}) has non-finite pixels")
    mean = stack.mean(axis=0)
    var_of_mean = stack.var(axis=0, ddof=1) / len(stack)
    value = float(mean.mean())
    se = image_se(pixel_var(var_of_mean))
    model = image_se(render_variance(pixel_var(var_of_mean), REFERENCE_BATCHES * variant.reference_spp, 1))
    basis = (f"|mean - expected| ≤ {Z_CRIT}·SE; SE² = SE(variant reference)² + SE(render)², the reference's from "
             f"the spread of its {REFERENCE_BATCHES} batches, the render's from its own variance, else the "
             "reference renderer's per-sample variance at this spp")
    source = (f"{variant.expected_note}: {value:.6g} ± {se:.2g} (reference run {outcome.time_s:.1f} s, "
              f"{outcome.peak_rss_mb:.0f} MB)")
    return Expectation(value, source, basis, se, model_se_1spp=model)


def expectation_for(variant: Variant, scene: Scene, stored_reference=None, outcome: SandboxOutcome | None = None,
                    why_not: str | None = None, reference_renderer: str = "the reference renderer") -> Expectation:
    """The expectation of ``variant`` by its kind; ``stored_reference`` for "reference", ``outcome`` for
    "variant-reference" (rendered by ``reference_renderer``; None, with ``why_not``, when it was not)."""
    if variant.expected == "furnace":
        return _furnace_expectation(variant)
    if variant.expected == "reference":
        return _reference_expectation(variant, scene, stored_reference)
    if variant.expected == "variant-reference":
        return _variant_reference_expectation(variant, scene, outcome, why_not, reference_renderer)
    return Expectation(None, variant.expected_note)
