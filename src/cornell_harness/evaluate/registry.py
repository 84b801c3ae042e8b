"""The metric registry: every column a run can carry, with its label, definition and direction.

One table for the whole harness. The gate reads the direction (a budget or a
baseline on a metric where higher is better is a floor, not a ceiling) and
refuses names that are not here; the report takes its labels, tooltips and
chart axes from it; the CLI prints its table columns from it. A metric that
:func:`cornell_harness.evaluate.metrics.image_metrics` or
:func:`cornell_harness.evaluate.noise.noise_yardsticks` computes must be listed here.

Region metrics (:mod:`cornell_harness.evaluate.regions`) are named here too, by their
column form ``region.<region>.<metric>`` (:func:`region_metric`): the gate
validates them without importing the mask code, which pulls in SciPy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable

#: The values a metric can take (:attr:`Metric.values`): any, an error's (0 and up), a fraction's.
ANY = (-math.inf, math.inf)
NON_NEGATIVE = (0.0, math.inf)
UNIT = (0.0, 1.0)


@dataclass(frozen=True)
class Metric:
    """``better`` is "low", "high" or None (a signed or descriptive figure); ``guide_slope`` is
    the log-log slope against spp an unbiased renderer shows (None: not a convergence metric)."""

    key: str
    label: str
    definition: str
    better: str | None = None
    axis_label: str | None = None
    guide_slope: float | None = None
    per_image: bool = False  # computed from one image against the reference (a gate may budget it)
    colour: bool = False  # radiance images only (a colour difference, HDR-FLIP); an AO image is one scalar
    cheap: bool = False  # a per-image metric of a few passes over the pixels: a check computes it unasked
    values: tuple[float, float] = ANY  # the closed range it lies in: a threshold outside it is meaningless
    citation: str = ""  # the published source of its definition; "" for a plain count, mean or bookkeeping column
    temporal: bool = False  # a figure of a whole sequence against its per-frame references (a gate may budget it)
    infinite: str = ""  # what a value of inf says, where it is a verdict rather than an overflow


def _m(key, label, definition, better=None, axis=None, slope=None, per_image=True, colour=False,
       cheap=False, values=NON_NEGATIVE, cite="", temporal=False, infinite="") -> Metric:
    return Metric(key, label, definition, better, axis, slope, per_image, colour, cheap, values, cite, temporal,
                  infinite)


#: Sources cited by several metrics.
_VEACH = "Veach 1997, \"Robust Monte Carlo Methods for Light Transport Simulation\" (PhD thesis), §2.4"
_ROUSSELLE = "Rousselle, Knaus and Zwicker 2011 (SIGGRAPH Asia): relMSE with ε = 0.01"
_DISPLAY = "display encoding: Reinhard et al. 2002 (exposure), IEC 61966-2-1 (sRGB)"
_SSIM = ("Wang, Bovik, Sheikh and Simoncelli 2004, \"Image quality assessment: from error visibility to "
         "structural similarity\"")
_JND = "Sharma 2003, \"Digital Color Imaging Handbook\"; Mahy et al. 1994: ΔE₀₀ 2.3 is just noticeable"
_FLIP = ("Andersson, Nilsson, Shirley and Akenine-Möller 2021, \"Visualizing Errors in Rendered High Dynamic "
         "Range Images\"")
_CIEDE2000 = ("Sharma, Wu and Dalal 2005, \"The CIEDE2000 color-difference formula: implementation notes, "
              "supplementary test data, and mathematical observations\"")


_TABLE = (
    _m("renderer", "renderer", "renderer name, with settings that differ from its defaults", per_image=False,
       values=ANY),
    _m("status", "status", "ok, skipped, unavailable or failed", per_image=False, values=ANY),
    _m("version", "version", "renderer version", per_image=False, values=ANY),
    _m("estimator", "estimator", "what the renderer's image estimates: unbiased, consistent (biased, error → 0 "
       "as the budget grows) or biased (does not converge to the reference)", per_image=False, values=ANY),
    _m("spp", "spp", "samples per pixel of the row (the highest reached)", per_image=False),
    _m("seeds", "seeds", "number of seeds (independent runs) the medians are over", per_image=False),
    _m("time_s", "time (s)", "wall time to reach this spp (median over seeds)", "low", per_image=False),
    _m("rmse", "RMSE", "root-mean-square error on linear radiance", "low", "RMSE (linear radiance)", -0.5,
       cheap=True, cite=_VEACH),
    _m("mse", "MSE", "mean squared error on linear radiance", "low", "MSE", -1.0, cheap=True, cite=_VEACH),
    _m("rel_mse", "relMSE", "mean of (img−ref)²/(ref²+0.01) on linear radiance", "low", "relMSE", -1.0,
       cheap=True, cite=_ROUSSELLE),
    _m("rel_mse_trimmed", "relMSE trim.", "relMSE without the worst pixels (fireflies)", "low",
       "relMSE (trimmed)", -1.0, cite=_ROUSSELLE),
    _m("psnr", "PSNR (dB)", "PSNR of the display-encoded images", "high", cite=_DISPLAY),
    _m("ssim", "SSIM", "mean SSIM of the display-encoded images", "high", values=(-1.0, 1.0), cite=_SSIM),
    _m("delta_e2000_mean", "ΔE mean", "mean CIEDE2000", "low", "mean ΔE₀₀", -0.5, colour=True,
       cite=_CIEDE2000),
    _m("delta_e2000_p95", "ΔE p95", "95th percentile of CIEDE2000", "low", "ΔE₀₀ 95th percentile", -0.5,
       colour=True, cite=_CIEDE2000),
    _m("delta_e2000_max", "ΔE max", "maximum CIEDE2000", "low", colour=True, cite=_CIEDE2000),
    _m("delta_e2000_frac_gt_2_3", "ΔE > 2.3", "fraction of pixels above the just-noticeable difference", "low",
       colour=True, values=UNIT, cite=_JND),
    # Radiance only: HDR-FLIP re-exposes the image over a range of stops from the reference; an AO image
    # is a fraction shown as it is (exposure 1), which those exposures would brighten.
    _m("flip_mean", "FLIP mean", "mean HDR-FLIP on linear radiance (Andersson et al. 2021): how visible the "
       "difference is when flipping between the images, worst over exposures from the reference's brightest "
       "to its median pixel; 0 none, 1 the largest", "low", "mean HDR-FLIP", colour=True, values=UNIT,
       cite=_FLIP),
    _m("mean_radiance_r", "mean R", "mean radiance of the red channel (broken pixels skipped)", cheap=True,
       values=ANY),
    _m("mean_radiance_g", "mean G", "mean radiance of the green channel (broken pixels skipped)", cheap=True,
       values=ANY),
    _m("mean_radiance_b", "mean B", "mean radiance of the blue channel (broken pixels skipped)", cheap=True,
       values=ANY),
    _m("mean_radiance_rel_error", "mean rad. err", "relative error of the image's mean radiance", cheap=True,
       values=ANY),
    _m("nan_count", "NaN px", "pixels with a NaN channel", "low", cheap=True),
    _m("inf_count", "Inf px", "pixels with an infinite channel", "low", cheap=True),
    _m("negative_count", "neg px", "pixels with a negative channel", "low", cheap=True),
    _m("noise_rmse", "RMSE (noise)", "expected RMSE from sampling noise alone at this spp"),
    _m("noise_delta_e2000_mean", "ΔE mean (noise)", "ΔE mean of a simulated noise-only image at this spp",
       colour=True),
    _m("noise_mean_radiance_z", "mean rad. z",
       "z-score of the mean-radiance difference given the noise; |z| > 3 points at bias", values=ANY),
    _m("efficiency", "efficiency", "1/(MSE·time) at the highest spp: higher is better; unchanged by more time "
       "for an unbiased renderer", "high", per_image=False,
       cite=_VEACH + "; Pharr, Jakob and Humphreys 2023, pbrt-v4, §2.1.4"),
    _m("slope_rmse_spp", "slope RMSE/spp", "log-log slope of RMSE against spp, mean over seeds ± 95% CI; "
       "−0.5 for an unbiased renderer, towards 0 once bias dominates", per_image=False, values=ANY, cite=_VEACH),
    _m("slope_rmse_time", "slope RMSE/time", "log-log slope of RMSE against wall time, mean over seeds ± 95% CI",
       per_image=False, values=ANY, cite=_VEACH),
    _m("bias2", "bias²", "squared bias, mean over pixels and channels (from several seeds' images)", "low",
       per_image=False),
    _m("variance", "variance", "between-seed variance, mean over pixels and channels", "low", per_image=False),
    _m("bias2_fraction", "bias share", "bias² / (bias² + variance)", per_image=False, values=UNIT),
    # A sequence (cbox sequence): its frames' rows carry every per-image metric and their frame; a sequence's row
    # the temporal figures (cornell_harness.evaluate.temporal) and the mean over frames of each per-image metric.
    _m("frame", "frame", "the frame of an animated scene a row is of (0 first)", per_image=False),
    _m("flicker", "flicker", "RMS of the frame-to-frame change of the error image (linear radiance): noise "
       "that is not held from frame to frame, and jumps; compare with flicker_floor", "low", "flicker (RMS)",
       per_image=False, temporal=True),
    _m("flicker_floor", "flicker floor", "the flicker of two independent reference-quality sequences, from the "
       "reference's per-frame variance: sqrt(mean 2·(V_i + V_i−1)); a renderer's flicker cannot go below it",
       per_image=False),
    _m("lag", "lag (frames)", "frames after the scene's change (a motion ending, a switch) until the per-frame "
       "mean ΔE00 is back in its steady band (mean ± 2 sd of the last third of the frames) for 3 frames; inf when "
       "it did not settle within the sequence (the steady frames still trend, or it never enters the band)", "low",
       "lag (frames)", per_image=False, temporal=True, infinite="not settled within the sequence"),
    _m("ghosting", "ghosting", "RMSE (linear radiance) over the pixels the motion uncovered (the disocclusion "
       "masks of the reference's motion), every frame", "low", "ghosting RMSE", per_image=False, temporal=True),
)

#: Every known column, by key.
METRICS: dict[str, Metric] = {m.key: m for m in _TABLE}
#: Colour differences (CIEDE2000) and HDR-FLIP: computed for radiance images only; an ambient-occlusion image
#: has one value per pixel, so its rows leave them out (RMSE, relMSE, SSIM, PSNR and the means stay).
COLOUR_METRICS = frozenset(k for k, m in METRICS.items() if m.colour)
#: Metrics where larger is better; every other scored metric is an error (smaller is better).
HIGHER_IS_BETTER = frozenset(k for k, m in METRICS.items() if m.better == "high")
#: Metrics of one image against the reference: what a gate budget or baseline may name.
IMAGE_METRICS = tuple(k for k, m in METRICS.items() if m.per_image)
#: Figures of a whole sequence against its per-frame references (:mod:`cornell_harness.evaluate.temporal`): what
#: a gate budget on an animated scene may name besides the per-image metrics (then the mean over frames).
TEMPORAL_METRICS = tuple(k for k, m in METRICS.items() if m.temporal)
#: The per-frame error :data:`TEMPORAL_METRICS`' lag follows: the mean ΔE00, display-encoded and so bounded per
#: pixel. A linear RMSE at the low spp of real-time rendering is dominated by the emitter's aliased edges, whose
#: error is the same in every frame and hides the recovery of the light on the walls.
LAG_METRIC = "delta_e2000_mean"
#: Per-image metrics a check computes unasked (``cbox compare-image`` with thresholds, :func:`check_metrics`): a
#: pass or two over the pixels each, together under a tenth of one ΔE00 map's cost.
CHEAP_METRICS = tuple(k for k, m in METRICS.items() if m.cheap)
#: Metrics the convergence and speed/accuracy charts offer, the default first.
PLOT_METRICS = ("rmse", "delta_e2000_mean", "rel_mse", "rel_mse_trimmed", "mse", "delta_e2000_p95")
assert all(METRICS[k].guide_slope is not None for k in PLOT_METRICS)

#: The metrics of each named region, in table order (computed by :func:`cornell_harness.evaluate.regions.region_metrics`).
REGION_METRICS = ("pixels", "mean_radiance_rel_error", "mean_z", "rmse", "rel_mse", "delta_e2000_mean")
#: Region metrics a gate budget, a consistency check or a time-to-target may name: ``pixels`` is a count,
#: not an error.
REGION_CHECK_METRICS = tuple(m for m in REGION_METRICS if m != "pixels")
#: In a flat row (the results table), region metrics are columns ``region.<name>.<metric>``.
REGION_PREFIX = "region."


def region_metric(key: str) -> tuple[str, str] | None:
    """``"region.caustic.rel_mse"`` → ("caustic", "rel_mse"); None for a key without the prefix.

    The metric is after the last dot (metric keys have none, region names
    may). The parts are not checked against anything: "" or an unknown
    metric come back as they are, for the caller to refuse in its own words.
    """
    if not key.startswith(REGION_PREFIX):
        return None
    region, _, metric = key[len(REGION_PREFIX):].rpartition(".")
    return region, metric


def value_range(key: str, kind: str = "max") -> tuple[float, float]:
    """The values a bound of ``kind`` on metric ``key`` (a registry key, or
    ``region.<region>.<metric>``) can meaningfully take: the metric's :attr:`Metric.values`, or for a bound on
    its magnitude (``abs_max``) 0 up to the largest magnitude; any value for a name the registry does not know.

    ``kind`` is how the bound is broken: by a value above it (``max``), below it (``min``) or a magnitude above
    it (``abs_max``), a gate budget's kinds and a ``--fail``/``--warn`` threshold's directions."""
    metric = (region_metric(key) or (None, key))[1]
    lo, hi = METRICS[metric].values if metric in METRICS else ANY
    return (0.0, max(abs(lo), abs(hi))) if kind == "abs_max" else (lo, hi)


def bound_problem(key: str, value: float, kind: str, what: str = "image") -> str | None:
    """Why a bound ``value`` of ``kind`` on metric ``key`` is meaningless, or None: outside the values the metric
    can take (a negative ΔE00, an SSIM above 1) it passes every ``what`` or fails every one, whatever the
    render. One rule for ``--fail``/``--warn`` and the gate's budgets."""
    lo, hi = value_range(key, kind)
    if lo <= value <= hi:
        return None
    shown = f"|{key}|" if kind == "abs_max" else key
    where = f"at least {lo:g}" if hi == math.inf else f"between {lo:g} and {hi:g}"
    passes = (value < lo) == (kind == "min")
    return f"{shown} is {where}, so {value:g} would {'pass' if passes else 'fail'} every {what}"


def check_metrics(named: Iterable[str]) -> frozenset[str]:
    """What a check that names ``named`` (its thresholds' keys: metrics, or ``region.<region>.<metric>``)
    computes: those and :data:`CHEAP_METRICS`, and not the costly rest (the ΔE00 map, SSIM, PSNR's display
    encoding, HDR-FLIP, the noise yardsticks, the regions), which costs several times what idiff's whole
    comparison does (BENCHMARKS.md, compare-image)."""
    return frozenset(CHEAP_METRICS).union(named)
