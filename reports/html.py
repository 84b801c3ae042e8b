"""The HTML report: one self-contained, interactive file comparing every renderer to the reference.

The file works offline, e.g. opened from a CI artifact: no script, font, style
or image is fetched; CSS, JavaScript, images, charts and data are all inlined.
It shows

1. **Summary table**, one row per renderer at its highest spp (median over
   seeds) with the metrics, time, spp and the summary figures (slopes,
   time to target, efficiency, bias²/variance); renderers that did not run
   with their status and reason. Columns sort on click; cells are coloured
   pass/fail where ``thresholds`` are given (a NaN fails: a missing number
   cannot show that a target was met).
2. **Image viewer** on a canvas. The images are embedded as HDR data
   (little-endian float16, base64) and tone-mapped in the browser:
   ``v · 2^stops · exposure``, clipped to [0, 1], sRGB OETF, where
   ``exposure`` is the harness's one exposure
   (:func:`harness.metrics.exposure_scale` of the reference), so at 0 stops
   the viewer shows exactly :func:`harness.metrics.display_encode`. Flip
   toggle (key F) and split slider against the reference, zoom to single
   pixels (nearest neighbour, up to 64× the fitted size), pan, a readout of the
   radiance of both images under the cursor, and false-colour maps:

   - per-pixel CIEDE2000 (:func:`harness.metrics.delta_e2000`), viridis, fixed
     0..10;
   - per-pixel relMSE ``mean_c (x − r)² / (r² + ε)``, ε =
     :data:`harness.metrics.REL_MSE_EPS`, inferno on a fixed log scale
     10⁻⁶..1 (embedded as log10 so float16 keeps its precision);
   - FLIP (Andersson et al. 2020, package ``flip-evaluator``) in its **HDR
     mode on the linear images** (non-finite pixels set to 0, negatives
     clipped to 0), magma, 0..1. HDR-FLIP picks its own exposure range from
     the reference, so it does not depend on the harness exposure.

   Maps are computed from the float32 images in Python and embedded as
   float16, not recomputed from the float16 images in the browser.
3. **Convergence plots** (error against spp and against time, log-log,
   median over seeds with a min–max band, slope guide), one pair per metric
   with a metric selector. With a single spp per renderer they are omitted
   with a one-line note.
4. **Speed/accuracy chart**: every (renderer, spp) point, medians over seeds,
   with the Pareto frontier (:func:`reports.plots.pareto_front`).
5. **Bias² and variance bars** per renderer from ``summary``.
6. **Provenance**: versions, machine, seeds, date, scene hash, the
   reference's own provenance and the command line.

Charts are inline SVG drawn by :mod:`reports.plots`. Entry point:
:func:`write_report`.
"""

from __future__ import annotations

import base64
import datetime as _dt
import io
import json
import math
import re
from pathlib import Path
from typing import Any, Mapping, Sequence

import jinja2
import markupsafe
import numpy as np
import pandas as pd
from markupsafe import Markup
from PIL import Image

from harness import metrics
from harness.atomic import write_text_atomic
from reports import plots
from reports.colormaps import TABLES, table_hex

#: Fixed ΔE00 range of every heatmap; values outside are clipped.
DELTA_E_RANGE = (0.0, 10.0)
#: Fixed log10 range of the per-pixel relMSE map.
REL_MSE_LOG_RANGE = (-6.0, 0.0)
#: FLIP's own range.
FLIP_RANGE = (0.0, 1.0)
#: Just-noticeable difference in ΔE00 (same value the metrics use).
JND = getattr(metrics, "JND_DELTA_E2000", 2.3)
#: Largest finite float16; finite radiance above it is clipped to it when embedded.
F16_MAX = 65504.0
#: Colour map of each false-colour mode.
MAP_COLORMAPS = {"de": "viridis", "relmse": "inferno", "flip": "magma"}

#: Swatch colour of renderers that did not run.
NOT_RUN_COLOR = "#5b616d"

SINGLE_SPP_NOTE = "single spp: run `cbox converge` for convergence plots"

_NOT_RUN = ("skipped", "unavailable", "failed")

# Metric key -> (short label, definition, better: "low" | "high" | None)
METRICS: dict[str, tuple[str, str, str | None]] = {
    "renderer": ("renderer", "renderer name", None),
    "status": ("status", "ok, skipped, unavailable or failed", None),
    "version": ("version", "renderer version", None),
    "spp": ("spp", "samples per pixel of the row (the highest reached)", None),
    "seeds": ("seeds", "number of seeds (independent runs) the medians are over", None),
    "time_s": ("time (s)", "wall time to reach this spp (median over seeds)", "low"),
    "rmse": ("RMSE", "root-mean-square error on linear radiance", "low"),
    "mse": ("MSE", "mean squared error on linear radiance", "low"),
    "rel_mse": ("relMSE", "mean of (img−ref)²/(ref²+0.01) on linear radiance", "low"),
    "rel_mse_trimmed": ("relMSE trim.", "relMSE without the worst pixels (fireflies)", "low"),
    "psnr": ("PSNR (dB)", "PSNR of the display-encoded images", "high"),
    "ssim": ("SSIM", "mean SSIM of the display-encoded images", "high"),
    "delta_e2000_mean": ("ΔE mean", "mean CIEDE2000", "low"),
    "delta_e2000_p95": ("ΔE p95", "95th percentile of CIEDE2000", "low"),
    "delta_e2000_max": ("ΔE max", "maximum CIEDE2000", "low"),
    "delta_e2000_frac_gt_2_3": ("ΔE > 2.3", "fraction of pixels above the just-noticeable difference", "low"),
    "mean_radiance_rel_error": ("mean rad. err", "relative error of the image's mean radiance", None),
    "nan_count": ("NaN px", "pixels with a NaN channel", "low"),
    "inf_count": ("Inf px", "pixels with an infinite channel", "low"),
    "negative_count": ("neg px", "pixels with a negative channel", "low"),
    "noise_rmse": ("RMSE (noise)", "expected RMSE from sampling noise alone at this spp", None),
    "noise_delta_e2000_mean": ("ΔE mean (noise)", "ΔE mean of a simulated noise-only image at this spp", None),
    "noise_mean_radiance_z": (
        "mean rad. z", "z-score of the mean-radiance difference given the noise; |z| > 3 points at bias", None),
    "efficiency": ("efficiency", "1/(MSE·time) at the highest spp: higher is better; unchanged by more time "
                   "for an unbiased renderer", "high"),
    "slope_rmse_spp": ("slope RMSE/spp", "log-log slope of RMSE against spp, mean over seeds ± 95% CI; "
                       "−0.5 for an unbiased renderer, towards 0 once bias dominates", None),
    "slope_rmse_time": ("slope RMSE/time", "log-log slope of RMSE against wall time, mean over seeds ± 95% CI",
                        None),
    "bias2": ("bias²", "squared bias, mean over pixels and channels (from several seeds' images)", "low"),
    "variance": ("variance", "between-seed variance, mean over pixels and channels", "low"),
    "bias2_fraction": ("bias share", "bias² / (bias² + variance)", None),
}

