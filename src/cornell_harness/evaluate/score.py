"""The one scorer: every number of one image against a reference, for every command that scores.

``cbox compare``, ``converge`` and the gate's runs (:func:`cornell_harness.workflows.runner.run_one`),
``cbox compare-image`` (:mod:`cornell_harness.workflows.compare_image`) and the gate's own checks on
checkpoints and bias-limit renders (:func:`metric_value`) all score through :func:`score_image`, so one
image gets the same numbers from each, bit for bit. The metrics themselves are
:mod:`cornell_harness.evaluate.metrics`', :mod:`cornell_harness.evaluate.noise`'s and
:mod:`cornell_harness.evaluate.regions`'; this module decides what to compute and shares the work between
them: the float64 pixels, the reference's display exposure and the ΔE00 map are made once.

``keys`` (registry names, :mod:`cornell_harness.evaluate.registry`) computes only what they name, with what
comes at no cost with it (:func:`cornell_harness.evaluate.metrics.image_metrics`): the ΔE00 map for a
``delta_e2000_*`` key, HDR-FLIP for ``flip_mean``, the noise yardsticks for a ``noise_*`` key, a region's
metric for a ``region.<region>.<metric>`` key. Each value is the same as with every metric.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Collection, Mapping

import numpy as np

from cornell_harness.evaluate import metrics
from cornell_harness.evaluate import noise as stats
from cornell_harness.evaluate import regions as named_regions
from cornell_harness.evaluate.registry import REGION_METRICS, region_metric
from cornell_harness.scenes.quantities import has_colour

if TYPE_CHECKING:
    from cornell_harness.store.references import Reference

#: The keys of the noise yardsticks (:func:`cornell_harness.evaluate.noise.noise_yardsticks`) start with it.
NOISE_PREFIX = "noise_"


@dataclass
class Score:
    """One image's numbers against a reference."""

    metrics: dict  # image metrics (metrics.image_metrics), in its order
    noise: dict | None  # the noise yardsticks, or None: noise_note says why
    noise_note: str | None
    regions: dict  # region -> metric -> value ({} when no region was scored)
    delta_e_map: np.ndarray | None = None  # (H, W) ΔE00 at the reference's display exposure, where it was made

    @property
    def values(self) -> dict:
        """The image metrics and the noise yardsticks, flat: a results row's metric columns (regions apart)."""
        return {**self.metrics, **(self.noise or {})}

    def value(self, key: str) -> float | None:
        """One number by its column name (``region.<region>.<metric>`` too); None where it was not scored."""
        return lookup(self.values, self.regions, key)


def lookup(values: Mapping, regions: Mapping, key: str) -> float | None:
    """``key`` of flat ``values`` or, as ``region.<region>.<metric>``, of ``regions``, as a float; None if absent."""
    parts = region_metric(key)
    v = values.get(key) if parts is None else regions.get(parts[0], {}).get(parts[1])
    return None if v is None else float(v)


