"""The report's region section: where each named region is, and every renderer's metrics inside it.

For a scene with ``[regions.*]`` (masks from :mod:`cornell_harness.evaluate.regions`):

- the masks as one colour-coded overlay on the reference (display-encoded
  with the report's exposure, in grey, so the colours read), with a legend
  giving each region's colour, pixel count and description; smaller regions
  are drawn last, so one inside another stays visible;
- a table with one row per (renderer, region): the region metrics
  (``region.<name>.<metric>`` columns of the runs, median over seeds at the
  renderer's highest spp, as in the summary table), |mean z| > 3 flagged;
- for the bias/variance section, a table with one row per (renderer,
  region) of bias², variance and bias share (the summary's
  ``region.<name>.bias2`` … columns, :func:`cornell_harness.evaluate.summary.region_split`),
  next to the image-wide bars (:func:`bias_variance_table`).

Region colours are the Okabe-Ito palette (Okabe & Ito 2008, "Color
Universal Design"), distinguishable with the common colour-vision
deficiencies. The fragment is escaped here, like the gate's section.
"""

from __future__ import annotations

import math
from html import escape
from typing import Mapping

import numpy as np
import pandas as pd

from cornell_harness.evaluate import metrics
from cornell_harness.evaluate.regions import REGION_METRICS, nested_regions, region_masks
from cornell_harness.evaluate.summary import REGION_SPLIT, REGION_SPLIT_BOUNDS, region_split
from cornell_harness.reports.images import png_data_uri, to_uint8
from cornell_harness.reports.numbers import bias_share_note, column_label, format_value, interval_note, value_note
from cornell_harness.reports.tables import at_max_spp

#: Okabe-Ito colours without black (the report is dark) and grey (the overlay's background).
REGION_COLORS = ("#E69F00", "#56B4E9", "#009E73", "#F0E442", "#0072B2", "#D55E00", "#CC79A7")
#: How much of a region pixel's colour is the region's (the rest is the reference beneath).
OVERLAY_ALPHA = 0.6
#: |mean z| above this points at bias rather than noise (as the image-wide mean-radiance z).
Z_FLAG = 3.0
#: Column header and tooltip of the region metrics the registry does not list under their own key.
_HEADERS = {
    "region": ("region", "named region of the scene (scene file, [regions.*])"),
    "pixels": ("pixels", "pixels whose every sub-pixel camera ray sees the region"),
    "mean_z": (column_label("noise_mean_radiance_z")[0], "z-score of the region's mean-radiance difference "
               "given the reference's and the render's noise; |z| > 3 points at bias"),
}


def region_color(index: int) -> str:
    return REGION_COLORS[index % len(REGION_COLORS)]


def _rgb(hex_color: str) -> np.ndarray:
    return np.array([int(hex_color[i:i + 2], 16) for i in (1, 3, 5)], dtype=np.float64)


def overlay(reference: np.ndarray, masks: Mapping[str, np.ndarray], exposure: float) -> np.ndarray:
    """(H, W, 3) uint8: the reference in grey with each region tinted its colour (largest first)."""
    grey = metrics.display_encode(reference, exposure) @ np.array([0.2126, 0.7152, 0.0722])
    out = np.repeat(grey[..., None] * 255.0 * 0.8, 3, axis=-1)
    order = sorted(range(len(masks)), key=lambda i: -int(np.count_nonzero(list(masks.values())[i])))
    for i in order:
        mask = np.asarray(list(masks.values())[i], dtype=bool)
        out[mask] = (1.0 - OVERLAY_ALPHA) * out[mask] + OVERLAY_ALPHA * _rgb(region_color(i))
    return to_uint8(out / 255.0)


def region_rows(runs: pd.DataFrame) -> list[tuple[str, str, dict]]:
    """(renderer, region, {metric: value}) for every ok renderer with region columns, in run order."""
    rows = []
    for renderer, values in at_max_spp(runs).items():
        rows.extend((renderer, name, ms) for name, ms in nested_regions(values).items())
    return rows


def _header(key: str) -> tuple[str, str]:
    if key in _HEADERS:
        return _HEADERS[key]
    label, definition = column_label(key)
    per_region = key in REGION_METRICS or key in REGION_SPLIT
    return (label, f"{definition}, on the region's pixels") if per_region else (label, definition)