# Summary table: (group title, column keys); columns with no value for any renderer are dropped.
TABLE_GROUPS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("", ("renderer", "status", "version")),
    ("run", ("spp", "seeds", "time_s")),
    ("error against the reference", (
        "rmse", "rel_mse", "rel_mse_trimmed", "psnr", "ssim", "delta_e2000_mean", "delta_e2000_p95",
        "delta_e2000_max", "delta_e2000_frac_gt_2_3", "mean_radiance_rel_error")),
    ("broken pixels", ("nan_count", "inf_count", "negative_count")),
    ("noise yardsticks", ("noise_*",)),
    ("convergence", ("slope_rmse_spp", "slope_rmse_time", "efficiency", "time_to_*")),
    ("bias / variance", ("bias2", "variance", "bias2_fraction")),
)
_ALWAYS = {"renderer", "status", "spp", "seeds", "time_s"}

# Metrics that the convergence and speed/accuracy charts offer: key -> (axis label, guide slope).
PLOT_METRICS: dict[str, tuple[str, float | None]] = {
    "rmse": ("RMSE (linear radiance)", -0.5),
    "delta_e2000_mean": ("mean ΔE₀₀", -0.5),
    "rel_mse": ("relMSE", -1.0),
    "rel_mse_trimmed": ("relMSE (trimmed)", -1.0),
    "mse": ("MSE", -1.0),
    "delta_e2000_p95": ("ΔE₀₀ 95th percentile", -0.5),
}
_GUIDE_LABELS = {-0.5: "slope −½ (∝ 1/√N)", -1.0: "slope −1 (∝ 1/N)"}

_OPS = {"<=": "≤", ">=": "≥", "<": "<", ">": ">"}


# --------------------------------------------------------------------------
# Images and colour maps
# --------------------------------------------------------------------------


def apply_colormap(values, vmin: float = DELTA_E_RANGE[0], vmax: float = DELTA_E_RANGE[1],
                   cmap: str = "viridis") -> np.ndarray:
    """Colours of ``values`` on [vmin, vmax] (clipped), uint8 of shape ``values.shape + (3,)``.

    NaN maps to the top of the scale: an undefined difference is shown as the
    worst one, never hidden as a good one. The report's script uses the same
    256-entry tables and the same rule.
    """
    v = np.asarray(values, dtype=np.float64)
    t = np.clip((v - vmin) / (vmax - vmin), 0.0, 1.0)
    t = np.where(np.isnan(t), 1.0, t)
    return TABLES[cmap][np.round(t * 255).astype(np.int64)]


def to_uint8(encoded) -> np.ndarray:
    """A display-encoded float image in [0, 1] as uint8 (rounded, clipped)."""
    x = np.nan_to_num(np.asarray(encoded, dtype=np.float64), nan=0.0)
    return np.round(np.clip(x, 0.0, 1.0) * 255.0).astype(np.uint8)


def png_data_uri(pixels: np.ndarray) -> str:
    """``data:image/png;base64,...`` of a uint8 (H, W) or (H, W, 3) array."""
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(pixels)).save(buf, format="PNG", optimize=True)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def colorbar_data_uri(cmap: str = "viridis", width: int = 256, height: int = 1) -> str:
    """The colour bar of ``cmap`` as a (height, width) PNG, low values on the left."""
    ramp = apply_colormap(np.linspace(0.0, 1.0, width), 0.0, 1.0, cmap)
    return png_data_uri(np.repeat(ramp[None, :, :], height, axis=0))


def f16_base64(values) -> str:
    """Little-endian float16 bytes of ``values`` (row-major), base64.

    NaN and ±Inf stay as they are; finite values beyond the float16 range are
    clipped to ±65504 so that a bright but finite pixel does not turn into Inf.
    """
    a = np.asarray(values, dtype=np.float64)
    a = np.where(np.isfinite(a), np.clip(a, -F16_MAX, F16_MAX), a)
    return base64.b64encode(np.ascontiguousarray(a.astype("<f2")).tobytes()).decode("ascii")


def f16_decode(text: str, shape) -> np.ndarray:
    """Inverse of :func:`f16_base64` (float32), for tests and tools."""
    return np.frombuffer(base64.b64decode(text, validate=True), dtype="<f2").astype(np.float32).reshape(shape)


