"""Pass/warn/fail thresholds on an image's scores (``cbox compare-image --fail/--warn/--fail-percent``).

Modelled on OpenImageIO's ``idiff``: ``-fail A`` / ``-warn A`` bound the
per-pixel error, ``-failpercent P`` lets up to P% of the pixels exceed it.
Here a threshold names any per-image metric of the registry
(:mod:`cornell_harness.evaluate.registry`), or a scene region's metric
``region.<region>.<metric>``, and its direction comes from the registry: a
metric where higher is better (PSNR, SSIM) fails below its value, a signed
one (``mean_radiance_rel_error``, the z-score) fails when its magnitude is
above, every other one when it is above. The pixel criterion counts the
pixels whose CIEDE2000 (at the reference's display exposure, the ΔE map of
the report) is above ``--pixel-threshold``; an image without colour (ambient
occlusion) has no ΔE00, and its pixels are counted by the absolute
difference of their one value.

Pure functions on numbers: the workflow computes the scores, the CLI turns
the verdict into an exit code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cornell_harness.evaluate.registry import (HIGHER_IS_BETTER, IMAGE_METRICS, METRICS, REGION_CHECK_METRICS,
                                               bound_problem, region_metric)
from cornell_harness.suggest import did_you_mean

#: The levels of a threshold, the worse first.
LEVELS = ("fail", "warn")
#: What ``--fail-percent`` counts per pixel: a radiance image's ΔE00; an image without colour (ambient
#: occlusion, one value per pixel) has none, and its pixels are counted by the absolute difference of that value.
PIXEL_METRIC = "ΔE00"
GREY_PIXEL_METRIC = "|Δ|"


class ThresholdError(ValueError):
    """A threshold that cannot be parsed or names no metric: bad input (exit 2)."""


@dataclass(frozen=True)
class Threshold:
    metric: str  # a registry key, or region.<region>.<metric>
    value: float
    level: str  # "fail" or "warn"

    @property
    def direction(self) -> str:
        """"min" (fails below), "abs_max" (fails when |value| is above) or "max" (fails above)."""
        metric = (region_metric(self.metric) or (None, self.metric))[1]
        if metric in HIGHER_IS_BETTER:
            return "min"
        return "abs_max" if METRICS.get(metric) is None or METRICS[metric].better is None else "max"

    def exceeded(self, value: float | None) -> bool:
        """Whether ``value`` breaks the threshold; a missing or NaN value does (it cannot be shown to pass)."""
        if value is None or math.isnan(value):
            return True
        if self.direction == "min":
            return value < self.value
        return (abs(value) if self.direction == "abs_max" else value) > self.value

    def line(self, label: str, value: float | None) -> str:
        """``LABEL: delta_e2000_mean = 5.126 > 0.1 (--fail)``: what a broken threshold prints."""
        shown = "n/a" if value is None or math.isnan(value) else f"{value:.6g}"
        if self.direction == "abs_max":
            return f"{label}: |{self.metric}| = {shown if value is None else f'{abs(value):.6g}'} > {self.value:g} " \
                   f"(--{self.level})"
        return f"{label}: {self.metric} = {shown} {'<' if self.direction == 'min' else '>'} {self.value:g} " \
               f"(--{self.level})"


def parse_threshold(text: str, level: str) -> Threshold:
    """``METRIC=VALUE`` → a Threshold; an unknown metric is refused with the closest known name."""
    name, sep, number = str(text).partition("=")
    name = name.strip()
    if not sep or not name:
        raise ThresholdError(f"{text!r}: expected METRIC=VALUE, e.g. delta_e2000_mean=1")
    try:
        value = float(number)
    except ValueError:
        raise ThresholdError(f"{text!r}: {number!r} is not a number") from None
    if not math.isfinite(value):
        raise ThresholdError(f"{text!r}: the value must be finite")
    parts = region_metric(name)
    if parts is not None:
        region, metric = parts
        if not region or metric not in REGION_CHECK_METRICS:
            raise ThresholdError(f"{text!r}: expected region.<region>.<metric> with <metric> one of "
                                 f"{', '.join(REGION_CHECK_METRICS)}{did_you_mean(metric, REGION_CHECK_METRICS)}")
        return _in_range(Threshold(name, value, level), text)
    known = {m.casefold(): m for m in IMAGE_METRICS}
    if name.casefold() not in known:
        raise ThresholdError(f"{text!r}: unknown metric {name!r}{did_you_mean(name, IMAGE_METRICS)}; "
                             f"metrics: {', '.join(IMAGE_METRICS)}")
    return _in_range(Threshold(known[name.casefold()], value, level), text)


def _in_range(threshold: Threshold, text: str) -> Threshold:
    """``threshold``, or a ThresholdError when its value is outside what its metric can be (a negative ΔE00, an
    SSIM above 1): such a threshold fails every image, or none."""
    if problem := bound_problem(threshold.metric, threshold.value, threshold.direction):
        raise ThresholdError(f"{text!r}: {problem}")
    return threshold


def fraction_above(per_pixel: np.ndarray, threshold: float) -> float:
    """The fraction of pixels whose error is above ``threshold`` (a NaN error counts as above)."""
    errors = np.asarray(per_pixel, dtype=np.float64).ravel()
    if errors.size == 0:
        raise ValueError("no pixels")
    return float(np.count_nonzero(~(errors <= threshold)) / errors.size)


def percent_line(label: str, percent: float, limit: float, pixel_threshold: float,
                 pixel_metric: str = PIXEL_METRIC) -> str:
    """``LABEL: 12.3% of the pixels have ΔE00 > 2 (--fail-percent 5)``."""
    return (f"{label}: {percent:.4g}% of the pixels have {pixel_metric} > {pixel_threshold:g} "
            f"(--fail-percent {limit:g})")


def broken(thresholds, row: dict) -> list[Threshold]:
    """The thresholds ``row`` (a flat score, :meth:`ImageScore.row`) breaks, fails first."""
    out = [t for t in thresholds if t.exceeded(row.get(t.metric))]
    return sorted(out, key=lambda t: LEVELS.index(t.level))
