"""Derived figures of convergence experiments: slopes, time to a target, efficiency, bias and variance.

Pure functions on the tidy results table (one row per renderer, seed and
spp; see :mod:`cornell_harness.workflows.converge`) and on images.

- **Convergence slope**: least-squares slope of log(error) against log(spp)
  or log(time), fitted per seed; reported as the mean over seeds with a 95%
  Student-t confidence half-width. An unbiased Monte Carlo estimator has
  RMSE ∝ spp^(-1/2) (e.g. Veach 1997, §2.4), so its slope is -0.5; a biased
  one flattens towards 0 once its bias dominates.
- **Time to target**: the wall time at which an error first drops to a
  target, interpolated log-log between the two checkpoints around it; the
  median over seeds; NaN if no seed reaches it.
- **Efficiency**: 1 / (MSE · time), the usual figure of merit of Monte Carlo
  estimators (Veach 1997 §2.4; Pharr et al., pbrt-v4 §2.1.4): doubling the
  time halves an unbiased estimator's MSE, leaving it unchanged.
- **Bias² and variance over K seeds** of the final images: the per-pixel
  variance between seeds, s², estimates one render's variance; the mean
  image's squared error against the reference, minus s²/K (the mean's own
  noise) and minus the reference's variance, estimates the squared bias.
  Both are averaged over pixels and channels. A consistent-but-biased method
  (photon mapping, probes) shows bias² that no spp removes; a noisy unbiased
  one shows bias² ≈ 0. :func:`region_bias_variance` gives the same split
  inside each named region (:mod:`cornell_harness.evaluate.regions`): a photon
  map's bias sits in its caustics and shadow edges, where an image-wide
  mean dilutes it.
- **Uncertainty**: every time-derived figure comes with a 95% interval over
  seeds and timing repeats (:func:`figure_interval`, the method in
  :mod:`cornell_harness.evaluate.bootstrap`); bias², variance and the bias share
  with one over the pixels (:func:`_split`). Times are read from a
  ``time_column``: ``time_s`` (wall) or ``cpu_time_s`` (``--time-basis cpu``).
"""

from __future__ import annotations

import math
import re
import warnings
from typing import NamedTuple

import numpy as np
import pandas as pd
from scipy import stats as _st

from cornell_harness.evaluate import bootstrap
from cornell_harness.evaluate.registry import IMAGE_METRICS, REGION_CHECK_METRICS, bound_problem, region_metric
from cornell_harness.suggest import closest

#: Targets of ``time_to_*`` columns by default: (metric, value).
DEFAULT_TARGETS = (("delta_e2000_mean", 2.0), ("delta_e2000_mean", 1.0), ("rel_mse", 1e-2), ("rel_mse", 1e-3))


def loglog_slope(x, y) -> float:
    """Slope of log(y) against log(x) by least squares; NaN with fewer than 2 usable points."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    ok = (x > 0) & (y > 0) & np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 2 or np.ptp(np.log(x[ok])) == 0:
        return math.nan
    return float(np.polyfit(np.log(x[ok]), np.log(y[ok]), 1)[0])


def mean_ci(values, level: float = 0.95) -> tuple[float, float]:
    """Mean and Student-t confidence half-width (NaN half-width for a single value)."""
    v = np.asarray([x for x in values if np.isfinite(x)], float)
    if v.size == 0:
        return math.nan, math.nan
    if v.size == 1:
        return float(v[0]), math.nan
    half = _st.t.ppf(0.5 + level / 2, v.size - 1) * v.std(ddof=1) / math.sqrt(v.size)
    return float(v.mean()), float(half)


def slope_over_seeds(runs: pd.DataFrame, metric: str = "rmse", x: str = "spp") -> tuple[float, float]:
    """Mean log-log slope of ``metric`` against ``x`` (``spp`` or a time column) over seeds, and its 95% CI
    half-width over seeds; NaN when ``x`` is absent."""
    if x not in runs:
        return math.nan, math.nan
    per_seed = [loglog_slope(g[x], g[metric]) for _, g in runs.groupby("seed")]
    return mean_ci(per_seed)


def time_to_target(runs: pd.DataFrame, metric: str, target: float, time_column: str = "time_s") -> float:
    """Median over seeds of the time (``time_column``) at which ``metric`` first reaches ``target`` (≤); NaN if
    never or without that column."""
    values = [_time_to(c.t, c.frame[metric].to_numpy(float), target) for c in _curves(runs, time_column)]
    return _aggregate(np.nanmedian, values)


def efficiency(runs: pd.DataFrame, time_column: str = "time_s") -> float:
    """Median over seeds of 1 / (MSE · time) at each seed's highest spp; NaN without ``time_column``."""
    values = [_efficiency(c.t, c.frame["mse"].to_numpy(float), c.frame["spp"].to_numpy(float))
              for c in _curves(runs, time_column)]
    return _aggregate(np.nanmedian, values)


