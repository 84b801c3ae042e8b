"""The summary table: its columns, thresholds and the per-renderer rows (each number printed by
:mod:`cornell_harness.reports.numbers`).

One row per renderer at its highest spp (median over seeds) with the
metrics, time, spp and the summary figures (slopes, time to target,
efficiency, bias²/variance); renderers that did not run with their status
and reason. Columns come from :data:`TABLE_GROUPS` and the harness's metric
registry (:data:`~cornell_harness.reports.numbers.METRICS`); cells are coloured pass/fail where
``thresholds`` are given (a NaN fails: a missing number cannot show that a
target was met).

Also the helpers on the tidy ``runs`` table the other parts share: the ok
rows (:func:`ok_runs`), renderer order and medians over seeds.
"""

from __future__ import annotations

import json
import math
from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd

from cornell_harness.reports.numbers import (METRICS, OPERATOR_SIGNS, bias_share_note, check_threshold, column_label,
                                             format_value, interval_note, is_missing, is_number, value_note)

# Summary table: (group title, column keys); columns with no value for any renderer are dropped. The
# decisive figures come first, on screen without scrolling the table: convergence slope, time to a target
# error, efficiency, bias share; then the run and the metrics of the final image.
TABLE_GROUPS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("", ("renderer", "status")),
    ("convergence", ("slope_rmse_spp", "slope_rmse_time", "time_to_*", "efficiency")),
    ("bias / variance", ("bias2_fraction", "bias2", "variance")),
    ("run", ("spp", "seeds", "time_s", "version")),
    ("error against the reference", (
        "rmse", "rel_mse", "rel_mse_trimmed", "psnr", "ssim", "delta_e2000_mean", "delta_e2000_p95",
        "delta_e2000_max", "delta_e2000_frac_gt_2_3", "flip_mean", "mean_radiance_rel_error")),
    ("broken pixels", ("nan_count", "inf_count", "negative_count")),
    ("noise yardsticks", ("noise_*",)),
)
_ALWAYS = {"renderer", "status", "spp", "seeds", "time_s"}
#: Columns that bound another (its interval), never columns of their own.
_BOUND_SUFFIXES = ("_ci", "_low", "_high")

# --------------------------------------------------------------------------
# The runs table
# --------------------------------------------------------------------------


def column_or_nan(df: pd.DataFrame, key: str) -> pd.Series:
    """``df[key]``, or NaN for every row when the table has no such column."""
    return df[key] if key in df.columns else pd.Series([np.nan] * len(df), index=df.index, dtype=float)


def numeric_column(df: pd.DataFrame, key: str) -> pd.Series:
    """:func:`column_or_nan` as numbers (NaN where a cell is not one)."""
    return pd.to_numeric(column_or_nan(df, key), errors="coerce")


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
    names = [str(n) for n in dict.fromkeys(column_or_nan(runs, "renderer").dropna())] if len(runs) else []
    return names + [n for n in images if n not in names]


def ok_runs(runs: pd.DataFrame) -> pd.DataFrame:
    """The rows with status ok and a usable spp."""
    if not len(runs) or "status" not in runs.columns:
        return runs.iloc[0:0]
    ok = runs[runs["status"] == "ok"].copy()
    ok["spp"] = pd.to_numeric(column_or_nan(ok, "spp"), errors="coerce")
    return ok[ok["spp"].notna()]


def at_max_spp(runs: pd.DataFrame) -> dict[str, dict]:
    """Per renderer with ok rows: the medians over seeds of every numeric column at its highest spp."""
    ok = ok_runs(runs)
    keys = _metric_keys(ok)
    out = {}
    for name, g in ok.groupby("renderer", sort=False):
        top = g[g["spp"] == g["spp"].max()]
        row = {k: nan_stat(np.nanmedian, numeric_column(top, k)) for k in keys}
        row["spp"] = float(g["spp"].max())
        row["seeds"] = int(column_or_nan(g, "seed").nunique()) or 1
        out[str(name)] = row
    return out