def rel_mse_map(img, ref, eps: float = metrics.REL_MSE_EPS) -> np.ndarray:
    """Per-pixel relMSE, ``mean_c (x − r)² / (r² + ε)``, shape (H, W); its mean is :func:`metrics.rel_mse`.

    A pixel with a non-finite channel is taken as black, as the metrics do.
    """
    img = np.asarray(img, dtype=np.float64)
    ref = np.asarray(ref, dtype=np.float64)
    clean = np.where(np.all(np.isfinite(img), axis=-1)[..., None], img, 0.0)
    return np.mean((clean - ref) ** 2 / (ref**2 + eps), axis=-1)


def flip_map(img, ref) -> np.ndarray | None:
    """HDR-FLIP map (H, W) of ``img`` against ``ref`` (linear radiance); None without ``flip_evaluator``."""
    try:
        import flip_evaluator
    except ImportError:
        return None

    def prep(x):
        x = np.asarray(x, dtype=np.float32)
        x = np.where(np.all(np.isfinite(x), axis=-1)[..., None], x, 0.0)
        return np.ascontiguousarray(np.maximum(x, 0.0), dtype=np.float32)

    fmap, _, _ = flip_evaluator.evaluate(prep(ref), prep(img), "HDR", applyMagma=False, computeMeanError=False)
    return np.asarray(fmap, dtype=np.float64).reshape(np.shape(ref)[:2])


def error_maps(img, ref, exposure: float) -> dict[str, np.ndarray | None]:
    """The viewer's three false-colour maps: ``de`` (ΔE00), ``relmse`` and ``flip`` (None if unavailable)."""
    _, de = metrics.delta_e2000(img, ref, exposure=exposure, full=True)
    return {"de": np.asarray(de, dtype=np.float64), "relmse": rel_mse_map(img, ref), "flip": flip_map(img, ref)}


# --------------------------------------------------------------------------
# Numbers
# --------------------------------------------------------------------------


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)


def _finite(v: Any) -> bool:
    return _is_number(v) and math.isfinite(float(v))


def _missing(v: Any) -> bool:
    if v is None:
        return True
    try:
        return bool(pd.isna(v))
    except (TypeError, ValueError):
        return False


def _generic(v: float) -> str:
    if v == 0:
        return "0"
    a = abs(v)
    if a >= 1e5 or a < 1e-3:
        return f"{v:.3e}"
    return f"{v:.4g}"


def _seconds(v: float) -> str:
    if v < 0.01:
        return f"{v:.2e}"
    return f"{v:.3f}" if v < 100 else f"{v:.1f}"


def format_value(key: str, v: Any) -> str:
    """A table cell: sensible precision per metric, "—" for missing values."""
    if v is None:
        return "—"
    if not _is_number(v):
        return str(v)
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    v = float(v)
    if math.isnan(v):
        return "NaN"
    if math.isinf(v):
        return "∞" if v > 0 else "−∞"
    if key.endswith("_count") or key in ("spp", "seeds", "max_spp"):
        return str(int(v)) if v.is_integer() else _generic(v)
    if key == "time_s" or key.startswith("time_to_"):
        return _seconds(v)
    if key == "psnr":
        return f"{v:.2f}"
    if key == "ssim":
        return f"{v:.4f}"
    if "frac" in key:
        return f"{100 * v:.1f} %"
    if key == "mean_radiance_rel_error":
        return f"{100 * v:+.2f} %"
    if key.endswith("_z") or key.startswith("slope_"):
        return f"{v:+.2f}"
    if key.startswith("delta_e2000") or key.startswith("noise_delta_e2000"):
        return f"{v:.2f}"
    return _generic(v)


def parse_time_to(key: str) -> tuple[str, str, float] | None:
    """``time_to_rel_mse_le_0.001`` → ("rel_mse", "<=", 0.001); None if not of that form."""
    m = re.fullmatch(r"time_to_(.+)_(le|lt|ge|gt)_([-+0-9.eE]+)", key)
    if not m:
        return None
    op = {"le": "<=", "lt": "<", "ge": ">=", "gt": ">"}[m.group(2)]
    try:
        return m.group(1), op, float(m.group(3))
    except ValueError:
        return None


def column_label(key: str) -> tuple[str, str]:
    """(header, definition) of a table column."""
    if key in METRICS:
        return METRICS[key][0], METRICS[key][1]
    if key.startswith("noise_"):
        return key.removeprefix("noise_").replace("_", " ") + " (noise)", "noise yardstick at this spp"
    parsed = parse_time_to(key)
    if parsed:
        metric, op, value = parsed
        label = METRICS.get(metric, (metric,))[0]
        return (f"time to {label} {_OPS[op]} {value:g}",
                f"seconds to reach {metric} {_OPS[op]} {value:g} (median over seeds; — if never reached)")
    return key.replace("_", " "), key


def check_threshold(value: Any, op: str, limit: float) -> bool:
    """Does ``value`` meet ``op limit``? A missing or NaN value does not."""
    if op not in _OPS:
        raise ValueError(f"threshold operator {op!r}: expected one of {', '.join(_OPS)}")
    if _missing(value) or not _is_number(value) or math.isnan(float(value)):
        return False
    v = float(value)
    return {"<=": v <= limit, ">=": v >= limit, "<": v < limit, ">": v > limit}[op]


# --------------------------------------------------------------------------
# Tables
# --------------------------------------------------------------------------


def _col(df: pd.DataFrame, key: str) -> pd.Series:
    return df[key] if key in df.columns else pd.Series([np.nan] * len(df), index=df.index, dtype=float)


def _numeric(df: pd.DataFrame, key: str) -> pd.Series:
    return pd.to_numeric(_col(df, key), errors="coerce")