def _table(rows, colors: Mapping[str, str], renderer_colors: Mapping[str, str], keys=REGION_METRICS,
           table_id: str = "region-table") -> str:
    num = ' class="num"'
    head = "".join(f'<th data-key="{k}" title="{escape(k)}: {escape(_header(k)[1])}"'
                   f'{num if i > 1 else ""}>{escape(_header(k)[0])}<span class="arrow"></span></th>'
                   for i, k in enumerate(("renderer", "region", *keys)))
    body = []
    for renderer, region, values in rows:
        cells = [f'<td data-key="renderer" data-sort="{escape(renderer)}"><span class="swatch" style="background: '
                 f'{escape(renderer_colors.get(renderer, "#9aa1ad"))}"></span>{escape(renderer)}</td>',
                 f'<td data-key="region" data-sort="{escape(region)}"><span class="swatch" style="background: '
                 f'{escape(colors.get(region, "#9aa1ad"))}"></span>{escape(region)}</td>']
        for key in keys:
            v = values.get(key)
            finite = v is not None and not pd.isna(v)
            flag = key == "mean_z" and finite and math.isfinite(v) and abs(v) > Z_FLAG
            title = f' title="|z| &gt; {Z_FLAG:g}: the region\'s mean differs by more than noise"' if flag else ""
            text = format_value(key, v) if finite else "—"
            extra, ci_title = interval_note(key, values) if finite else ("", "")
            text += extra
            if note := "; ".join(n for n in ((value_note(key, v) if finite else ""), ci_title) if n):
                title = f' title="{escape(note)}"'
            if key == "bias2_fraction" and (share := bias_share_note(values)):
                text, title = share[0], f' title="{escape(share[1])}"'
            cells.append(f'<td data-key="{key}" data-sort="{repr(float(v)) if finite else ""}" '
                         f'class="num{" fail" if flag else ""}"{title}>{escape(text)}</td>')
        body.append(f'<tr class="record ok">{"".join(cells)}</tr>')
    return (f'<div class="table-wrap"><table class="summary sortable" id="{table_id}"><thead><tr class="cols">'
            f'{head}</tr></thead><tbody>{"".join(body)}</tbody></table></div>')


def bias_variance_table(summary: pd.DataFrame | None, scene, renderer_colors: Mapping[str, str]) -> str | None:
    """HTML table (escaped) of bias², variance and bias share per (renderer, region); None without them."""
    split = region_split(summary) if summary is not None and len(summary) else None
    if split is None or split.empty:
        return None
    colors = {name: region_color(i) for i, name in enumerate(scene.regions)}
    rows = [(str(r["renderer"]), str(r["region"]), {k: r[k] for k in (*REGION_SPLIT, *REGION_SPLIT_BOUNDS)})
            for r in split.to_dict("records")]
    return _table(rows, colors, renderer_colors, REGION_SPLIT, "region-bias-variance-table")


def region_section(scene, reference: np.ndarray, exposure: float, runs: pd.DataFrame,
                   renderer_colors: Mapping[str, str]) -> str | None:
    """HTML fragment (escaped) of the regions section; None for a scene without regions."""
    masks = region_masks(scene)
    if not masks:
        return None
    colors = {name: region_color(i) for i, name in enumerate(masks)}
    legend = "".join(
        f'<li><span class="swatch" style="background: {colors[name]}"></span><strong>{escape(name)}</strong> '
        f'<span class="note">{int(np.count_nonzero(m))} px'
        f'{" · " + escape(scene.regions[name].description) if scene.regions[name].description else ""}</span></li>'
        for name, m in masks.items())
    parts = [
        '<p class="note">A pixel belongs to a region when every one of its sub-pixel camera rays first hits one of '
        "the region's objects (inside its box, if it has one): pixels on a region's boundary are left out. "
        "Metrics are those of the whole image, on the region's pixels; ΔE uses the whole reference's exposure.</p>",
        f'<div class="region-maps"><figure><img alt="regions over the reference" '
        f'src="{png_data_uri(overlay(reference, masks, exposure))}"><figcaption>regions over the reference'
        f'</figcaption></figure><ul class="region-legend">{legend}</ul></div>',
    ]
    rows = region_rows(runs) if runs is not None and len(runs) else []
    parts.append(_table(rows, colors, renderer_colors) if rows else
                 '<p class="note single">No region metrics in these runs.</p>')
    return "\n".join(parts)