class _Curve(NamedTuple):
    """One seed's rows, in time order: the rows, their times and each row's timing repeats."""

    frame: pd.DataFrame
    t: np.ndarray
    samples: list[np.ndarray]


def _curves(runs: pd.DataFrame, time_column: str) -> list[_Curve]:
    out = []
    for _, g in runs.groupby("seed", sort=True):
        if time_column not in g:
            t = np.full(len(g), math.nan)
        else:
            g = g.assign(_t=pd.to_numeric(g[time_column], errors="coerce")).sort_values("_t", kind="stable")
            t = g["_t"].to_numpy(float)
        col = bootstrap.samples_column(time_column)
        texts = g[col].tolist() if col in g else [None] * len(g)
        out.append(_Curve(g, t, [bootstrap.parse_samples(x, ti) for x, ti in zip(texts, t)]))
    return out


def _aggregate(fn, values) -> float:
    v = np.asarray(values, float)
    return float(fn(v)) if np.isfinite(v).any() else math.nan


def _time_to(t: np.ndarray, e: np.ndarray, target: float) -> np.ndarray:
    """Per seed (``t``: (..., rows) times, ``e``: (rows,) errors in time order): when ``e`` first reaches
    ``target``, interpolated log-log between the last miss and the first hit; NaN if never."""
    t = np.asarray(t, float)
    hit = np.flatnonzero(e <= target)
    if hit.size == 0:
        return np.full(t.shape[:-1], math.nan)
    k = hit[0]
    if k == 0 or not (e[k - 1] > 0 and e[k] > 0):
        return t[..., k]
    f = (math.log(target) - math.log(e[k - 1])) / (math.log(e[k]) - math.log(e[k - 1]))
    with np.errstate(divide="ignore", invalid="ignore"):
        lo, hi = np.log(t[..., k - 1]), np.log(t[..., k])
        return np.where(t[..., k - 1] > 0, np.exp(lo + f * (hi - lo)), t[..., k])


def _efficiency(t: np.ndarray, mse: np.ndarray, spp: np.ndarray) -> np.ndarray:
    """Per seed: 1 / (MSE · time) at its highest spp (the median where it has several rows there)."""
    top = spp == spp.max()
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.median(1.0 / (mse[top] * np.asarray(t, float)[..., top]), axis=-1)