def _metric_keys(runs: pd.DataFrame) -> list[str]:
    skip = {"scene", "scene_hash", "renderer", "status", "reason", "version", "settings", "approximations",
            "seed", "spp"}
    keys = []
    for k in runs.columns:
        if k in skip:
            continue
        if pd.api.types.is_numeric_dtype(runs[k]) or pd.to_numeric(runs[k], errors="coerce").notna().any():
            keys.append(k)
    return keys


def renderer_order(runs: pd.DataFrame, images: Mapping[str, Any]) -> list[str]:
    """Renderers in the order of their first row, then any renderer that only has an image."""
    names = [str(n) for n in dict.fromkeys(_col(runs, "renderer").dropna())] if len(runs) else []
    return names + [n for n in images if n not in names]


def ok_runs(runs: pd.DataFrame) -> pd.DataFrame:
    """The rows with status ok and a usable spp."""
    if not len(runs) or "status" not in runs.columns:
        return runs.iloc[0:0]
    ok = runs[runs["status"] == "ok"].copy()
    ok["spp"] = pd.to_numeric(_col(ok, "spp"), errors="coerce")
    return ok[ok["spp"].notna()]


def at_max_spp(runs: pd.DataFrame) -> dict[str, dict]:
    """Per renderer with ok rows: the medians over seeds of every numeric column at its highest spp."""
    ok = ok_runs(runs)
    keys = _metric_keys(ok)
    out = {}
    for name, g in ok.groupby("renderer", sort=False):
        top = g[g["spp"] == g["spp"].max()]
        row = {k: _nanstat(np.nanmedian, _numeric(top, k)) for k in keys}
        row["spp"] = float(g["spp"].max())
        row["seeds"] = int(_col(g, "seed").nunique()) or 1
        out[str(name)] = row
    return out


def convergence_table(runs: pd.DataFrame, metric_keys: Sequence[str]) -> pd.DataFrame:
    """One row per (renderer, spp) of the ok runs: median, min and max over seeds of each metric, median time."""
    ok = ok_runs(runs)
    rows = []
    for (name, spp), g in ok.groupby(["renderer", "spp"], sort=False):
        row = {"renderer": str(name), "spp": float(spp), "n": len(g),
               "time_s": _nanstat(np.nanmedian, _numeric(g, "time_s"))}
        for k in metric_keys:
            v = _numeric(g, k)
            row[k] = _nanstat(np.nanmedian, v)
            row[k + "_min"] = _nanstat(np.nanmin, v)
            row[k + "_max"] = _nanstat(np.nanmax, v)
        rows.append(row)
    df = pd.DataFrame(rows)
    if not len(df):
        return df
    order = {n: i for i, n in enumerate(dict.fromkeys(df["renderer"]))}  # renderers in the order of the runs
    return df.assign(_o=df["renderer"].map(order)).sort_values(["_o", "spp"], kind="stable").drop(columns="_o")


def _nanstat(fn, values: pd.Series) -> float:
    v = values.to_numpy(dtype=float)
    return float(fn(v)) if np.isfinite(v).any() else math.nan


def has_convergence(runs: pd.DataFrame) -> bool:
    """True when some renderer has ok rows at two or more spp: convergence plots then make sense."""
    ok = ok_runs(runs)
    return bool(len(ok)) and bool((ok.groupby("renderer")["spp"].nunique() >= 2).any())


def _empty(v: Any) -> bool:
    return not isinstance(v, (list, tuple, dict, np.ndarray)) and _missing(v)


def _parse_json(value: Any, default):
    if _empty(value):
        return default
    if isinstance(value, (list, tuple, dict, np.ndarray)):
        return list(value) if isinstance(value, np.ndarray) else value
    try:
        return json.loads(str(value))
    except (TypeError, ValueError):
        return str(value)


def _first(g: pd.DataFrame, key: str) -> Any:
    for v in _col(g, key):
        if not _empty(v):
            return v
    return None


# --------------------------------------------------------------------------
# The report's parts
# --------------------------------------------------------------------------


def _renderer_info(runs: pd.DataFrame, names: Sequence[str], colors: dict[str, str]) -> list[dict]:
    """Per renderer: status, reasons, version, settings, approximations (for the table and the cards)."""
    out = []
    for name in names:
        g = runs[_col(runs, "renderer").astype(str) == name] if len(runs) else runs
        statuses = [str(s) for s in _col(g, "status").dropna()]
        status = "ok" if "ok" in statuses else (statuses[0] if statuses else "ok")
        reasons = []
        for s, r in zip(_col(g, "status"), _col(g, "reason")):
            if str(s) != "ok" and not _missing(r) and str(r) not in [x for _, x in reasons]:
                reasons.append((str(s), str(r)))
        n_bad = sum(1 for s in statuses if s != "ok")
        approx = _parse_json(_first(g, "approximations"), [])
        if isinstance(approx, str):
            approx = [approx]
        settings = _parse_json(_first(g, "settings"), {})
        if isinstance(settings, dict):
            settings_rows = [(str(k), v if isinstance(v, str) else json.dumps(v)) for k, v in settings.items()]
        elif settings in (None, "", [], {}):
            settings_rows = []
        else:
            settings_rows = [("settings", str(settings))]
        version = _first(g, "version")
        out.append({
            "name": name,
            "color": colors.get(name, "#9aa1ad"),
            "status": status,
            "reasons": reasons,
            "reason": "; ".join(r for _, r in reasons) or ("(no reason given)" if status != "ok" else ""),
            "partial": f"{n_bad} of {len(statuses)} runs did not succeed" if status == "ok" and n_bad else "",
            "version": "" if version is None else str(version),
            "approximations": [str(a) for a in approx or ()],
            "settings": settings_rows,
        })
    return out