def nan_stat(fn, values: pd.Series) -> float:
    """``fn`` (np.nanmedian, ...) of ``values``; NaN, without a warning, when none is finite."""
    v = values.to_numpy(dtype=float)
    return float(fn(v)) if np.isfinite(v).any() else math.nan


def _empty(v: Any) -> bool:
    return not isinstance(v, (list, tuple, dict, np.ndarray)) and is_missing(v)


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
    for v in column_or_nan(g, key):
        if not _empty(v):
            return v
    return None


# --------------------------------------------------------------------------
# The summary table's rows
# --------------------------------------------------------------------------


def renderer_info(runs: pd.DataFrame, names: Sequence[str], colors: dict[str, str]) -> list[dict]:
    """Per renderer: status, reasons, version, settings, approximations (for the table and the cards)."""
    out = []
    for name in names:
        g = runs[column_or_nan(runs, "renderer").astype(str) == name] if len(runs) else runs
        statuses = [str(s) for s in column_or_nan(g, "status").dropna()]
        status = "ok" if "ok" in statuses else (statuses[0] if statuses else "ok")
        reasons = []
        for s, r in zip(column_or_nan(g, "status"), column_or_nan(g, "reason")):
            if str(s) != "ok" and not is_missing(r) and str(r) not in [x for _, x in reasons]:
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
               and is_number(v) and not math.isnan(float(v))}
    present |= {"version"} if any(r.get("version") for r in rows) else set()
    groups = []
    for title, keys in TABLE_GROUPS:
        cols = []
        for key in keys:
            if key.endswith("*"):
                prefix = key[:-1]
                found = sorted({k for r in rows for k in r if k.startswith(prefix) and not k.endswith(_BOUND_SUFFIXES)})
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


def summary_rows(runs, summary, names, info, thresholds) -> tuple[list[dict], list[dict]]:
    """The summary table's header cells and rows, one per renderer (the figures at its highest spp)."""
    medians = at_max_spp(runs)
    extra: dict[str, dict] = {}
    if summary is not None and len(summary):
        for rec in summary.to_dict("records"):
            d = {k: v for k, v in rec.items() if k != "renderer"}
            if "max_spp" in d and not is_missing(d["max_spp"]):
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
                if not is_missing(v) or k not in row:
                    row[k] = float(v) if is_number(v) else v
        rows.append(row)
    groups = _table_columns(rows, thresholds)
    columns = [k for g in groups for k in g["keys"]]
    table = []
    for inf, row in zip(info, rows):
        cells = []
        for key in columns:
            v = row.get(key)
            cell = {"key": key, "text": format_value(key, v) if not is_missing(v) or key in ("version",) else "—",
                    "sort": "", "cls": "", "title": ""}
            if key == "version":
                cell["text"] = row.get("version") or "—"
                cell["sort"] = cell["text"]
            elif key in ("renderer", "status"):
                cell["sort"] = str(v)
            elif is_number(v) and not math.isnan(float(v)):
                cell["sort"] = repr(float(v))
                cell["cls"] = "num"
                cell["title"] = value_note(key, v)
                text, title = interval_note(key, row)
                cell["text"] += text
                cell["title"] = "; ".join(t for t in (cell["title"], title) if t)
            else:
                cell["cls"] = "num"
                if key.startswith("time_to_") and inf["status"] == "ok":
                    cell["text"] = "not reached"
                    cell["title"] = "no seed reached this target"
            if key == "bias2_fraction" and (note := bias_share_note(row)):
                cell["text"], cell["title"] = note
            if key in thresholds and inf["status"] == "ok":
                op, limit = thresholds[key]
                passed = check_threshold(v, op, float(limit))
                cell["cls"] += " pass" if passed else " fail"
                cell["title"] = f"{'meets' if passed else 'misses'} {key} {OPERATOR_SIGNS[op]} {limit:g}"
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
            tip += f" — threshold: {OPERATOR_SIGNS[op]} {limit:g}"
        cols.append({"key": key, "label": label, "tip": tip, "better": better,
                     "num": key not in ("renderer", "status", "version")})
    return [{"head": head, "cols": cols}], table