def _slope(t: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Per seed: least-squares slope of log(e) against log(t) (:func:`loglog_slope`, over (..., rows) times)."""
    t = np.asarray(t, float)
    ok = (e > 0) & np.isfinite(e) & np.all((t > 0) & np.isfinite(t), axis=tuple(range(t.ndim - 1)))
    if ok.sum() < 2:
        return np.full(t.shape[:-1], math.nan)
    x, y = np.log(t[..., ok]), np.log(e[ok])
    dx = x - x.mean(axis=-1, keepdims=True)
    sxx = (dx**2).sum(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(sxx > 0, (dx * (y - y.mean())).sum(axis=-1) / sxx, math.nan)


def figure_interval(curves: list[_Curve], per_seed, aggregate, log: bool = True) -> tuple[float, float, float]:
    """(value, low, high) of a time-derived figure: ``aggregate`` over seeds of ``per_seed(curve, times)``,
    with its 95% interval over seeds and timing repeats (:func:`cornell_harness.evaluate.bootstrap.interval`)."""
    values = np.array([per_seed(c, c.t) for c in curves], float)
    point = _aggregate(aggregate, values)
    repeats = max((s.size for c in curves for s in c.samples), default=1)
    gen = bootstrap.rng()
    timing = None
    if repeats >= 2:
        timing = np.stack([per_seed(c, bootstrap.resampled_times(c.samples, bootstrap.RESAMPLES, gen))
                           for c in curves], axis=1)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN resamples: their figure is NaN
        lo, hi = bootstrap.interval(point, values, timing, aggregate, repeats, log, gen)
    return point, lo, hi


def target_column(metric: str, target: float) -> str:
    """Column name of a time-to-target figure, e.g. ``time_to_delta_e2000_mean_le_1``."""
    return f"time_to_{metric}_le_{target:g}"


def parse_target(text: str) -> tuple[str, float]:
    """``"delta_e2000_mean=1"``, ``"rel_mse<=1e-3"``, ``"region.caustic.rel_mse=0.01"`` or ``"1"`` (ΔE mean)
    → (metric, value).

    The metric must be an error of one image (:data:`cornell_harness.evaluate.registry.IMAGE_METRICS`) or
    a region's (``region.<region>.<metric>``, ``<metric>`` in ``REGION_CHECK_METRICS``); whether the
    scene names that region is the caller's to check (:func:`unknown_target_regions`).
    """
    m = re.fullmatch(r"\s*(?:([A-Za-z0-9_.\-]+)\s*(?:<=|=)\s*)?([-+0-9.eE]+)\s*", text)
    if not m:
        raise ValueError(f"target error {text!r}: expected METRIC=VALUE (e.g. delta_e2000_mean=1 or "
                         "region.caustic.rel_mse=0.01) or a number")
    metric = m.group(1) or "delta_e2000_mean"
    parts = region_metric(metric)
    known = IMAGE_METRICS if parts is None else REGION_CHECK_METRICS
    if (parts[1] if parts else metric) not in known or (parts is not None and not parts[0]):
        hint = closest(parts[1] if parts else metric, known)
        if parts and hint:
            hint = f"region.{parts[0] or '<region>'}.{hint}"
        raise ValueError(f"target error {text!r}: unknown metric {metric!r}"
                         + (f" (did you mean {hint!r}?)" if hint and hint != metric else "")
                         + f"; use one of {', '.join(known)}"
                         + ("" if parts else ", or region.<region>.<metric>"))
    try:
        value = float(m.group(2))
    except ValueError:
        raise ValueError(f"target error {text!r}: {m.group(2)!r} is not a number") from None
    if not math.isfinite(value):
        raise ValueError(f"target error {text!r}: the value must be finite")
    # A target is reached once the error is at most it: an upper bound, refused outside the metric's range.
    if problem := bound_problem(metric, value, "max"):
        raise ValueError(f"target error {text!r}: {problem}")
    return metric, value


def unknown_target_regions(targets, regions) -> list[str]:
    """The regions that ``targets`` name and a scene with ``regions`` does not declare."""
    return sorted({p[0] for metric, _ in targets if (p := region_metric(metric)) and p[0] not in regions})


def bias_variance(images: list[np.ndarray], ref: np.ndarray, ref_var: np.ndarray,
                  deterministic: bool = False) -> dict:
    """Squared bias and variance (means over pixels and channels) from K seeds' images.

    Needs K ≥ 2, or one image of a ``deterministic`` renderer (variance 0).
    """
    maps = _bias_variance_maps(images, ref, ref_var, deterministic)
    return _NAN_SPLIT.copy() if maps is None else _split(*maps)


_NAN_SPLIT = {k: math.nan for k in ("bias2", "variance", "bias2_fraction", "bias2_low", "bias2_high",
                                    "variance_low", "variance_high", "bias2_fraction_low", "bias2_fraction_high")}


def _bias_variance_maps(images, ref, ref_var, deterministic: bool) -> tuple[np.ndarray, np.ndarray] | None:
    """Per pixel and channel: the bias² estimate and the between-seed variance s²; None with too few images."""
    if images is None or len(images) == 0:
        return None
    stack = np.stack([np.asarray(i, np.float64) for i in images])
    k = stack.shape[0]
    if deterministic:
        s2 = np.zeros_like(stack[0])
    elif k < 2:
        return None
    else:
        s2 = stack.var(axis=0, ddof=1)
    err2 = (stack.mean(axis=0) - np.asarray(ref, np.float64)) ** 2
    return err2 - s2 / k - np.asarray(ref_var, np.float64), s2


def _split(bias2_map: np.ndarray, s2_map: np.ndarray, level: float = 0.95) -> dict:
    """Means of the per-pixel maps (over the pixels given) as bias², variance and bias²'s share, with intervals.

    The intervals treat the pixels as the samples of the estimate (each pixel's channels averaged into one:
    they share a path): bias² ± z · sd(per-pixel bias² estimate) / √pixels, likewise the variance. With 2
    seeds a bootstrap over seeds has one degree of freedom and says nothing; the pixels are many and the
    seeds' noise in each is independent of its neighbours' (a reconstruction filter wider than a pixel
    would correlate them and make this interval too narrow). Pixel-to-pixel variation of a real bias counts
    as spread too, so a bias confined to a few pixels needs more evidence: conservative. The share's
    interval takes bias²'s bounds (floored at 0) against the variance's opposite bounds.
    A bias² whose interval reaches 0 (``bias2_fraction_low`` = 0) is not significant: :func:`bias_significant`.
    """
    if bias2_map.size == 0:
        return _NAN_SPLIT.copy()
    per_pixel_b = _per_pixel(bias2_map)
    per_pixel_v = _per_pixel(s2_map)
    bias2, variance = float(np.mean(per_pixel_b)), float(np.mean(per_pixel_v))
    z = float(_st.norm.ppf(0.5 + level / 2))
    n = per_pixel_b.size
    hb = z * float(per_pixel_b.std(ddof=1)) / math.sqrt(n) if n > 1 else math.nan
    hv = z * float(per_pixel_v.std(ddof=1)) / math.sqrt(n) if n > 1 else math.nan
    out = {"bias2": bias2, "variance": variance, "bias2_fraction": _share(bias2, variance),
           "bias2_low": bias2 - hb, "bias2_high": bias2 + hb,
           "variance_low": max(variance - hv, 0.0), "variance_high": variance + hv}
    out["bias2_fraction_low"] = _share(out["bias2_low"], out["variance_high"])
    out["bias2_fraction_high"] = _share(out["bias2_high"], out["variance_low"])
    return out


def bias_significant(fraction_low) -> bool | None:
    """Whether a bias share's interval excludes 0 (from its ``bias2_fraction_low``); None when unknown."""
    try:
        low = float(fraction_low)
    except (TypeError, ValueError):
        return None
    return None if math.isnan(low) else low > 0


def _per_pixel(m: np.ndarray) -> np.ndarray:
    m = np.asarray(m, np.float64)
    return m.reshape(-1, m.shape[-1]).mean(axis=1) if m.ndim >= 2 else m.ravel()


def _share(bias2: float, variance: float) -> float:
    """bias² / (bias² + variance), bias² floored at 0; NaN when both are 0 or unknown."""
    if not (math.isfinite(bias2) and math.isfinite(variance)):
        return math.nan
    denom = max(bias2, 0.0) + variance
    return max(bias2, 0.0) / denom if denom > 0 else math.nan


def region_bias_variance(images, ref: np.ndarray, ref_var: np.ndarray, masks: dict[str, np.ndarray],
                         deterministic: bool = False) -> dict[str, dict]:
    """:func:`bias_variance` inside each region: {region: {bias2, variance, bias2_fraction}}.

    ``images`` are K seeds' final images (a list, or stacked (K, H, W, 3));
    ``masks`` are (H, W) booleans, e.g. :func:`cornell_harness.evaluate.regions.region_masks`.
    The estimators are the image-wide ones, averaged over the region's pixels
    and channels; an empty region, or too few images, gives NaN.
    """
    maps = _bias_variance_maps(images, ref, ref_var, deterministic)
    if maps is None:
        return {name: _NAN_SPLIT.copy() for name in masks}
    bias2_map, s2_map = maps
    return {name: _split(bias2_map[np.asarray(m, bool)], s2_map[np.asarray(m, bool)]) for name, m in masks.items()}


def summarize(runs: pd.DataFrame, targets=DEFAULT_TARGETS, time_column: str = "time_s") -> pd.DataFrame:
    """One row per renderer: slopes, time to each target, efficiency at max spp, each with its 95% interval.

    Times are read from ``time_column`` (``time_s``, wall, or ``cpu_time_s``); a column that is absent or all
    NaN gives NaN figures. Every time-derived figure ``F`` has ``F_low`` / ``F_high``, its interval over seeds
    and timing repeats (:mod:`cornell_harness.evaluate.bootstrap`); ``interval_basis`` says which of the two the
    rows allowed. ``slope_rmse_spp_ci`` / ``slope_rmse_time_ci`` keep the Student-t half-width over seeds.
    """
    rows = []
    ok = runs[runs["status"] == "ok"]
    for renderer, g in ok.groupby("renderer", sort=False):
        curves = _curves(g, time_column)
        repeats = max((s.size for c in curves for s in c.samples), default=1)
        row = {"renderer": renderer, "seeds": int(g["seed"].nunique()), "max_spp": int(g["spp"].max()),
               "time_column": time_column, "time_repeats": repeats,
               "interval_basis": bootstrap.basis(len(curves), repeats)}
        row["slope_rmse_spp"], row["slope_rmse_spp_ci"] = slope_over_seeds(g, "rmse", "spp")
        row["slope_rmse_spp_low"] = row["slope_rmse_spp"] - row["slope_rmse_spp_ci"]
        row["slope_rmse_spp_high"] = row["slope_rmse_spp"] + row["slope_rmse_spp_ci"]
        _, row["slope_rmse_time_ci"] = slope_over_seeds(g, "rmse", time_column)
        row["slope_rmse_time"], row["slope_rmse_time_low"], row["slope_rmse_time_high"] = figure_interval(
            curves, lambda c, t: _slope(t, c.frame["rmse"].to_numpy(float)), np.nanmean, log=False)
        for metric, value in targets:
            if metric in g:  # an AO image's rows have no colour differences, so no ΔE target
                col = target_column(metric, value)
                row[col], row[col + "_low"], row[col + "_high"] = figure_interval(
                    curves, lambda c, t, m=metric, v=value: _time_to(t, c.frame[m].to_numpy(float), v), np.nanmedian)
        row["efficiency"], row["efficiency_low"], row["efficiency_high"] = figure_interval(
            curves, lambda c, t: _efficiency(t, c.frame["mse"].to_numpy(float), c.frame["spp"].to_numpy(float)),
            np.nanmedian)
        # The time of the highest spp (equal quality: what reaching the target cost) and, in equal-time mode, the
        # spp the budget buys at the measured speed.
        row["time_at_max_spp"], row["time_at_max_spp_low"], row["time_at_max_spp_high"] = figure_interval(
            curves, lambda c, t: _at_top(t, c.frame["spp"].to_numpy(float)), np.nanmedian)
        if "info_time_budget_s" in g:
            budget = float(pd.to_numeric(g["info_time_budget_s"], errors="coerce").max())
            row["spp_in_budget"], row["spp_in_budget_low"], row["spp_in_budget_high"] = figure_interval(
                curves, lambda c, t: _spp_in(budget, t, c.frame["spp"].to_numpy(float)), np.nanmedian)
        rows.append(row)
    return pd.DataFrame(rows)


def _at_top(t: np.ndarray, spp: np.ndarray) -> np.ndarray:
    return np.median(np.asarray(t, float)[..., spp == spp.max()], axis=-1)


def _spp_in(budget: float, t: np.ndarray, spp: np.ndarray) -> np.ndarray:
    """The spp ``budget`` seconds buy at the speed of the highest-spp render (samples per second × budget)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return budget * spp.max() / _at_top(t, spp)