def _table_columns(rows: Sequence[dict], thresholds: Mapping) -> list[dict]:
    present = {k for r in rows for k, v in r.items() if k not in ("renderer", "status", "version")
               and _is_number(v) and not math.isnan(float(v))}
    present |= {"version"} if any(r.get("version") for r in rows) else set()
    groups = []
    for title, keys in TABLE_GROUPS:
        cols = []
        for key in keys:
            if key.endswith("*"):
                prefix = key[:-1]
                found = sorted({k for r in rows for k in r if k.startswith(prefix) and not k.endswith("_ci")})
                # every time-to-target column is shown: "not reached" by all is a result too
                cols.extend(k for k in found if k in present or k in thresholds or prefix == "time_to_")
            elif key in _ALWAYS or key in present or key in thresholds:
                cols.append(key)
        if cols:
            groups.append({"title": title, "keys": cols})
    placed = {k for g in groups for k in g["keys"]}
    if leftover := [k for k in thresholds if k not in placed]:  # a threshold on any other column
        groups.append({"title": "other thresholds", "keys": leftover})
    return groups


def _summary_rows(runs, summary, names, info, thresholds) -> tuple[list[dict], list[dict]]:
    medians = at_max_spp(runs)
    extra: dict[str, dict] = {}
    if summary is not None and len(summary):
        for rec in summary.to_dict("records"):
            d = {k: v for k, v in rec.items() if k != "renderer"}
            if "max_spp" in d and not _missing(d["max_spp"]):
                d["spp"] = d.pop("max_spp")
            else:
                d.pop("max_spp", None)
            extra[str(rec.get("renderer"))] = d
    rows = []
    for inf in info:
        name = inf["name"]
        row: dict[str, Any] = {"renderer": name, "status": inf["status"], "version": inf["version"]}
        if inf["status"] == "ok":
            row.update(medians.get(name, {}))
            for k, v in extra.get(name, {}).items():
                if not _missing(v) or k not in row:
                    row[k] = float(v) if _is_number(v) else v
        rows.append(row)
    groups = _table_columns(rows, thresholds)
    columns = [k for g in groups for k in g["keys"]]
    table = []
    for inf, row in zip(info, rows):
        cells = []
        for key in columns:
            v = row.get(key)
            cell = {"key": key, "text": format_value(key, v) if not _missing(v) or key in ("version",) else "—",
                    "sort": "", "cls": "", "title": ""}
            if key == "version":
                cell["text"] = row.get("version") or "—"
                cell["sort"] = cell["text"]
            elif key in ("renderer", "status"):
                cell["sort"] = str(v)
            elif _is_number(v) and not math.isnan(float(v)):
                cell["sort"] = repr(float(v))
                cell["cls"] = "num"
                ci = row.get(key + "_ci")
                if key.startswith("slope_") and _finite(ci):
                    cell["text"] += f" ± {float(ci):.2f}"
            else:
                cell["cls"] = "num"
                if key.startswith("time_to_") and inf["status"] == "ok":
                    cell["text"] = "not reached"
                    cell["title"] = "no seed reached this target"
            if key in thresholds and inf["status"] == "ok":
                op, limit = thresholds[key]
                passed = check_threshold(v, op, float(limit))
                cell["cls"] += " pass" if passed else " fail"
                cell["title"] = f"{'meets' if passed else 'misses'} {key} {_OPS[op]} {limit:g}"
            cells.append(cell)
        table.append({"renderer": inf["name"], "status": inf["status"], "color": inf["color"],
                      "reason": inf["reason"], "cells": cells})
    head = [{"title": g["title"], "span": len(g["keys"])} for g in groups]
    cols = []
    for key in columns:
        label, tip = column_label(key)
        better = METRICS.get(key, (None, None, None))[2]
        if key.startswith("time_to_"):
            better = "low"
        if key in thresholds:
            op, limit = thresholds[key]
            tip += f" — threshold: {_OPS[op]} {limit:g}"
        cols.append({"key": key, "label": label, "tip": tip, "better": better,
                     "num": key not in ("renderer", "status", "version")})
    return [{"head": head, "cols": cols}], table


def _series_for(conv: pd.DataFrame, metric: str, x: str, names: Sequence[str], colors: dict) -> list[plots.Series]:
    out = []
    for name in names:
        g = conv[conv["renderer"] == name].sort_values(x if x == "spp" else "spp")
        if not len(g) or not np.isfinite(g[metric].to_numpy(float)).any():
            continue
        labels = [
            f"{name}: {int(r['spp'])} spp, {r['time_s']:.3g} s, {metric} = {r[metric]:.4g} "
            f"(median of {int(r['n'])} seed{'s' if r['n'] != 1 else ''}; range {r[metric + '_min']:.4g}–"
            f"{r[metric + '_max']:.4g})"
            for _, r in g.iterrows()
        ]
        multi = (g["n"] > 1).any()
        out.append(plots.Series(
            name=name, color=colors[name], x=g[x].astype(float).tolist(), y=g[metric].astype(float).tolist(),
            lo=g[metric + "_min"].astype(float).tolist() if multi else None,
            hi=g[metric + "_max"].astype(float).tolist() if multi else None, labels=labels,
        ))
    return out


def _plot_metrics(conv: pd.DataFrame) -> list[str]:
    if not len(conv):
        return []
    out = []
    for k in PLOT_METRICS:
        if k in conv.columns:
            v = conv[k].to_numpy(float)
            if (np.isfinite(v) & (v > 0)).any():
                out.append(k)
    return out


