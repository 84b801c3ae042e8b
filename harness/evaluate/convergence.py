"""Derived figures of convergence experiments: slopes, time to a target, efficiency, bias and variance.

Pure functions on the tidy results table (one row per renderer, seed and
spp; see :mod:`harness.workflows.converge`) and on images.

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
  inside each named region (:mod:`harness.evaluate.regions`): a photon
  map's bias sits in its caustics and shadow edges, where an image-wide
  mean dilutes it.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd
from scipy import stats as _st

from harness.evaluate.registry import IMAGE_METRICS, REGION_CHECK_METRICS, region_metric
from harness.suggest import closest

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
    """Mean log-log slope of ``metric`` against ``x`` over seeds, and its 95% CI half-width."""
    per_seed = [loglog_slope(g[x], g[metric]) for _, g in runs.groupby("seed")]
    return mean_ci(per_seed)


def time_to_target(runs: pd.DataFrame, metric: str, target: float) -> float:
    """Median over seeds of the time at which ``metric`` first reaches ``target`` (≤); NaN if never."""
    times = []
    for _, g in runs.groupby("seed"):
        g = g.sort_values("time_s")
        t, e = g["time_s"].to_numpy(float), g[metric].to_numpy(float)
        hit = np.flatnonzero(e <= target)
        if hit.size == 0:
            continue
        k = hit[0]
        if k == 0 or not (e[k - 1] > 0 and e[k] > 0 and t[k - 1] > 0):
            times.append(t[k])
            continue
        # Interpolate log-log between the last miss and the first hit.
        f = (math.log(target) - math.log(e[k - 1])) / (math.log(e[k]) - math.log(e[k - 1]))
        times.append(math.exp(math.log(t[k - 1]) + f * (math.log(t[k]) - math.log(t[k - 1]))))
    return float(np.median(times)) if times else math.nan


def target_column(metric: str, target: float) -> str:
    """Column name of a time-to-target figure, e.g. ``time_to_delta_e2000_mean_le_1``."""
    return f"time_to_{metric}_le_{target:g}"


def parse_target(text: str) -> tuple[str, float]:
    """``"delta_e2000_mean=1"``, ``"rel_mse<=1e-3"``, ``"region.caustic.rel_mse=0.01"`` or ``"1"`` (ΔE mean)
    → (metric, value).

    The metric must be an error of one image (:data:`harness.evaluate.registry.IMAGE_METRICS`) or
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


_NAN_SPLIT = {"bias2": math.nan, "variance": math.nan, "bias2_fraction": math.nan}


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


def _split(bias2_map: np.ndarray, s2_map: np.ndarray) -> dict:
    """Means of the per-pixel maps (over the pixels given) as bias², variance and bias²'s share."""
    if bias2_map.size == 0:
        return _NAN_SPLIT.copy()
    bias2, variance = float(np.mean(bias2_map)), float(np.mean(s2_map))
    denom = max(bias2, 0.0) + variance
    return {"bias2": bias2, "variance": variance,
            "bias2_fraction": max(bias2, 0.0) / denom if denom > 0 else math.nan}


def region_bias_variance(images, ref: np.ndarray, ref_var: np.ndarray, masks: dict[str, np.ndarray],
                         deterministic: bool = False) -> dict[str, dict]:
    """:func:`bias_variance` inside each region: {region: {bias2, variance, bias2_fraction}}.

    ``images`` are K seeds' final images (a list, or stacked (K, H, W, 3));
    ``masks`` are (H, W) booleans, e.g. :func:`harness.evaluate.regions.region_masks`.
    The estimators are the image-wide ones, averaged over the region's pixels
    and channels; an empty region, or too few images, gives NaN.
    """
    maps = _bias_variance_maps(images, ref, ref_var, deterministic)
    if maps is None:
        return {name: _NAN_SPLIT.copy() for name in masks}
    bias2_map, s2_map = maps
    return {name: _split(bias2_map[np.asarray(m, bool)], s2_map[np.asarray(m, bool)]) for name, m in masks.items()}


def summarize(runs: pd.DataFrame, targets=DEFAULT_TARGETS) -> pd.DataFrame:
    """One row per renderer: slopes with CIs, time to each target, efficiency at max spp."""
    rows = []
    ok = runs[runs["status"] == "ok"]
    for renderer, g in ok.groupby("renderer", sort=False):
        top = g[g["spp"] == g["spp"].max()]
        row = {"renderer": renderer, "seeds": int(g["seed"].nunique()), "max_spp": int(g["spp"].max())}
        row["slope_rmse_spp"], row["slope_rmse_spp_ci"] = slope_over_seeds(g, "rmse", "spp")
        row["slope_rmse_time"], row["slope_rmse_time_ci"] = slope_over_seeds(g, "rmse", "time_s")
        for metric, value in targets:
            if metric in g:  # an AO image's rows have no colour differences, so no ΔE target
                row[target_column(metric, value)] = time_to_target(g, metric, value)
        row["efficiency"] = float(np.median(1.0 / (top["mse"] * top["time_s"])))
        rows.append(row)
    return pd.DataFrame(rows)