def score_image(image: np.ndarray, reference: "Reference", spp: int | None = None, *,
                masks: Mapping[str, np.ndarray] | None = None, variance: np.ndarray | None = None,
                keys: Collection[str] | None = None, with_flip: bool = True,
                noise_note: str | None = None) -> Score:
    """Every metric of ``image`` against ``reference`` (its ``image``, ``quantity``, and for the noise
    yardsticks and ``mean_z`` its ``variance``, ``noise`` and spps); with ``keys``, those only.

    ``spp`` is the image's samples per pixel (the noise model's; None: unknown, no yardsticks). ``masks``
    the scene's named regions (:func:`cornell_harness.evaluate.regions.region_masks`), each scored
    (:func:`cornell_harness.evaluate.regions.region_metrics`; ``variance``, the image's own variance of its
    mean where the renderer gives one, is ``mean_z``'s). ``with_flip=False`` leaves ``flip_mean`` out of
    every metric (it costs more than the others together). ``noise_note`` says why the yardsticks cannot be
    computed when the caller knows (a file with no spp); they are skipped then.
    """
    every = keys is None
    keys = frozenset(keys or ())
    with_de = every or not keys.isdisjoint(metrics.DELTA_E_KEYS)
    with_noise = every or any(k.startswith(NOISE_PREFIX) for k in keys)
    # float64 once, where each metric would convert the float32 pixels again (the same values, exactly: the
    # metrics take as_pair's arrays), and the exposure once (each would compute it from the reference again).
    img, ref = metrics.as_pair(image, reference.image)
    colour = has_colour(reference.quantity)
    needs_exposure = with_de or with_noise or not keys.isdisjoint(("psnr", "ssim"))
    exposure = metrics.display_exposure(ref, reference.quantity) if needs_exposure else None
    # the ΔE00 map once: its statistics, compare-image's error map and its --fail-percent
    de = metrics.delta_e2000(img, ref, exposure=exposure, full=True)[1] if with_de and colour else None
    values = metrics.image_metrics(img, ref, exposure=exposure, quantity=reference.quantity,
                                   with_flip=with_flip if every else "flip_mean" in keys, delta_e_map=de,
                                   keys=None if every else keys)
    noise = None
    if with_noise:
        noise_note = noise_note or _noise_gap(reference, spp)
        if noise_note is None:
            noise = stats.noise_yardsticks(img, reference, spp, exposure=exposure)
    else:
        noise_note = None
    regions = _regions(img, reference, spp, masks, variance, None if every else keys)
    return Score(values, noise, noise_note, regions, de)


def _noise_gap(reference: "Reference", spp: int | None) -> str | None:
    if reference.variance is None or reference.noise is None:
        return "no reference variance"
    if spp is None:
        return "no spp"
    return None


def _regions(img: np.ndarray, reference: "Reference", spp: int | None, masks: Mapping[str, np.ndarray] | None,
             variance: np.ndarray | None, keys: frozenset[str] | None) -> dict:
    """The regions' metrics: every region's every metric, or those ``keys`` name (``region.<r>.<m>``)."""
    if not masks:
        return {}
    if keys is None:
        return named_regions.region_metrics(img, reference, masks, spp=spp, variance=variance)
    wanted: dict[str, set[str]] = {}
    for key in keys:
        if (parts := region_metric(key)) is not None:
            if parts[0] not in masks:
                raise KeyError(f"no mask for region {parts[0]!r}")
            wanted.setdefault(parts[0], set()).add(parts[1])
    # Region by region, in the scene's order: one region's ΔE costs nothing for a metric that needs none.
    out = {}
    for region in (r for r in masks if r in wanted):
        out.update(named_regions.region_metrics(img, reference, {region: masks[region]}, spp=spp,
                                                variance=variance, keys=wanted[region]))
    return out


def every_region_key(masks: Mapping[str, np.ndarray]) -> list[str]:
    """``region.<region>.<metric>`` for every region of ``masks`` and every region metric."""
    return [f"{named_regions.REGION_PREFIX}{r}.{m}" for r in masks for m in REGION_METRICS[1:]]


def metric_value(image: np.ndarray, reference: "Reference", spp: int, metric: str,
                 masks: Mapping[str, np.ndarray] | None = None) -> float:
    """One metric of one image at ``spp`` (image-wide, or ``region.<region>.<metric>`` with its mask in
    ``masks``): :func:`score_image` with that key, so the same number a run's row holds for that image.

    What the gate's slope, consistency and bias-limit checks score at every checkpoint, at the cost of
    that metric alone. KeyError for a region without a mask, or a metric that is not scored.
    """
    if (parts := region_metric(metric)) is not None and (not masks or parts[0] not in masks):
        raise KeyError(f"no mask for region {parts[0]!r}")
    value = score_image(image, reference, spp, masks=masks, keys=(metric,)).value(metric)
    if value is None:
        raise KeyError(metric)
    return value