def _charts(runs, names, colors) -> dict:
    ok = ok_runs(runs)
    conv = convergence_table(runs, [k for k in PLOT_METRICS if k in ok.columns])
    metric_keys = _plot_metrics(conv)
    charts: dict[str, Any] = {"metrics": [{"key": k, "label": PLOT_METRICS[k][0]} for k in metric_keys],
                              "convergence": [], "pareto": [], "has_convergence": has_convergence(runs)}
    for i, k in enumerate(metric_keys):
        label, slope = PLOT_METRICS[k]
        hidden = "" if i == 0 else ' style="display:none"'
        attrs = f' data-metric="{k}"{hidden}'
        if charts["has_convergence"]:
            guide = _GUIDE_LABELS.get(slope, f"slope {slope:g}")
            spp = plots.line_plot_svg(_series_for(conv, k, "spp", names, colors), uid=f"conv-spp-{k}",
                                      xlabel="samples per pixel", ylabel=label, guide_slope=slope,
                                      guide_label=guide, xbase2=True)
            tim = plots.line_plot_svg(_series_for(conv, k, "time_s", names, colors), uid=f"conv-time-{k}",
                                      xlabel="wall time (s)", ylabel=label, guide_slope=slope, guide_label=guide)
            charts["convergence"].append({"key": k, "attrs": Markup(attrs), "spp": Markup(spp),
                                          "time": Markup(tim)})
        points = [
            plots.Point(name=r["renderer"], color=colors[r["renderer"]], x=float(r["time_s"]), y=float(r[k]),
                        label=f"{r['renderer']}: {int(r['spp'])} spp, {r['time_s']:.3g} s, {k} = {r[k]:.4g}",
                        tag=f"{int(r['spp'])}")
            for _, r in conv.iterrows()
        ]
        charts["pareto"].append({"key": k, "attrs": Markup(attrs), "svg": Markup(plots.scatter_svg(
            points, uid=f"pareto-{k}", xlabel="wall time (s)", ylabel=label))})
    return charts


def _bias_variance_chart(summary, names, colors) -> Markup | None:
    if summary is None or not len(summary) or "bias2" not in summary.columns or "variance" not in summary.columns:
        return None
    by_name = {str(r["renderer"]): r for r in summary.to_dict("records")}
    groups = []
    for name in names:
        r = by_name.get(name)
        if r is None:
            continue
        b2, var = float(r.get("bias2", math.nan)), float(r.get("variance", math.nan))
        if not (math.isfinite(b2) or math.isfinite(var)):
            continue
        frac = r.get("bias2_fraction")
        note = f"bias {100 * float(frac):.0f} %" if _finite(frac) else ""
        groups.append(plots.BarGroup(name, [b2, var], note))
    if not groups:
        return None
    return Markup(plots.bars_svg(groups, (("bias²", "#e69f00"), ("variance", "#56b4e9")), uid="bias-variance",
                                 ylabel="mean over pixels and channels"))


def _provenance_rows(prov: dict, scene_hash: str) -> list[tuple[str, str]]:
    """The reference's own provenance as (label, value) rows."""
    renderer = " ".join(
        str(x) for x in (prov.get("renderer"), prov.get("renderer_version")) if x not in (None, "")
    ) or "—"
    if prov.get("variant") and str(prov["variant"]) not in renderer:
        renderer += f", variant {prov['variant']}"
    spp = str(prov.get("spp", "—"))
    if prov.get("batches") and prov.get("batch_spp"):
        spp += f" ({prov['batches']} batches × {prov['batch_spp']} spp)"
    rows = [("renderer", renderer), ("spp", spp), ("date", str(prov.get("date", "—")))]
    for key, label in (("wall_time_s", "wall time (s)"), ("machine", "machine"), ("command", "built with"),
                       ("noise_spp", "noise sample spp")):
        if prov.get(key) not in (None, ""):
            rows.append((label, str(prov[key])))
    seeds = prov.get("seeds")
    if isinstance(seeds, (list, tuple)) and seeds:
        rows.append(("seeds", f"{len(seeds)}: {seeds[0]}…{seeds[-1]}" if len(seeds) > 3 else
                     ", ".join(map(str, seeds))))
    ref_hash = prov.get("scene_hash")
    if ref_hash and ref_hash != scene_hash:
        rows.append(("warning", f"reference built for scene hash {ref_hash}, not this scene's"))
    return rows


def _kv(value: Any) -> str:
    if isinstance(value, (dict, list, tuple)):
        return json.dumps(value, default=str)
    return str(value)


def _run_provenance(provenance: Mapping) -> dict:
    prov = dict(provenance or {})
    versions = prov.pop("versions", None) or {}
    seeds = prov.pop("seeds", None)
    machine = prov.pop("machine", None)
    date = prov.pop("date", None)
    return {
        "versions": [(str(k), str(v)) for k, v in (versions.items() if isinstance(versions, Mapping) else [])],
        "seeds": ", ".join(str(s) for s in seeds) if isinstance(seeds, (list, tuple)) else (
            "" if seeds is None else str(seeds)),
        "machine": "" if machine is None else str(machine),
        "date": "" if date is None else str(date),
        "other": [(str(k), _kv(v)) for k, v in prov.items()],
    }


def _first_seed_image_run(runs: pd.DataFrame, name: str, seeds: Sequence) -> tuple[Any, Any]:
    ok = ok_runs(runs)
    g = ok[ok["renderer"].astype(str) == name]
    if not len(g):
        return None, None
    seed_vals = [s for s in _col(g, "seed").dropna().tolist()]
    seed = next((s for s in seeds if s in seed_vals), min(seed_vals) if seed_vals else None)
    gs = g[_col(g, "seed") == seed] if seed is not None else g
    return (int(gs["spp"].max()) if len(gs) else None), (int(seed) if seed is not None else None)


