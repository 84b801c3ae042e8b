"""The report's image viewer: its embedded data and the colour-map legends.

The viewer draws on a canvas. The images are embedded as HDR data
(little-endian float16, base64) and tone-mapped in the browser:
``v · 2^stops · exposure``, clipped to [0, 1], sRGB OETF, where
``exposure`` is the harness's one exposure
(:func:`cornell_harness.evaluate.metrics.exposure_scale` of the reference), so at 0 stops
the viewer shows exactly :func:`cornell_harness.evaluate.metrics.display_encode`. Flip
toggle (key F) and split slider against the reference, zoom to single
pixels (nearest neighbour, up to 64× the fitted size), pan, a readout of the
radiance of both images under the cursor, and the false-colour maps of
:func:`cornell_harness.reports.images.error_maps` (ΔE00, relMSE, FLIP) with their legends.
The browser side lives in ``templates/report.js``.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd

from cornell_harness.reports import plotmath
from cornell_harness.reports.colormaps import table_hex
from cornell_harness.reports.images import (
    DELTA_E_RANGE,
    FLIP_RANGE,
    JND,
    MAP_COLORMAPS,
    REL_MSE_LOG_RANGE,
    colorbar_data_uri,
    error_maps,
    f16_base64,
)
from cornell_harness.reports.tables import column_or_nan, ok_runs

def _first_seed_image_run(runs: pd.DataFrame, name: str, seeds: Sequence,
                          time_column: str = "time_s") -> tuple[Any, Any, Any]:
    """(spp, seed, time in s) of the run whose image is shown: the first seed's highest spp; None where unknown."""
    ok = ok_runs(runs)
    g = ok[ok["renderer"].astype(str) == name]
    if not len(g):
        return None, None, None
    seed_vals = [s for s in column_or_nan(g, "seed").dropna().tolist()]
    seed = next((s for s in seeds if s in seed_vals), min(seed_vals) if seed_vals else None)
    gs = g[column_or_nan(g, "seed") == seed] if seed is not None else g
    if not len(gs):
        return None, (int(seed) if seed is not None else None), None
    top = gs[gs["spp"] == gs["spp"].max()]
    times = pd.to_numeric(column_or_nan(top, time_column), errors="coerce").dropna()
    return (int(gs["spp"].max()), (int(seed) if seed is not None else None),
            _clean(float(times.iloc[0])) if len(times) else None)


def _clean(v: float) -> float | None:
    return float(v) if v is not None and math.isfinite(v) else None


def image_viewer(reference: np.ndarray, exposure: float, images: Mapping, names, colors, runs,
                 seeds, maps_out: dict | None = None, time_column: str = "time_s") -> tuple[dict, list]:
    """The image viewer's data (the reference, each renderer's image with the spp, seed and time (by
    ``time_column``) of its run, and its error maps) and its notes; each renderer's error maps also go into
    ``maps_out`` (by name) when given, for the image figure to reuse."""
    h, w = reference.shape[:2]
    entries, notes = [], []
    for name in names:
        if name not in images or images[name] is None:
            continue
        img = np.asarray(images[name], dtype=np.float32)
        if img.shape != reference.shape:
            notes.append(f"{name}: image shape {img.shape} does not match the reference's {reference.shape}; "
                         "not shown")
            continue
        maps = error_maps(img, reference, exposure)
        if maps_out is not None:
            maps_out[name] = maps
        spp, seed, seconds = _first_seed_image_run(runs, name, seeds, time_column)
        entries.append({
            "name": name,
            "color": colors[name],
            "spp": spp,
            "seed": seed,
            "time_s": seconds,
            "img": f16_base64(img),
            "de": f16_base64(maps["de"]),
            "relmse": f16_base64(np.log10(np.maximum(maps["relmse"], 1e-12))),
            "flip": f16_base64(maps["flip"]),
            "stats": {
                "de": _clean(float(np.mean(maps["de"]))),
                "relmse": _clean(float(np.mean(maps["relmse"]))),
                "flip": _clean(float(np.mean(maps["flip"]))),
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
                     "label": "FLIP", "available": bool(entries)},
        },
        "colormaps": {name: table_hex(name) for name in sorted(set(MAP_COLORMAPS.values()))},
    }
    return data, notes


def viewer_legends() -> list[dict]:
    """The colour bars of the viewer's error maps, with their ticks."""
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
                        lambda v: plotmath.format_tick(10.0**v)),
         "marker": None,
         "note": "relMSE 10⁻² is a 10 % relative error, 10⁻⁴ a 1 % one."},
        {"mode": "flip", "title": "FLIP per pixel (HDR-FLIP on linear radiance)",
         "uri": colorbar_data_uri(MAP_COLORMAPS["flip"]), "cmap": MAP_COLORMAPS["flip"],
         "ticks": ticks(0.0, 1.0, np.linspace(0, 1, 6), lambda v: f"{v:g}"),
         "marker": None,
         "note": "0: no visible difference when flipping between the images; 1: the largest."},
    ]