def _json_for_script(data: Any) -> Markup:
    """JSON safe inside a ``<script>`` element: no ``<``, ``>`` or ``&`` characters at all."""
    text = json.dumps(data, separators=(",", ":"), allow_nan=False)
    text = text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")
    text = text.replace("\u2028", "\\u2028").replace("\u2029", "\\u2029")
    return Markup(text)


def _clean(v: float) -> float | None:
    return float(v) if v is not None and math.isfinite(v) else None


def _viewer(reference: np.ndarray, exposure: float, images: Mapping, names, colors, runs, seeds) -> tuple[dict, list]:
    h, w = reference.shape[:2]
    entries, notes = [], []
    flip_available = True
    for name in names:
        if name not in images or images[name] is None:
            continue
        img = np.asarray(images[name], dtype=np.float32)
        if img.shape != reference.shape:
            notes.append(f"{name}: image shape {img.shape} does not match the reference's {reference.shape}; "
                         "not shown")
            continue
        maps = error_maps(img, reference, exposure)
        if maps["flip"] is None:
            flip_available = False
        spp, seed = _first_seed_image_run(runs, name, seeds)
        entries.append({
            "name": name,
            "color": colors[name],
            "spp": spp,
            "seed": seed,
            "img": f16_base64(img),
            "de": f16_base64(maps["de"]),
            "relmse": f16_base64(np.log10(np.maximum(maps["relmse"], 1e-12))),
            "flip": None if maps["flip"] is None else f16_base64(maps["flip"]),
            "stats": {
                "de": _clean(float(np.mean(maps["de"]))),
                "relmse": _clean(float(np.mean(maps["relmse"]))),
                "flip": None if maps["flip"] is None else _clean(float(np.mean(maps["flip"]))),
            },
        })
    data = {
        "width": w,
        "height": h,
        "exposure": exposure,
        "reference": f16_base64(reference),
        "renderers": entries,
        "maps": {
            "de": {"lo": DELTA_E_RANGE[0], "hi": DELTA_E_RANGE[1], "log": False, "cmap": MAP_COLORMAPS["de"],
                   "label": "ΔE00"},
            "relmse": {"lo": REL_MSE_LOG_RANGE[0], "hi": REL_MSE_LOG_RANGE[1], "log": True,
                       "cmap": MAP_COLORMAPS["relmse"], "label": "relMSE"},
            "flip": {"lo": FLIP_RANGE[0], "hi": FLIP_RANGE[1], "log": False, "cmap": MAP_COLORMAPS["flip"],
                     "label": "FLIP", "available": flip_available and bool(entries)},
        },
        "colormaps": {name: table_hex(name) for name in sorted(set(MAP_COLORMAPS.values()))},
    }
    return data, notes


def _legends() -> list[dict]:
    def ticks(lo, hi, values, fmt):
        return [(fmt(v), 100 * (v - lo) / (hi - lo)) for v in values]

    de_lo, de_hi = DELTA_E_RANGE
    rl_lo, rl_hi = REL_MSE_LOG_RANGE
    return [
        {"mode": "de", "title": "ΔE₀₀ per pixel (CIEDE2000), fixed scale, clipped at 10",
         "uri": colorbar_data_uri(MAP_COLORMAPS["de"]), "cmap": MAP_COLORMAPS["de"],
         "ticks": ticks(de_lo, de_hi, np.linspace(de_lo, de_hi, 6), lambda v: f"{v:g}" + ("+" if v == de_hi else "")),
         "marker": (f"JND {JND:g}", 100 * (JND - de_lo) / (de_hi - de_lo)),
         "note": f"Past the dashed line (ΔE {JND:g}) a difference is just noticeable side by side."},
        {"mode": "relmse", "title": "relMSE per pixel, (x−r)²/(r²+0.01), log scale, clipped to 10⁻⁶…1",
         "uri": colorbar_data_uri(MAP_COLORMAPS["relmse"]), "cmap": MAP_COLORMAPS["relmse"],
         "ticks": ticks(rl_lo, rl_hi, np.arange(rl_lo, rl_hi + 0.5),
                        lambda v: plots.format_tick(10.0**v)),
         "marker": None,
         "note": "relMSE 10⁻² is a 10 % relative error, 10⁻⁴ a 1 % one."},
        {"mode": "flip", "title": "FLIP per pixel (HDR-FLIP on linear radiance)",
         "uri": colorbar_data_uri(MAP_COLORMAPS["flip"]), "cmap": MAP_COLORMAPS["flip"],
         "ticks": ticks(0.0, 1.0, np.linspace(0, 1, 6), lambda v: f"{v:g}"),
         "marker": None,
         "note": "0: no visible difference when flipping between the images; 1: the largest."},
    ]


def _environment() -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.PackageLoader("reports", "templates"),
        autoescape=True,
        trim_blocks=True,
        lstrip_blocks=True,
        undefined=jinja2.StrictUndefined,
    )


def _asset(env: jinja2.Environment, name: str) -> Markup:
    text = env.loader.get_source(env, name)[0]
    if "</script" in text.lower() or "</style" in text.lower():
        raise ValueError(f"{name} must not contain a closing script or style tag")
    return Markup(text)


def _harness_version() -> str:
    try:
        from importlib.metadata import version

        return version("cornell-harness")
    except Exception:
        return "unknown"


def _max_depth_text(max_depth: int) -> str:
    if max_depth < 0:
        return "unbounded (Russian roulette)"
    return f"{max_depth} segments"


def _runs_text(runs: pd.DataFrame) -> str:
    ok = ok_runs(runs)
    if not len(ok):
        return "no successful runs"
    spps = sorted({int(s) for s in ok["spp"]})
    seeds = sorted({int(s) for s in _col(ok, "seed").dropna()})
    spp_text = f"{spps[0]} spp" if len(spps) == 1 else f"{len(spps)} spp levels, {spps[0]}–{spps[-1]}"
    seed_text = ("seed " + str(seeds[0])) if len(seeds) == 1 else f"{len(seeds)} seeds"
    return f"{spp_text}, {seed_text}"


def render_html(
    *,
    scene,
    reference,
    runs: pd.DataFrame,
    images: Mapping[str, Any],
    summary: pd.DataFrame | None = None,
    thresholds: Mapping[str, tuple[str, float]] | None = None,
    provenance: Mapping,
    command: str = "",
    title: str | None = None,
    sections: Sequence[tuple[str, str, str]] = (),
) -> str:
    """The report's HTML text (see :func:`write_report`).

    ``sections`` are extra (id, title, HTML fragment) sections other parts of
    the harness add (e.g. the gate's verdicts), placed after the summary; the
    fragments must be built with escaping already done.
    """
    ref_img = np.asarray(reference.image, dtype=np.float32)
    exposure = metrics.exposure_scale(ref_img)
    scene_hash = scene.content_hash()
    runs = runs if runs is not None else pd.DataFrame()
    images = dict(images or {})
    thresholds = dict(thresholds or {})
    for key, spec in thresholds.items():
        if not (isinstance(spec, (tuple, list)) and len(spec) == 2 and spec[0] in _OPS):
            raise ValueError(f"threshold for {key!r}: expected (op, value) with op in {', '.join(_OPS)}, got {spec!r}")
    provenance = dict(provenance or {})

    names = renderer_order(runs, images)
    # Palette colours for renderers with something to show; grey for those that did not run.
    shown = [n for n in names if n in images or n in set(ok_runs(runs).get("renderer", pd.Series(dtype=str)).astype(str))]
    colors = {n: plots.color_for(i) for i, n in enumerate(shown)}
    colors.update({n: NOT_RUN_COLOR for n in names if n not in colors})
    info = _renderer_info(runs, names, colors)
    table_head, table_rows = _summary_rows(runs, summary, names, info, thresholds)
    charts = _charts(runs, names, colors)
    run_seeds = provenance.get("seeds") or []
    viewer, viewer_notes = _viewer(ref_img, exposure, images, names, colors, runs, run_seeds)
    ref_prov = dict(reference.provenance or {})
    counts = {s: sum(i["status"] == s for i in info) for s in ("ok", *_NOT_RUN)}

    env = _environment()
    ctx = {
        "sections": [(sid, stitle, markupsafe.Markup(frag)) for sid, stitle, frag in sections],
        "title": title or f"Renderer comparison — {scene.name}",
        "scene": {
            "name": scene.name,
            "hash": scene_hash,
            "description": getattr(scene, "description", "") or "",
            "resolution": f"{scene.camera.width} × {scene.camera.height}",
            "max_depth": _max_depth_text(scene.max_depth),
            "pixel_filter": scene.pixel_filter,
        },
        "reference_rows": _provenance_rows(ref_prov, scene_hash),
        "reference_spp": ref_prov.get("spp", "—"),
        "run": _run_provenance(provenance),
        "command": command,
        "runs_text": _runs_text(runs),
        "generated": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "harness_version": _harness_version(),
        "exposure": f"{exposure:.4g}",
        "counts": counts,
        "renderers": info,
        "table_head": table_head[0],
        "table_rows": table_rows,
        "thresholds": [
            {"key": k, "label": column_label(k)[0], "op": _OPS[op], "value": f"{float(v):g}"}
            for k, (op, v) in thresholds.items()
        ],
        "charts": charts,
        "single_spp_note": SINGLE_SPP_NOTE,
        "bias_variance": _bias_variance_chart(summary, names, colors),
        "viewer": viewer,
        "viewer_json": _json_for_script(viewer),
        "viewer_notes": viewer_notes,
        "legends": _legends(),
        "jnd": JND,
        "rel_mse_eps": metrics.REL_MSE_EPS,
        "css": _asset(env, "report.css"),
        "js": _asset(env, "report.js"),
    }
    return env.get_template("report.html.j2").render(**ctx)


def write_report(
    path,
    *,
    scene,
    reference,
    runs: pd.DataFrame,
    images: Mapping[str, Any],
    summary: pd.DataFrame | None = None,
    thresholds: Mapping[str, tuple[str, float]] | None = None,
    provenance: Mapping,
    command: str = "",
    title: str | None = None,
    sections: Sequence[tuple[str, str, str]] = (),
) -> Path:
    """Write the self-contained HTML report to ``path`` atomically; return the path.

    - ``scene``: the :class:`harness.scene.Scene`;
    - ``reference``: the :class:`harness.reference.Reference` (its ``image`` and
      ``provenance`` are used);
    - ``runs``: the tidy results, one row per (renderer, seed, spp), with
      ``status`` and ``reason`` for renderers that did not run;
    - ``images``: renderer → (H, W, 3) linear-sRGB image shown in the viewer
      (the highest-spp image of the first seed);
    - ``summary``: optional per-renderer figures (slopes, ``time_to_*``,
      efficiency, bias², variance);
    - ``thresholds``: optional metric → (op, value), op in ``<= >= < >``, for
      pass/fail colouring of the summary table;
    - ``provenance``: ``versions``, ``machine``, ``seeds``, ``date`` and any
      other key/value to show; ``command``: the command line;
    - ``sections``: extra (id, title, escaped HTML fragment) sections, shown
      after the summary (the gate's verdicts use this).
    """
    path = Path(path)
    html = render_html(
        scene=scene, reference=reference, runs=runs, images=images, summary=summary, thresholds=thresholds,
        provenance=provenance, command=command, title=title, sections=sections,
    )
    write_text_atomic(path, html)
    return path
