"""A section about another scene or experiment, for a report that leads with one scene (``cbox demo``, and
each experiment of a merged report, :mod:`cornell_harness.reports.merge`).

The fragment shows the scene's reference and every renderer's image side by
side (display-encoded with the reference's exposure, as the main viewer
does), a sortable table of each renderer's outcome with its image-wide ΔE, the
noise yardstick beside it, a convergence experiment's slope, efficiency and
bias share, and the ΔE mean of every named region, and a link to the
experiment's own full report. It is escaped here, like the gate's section.
"""

from __future__ import annotations

from html import escape
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from cornell_harness.evaluate import metrics
from cornell_harness.evaluate.regions import REGION_PREFIX, nested_regions
from cornell_harness.reports.images import png_data_uri, to_uint8
from cornell_harness.reports.numbers import bias_share_note, column_label, format_value, interval_note, is_finite
from cornell_harness.reports.tables import at_max_spp, renderer_info, renderer_order

#: Columns of a convergence experiment's summary that a section's table adds where the experiment has them.
SECTION_SUMMARY_COLUMNS = ("slope_rmse_spp", "efficiency", "bias2_fraction")


def _thumbnail(image: np.ndarray, exposure: float, caption: str) -> str:
    pixels = to_uint8(metrics.display_encode(np.nan_to_num(image, nan=0.0), exposure))
    return (f'<figure><img alt="{escape(caption)}" src="{png_data_uri(pixels)}">'
            f'<figcaption>{escape(caption)}</figcaption></figure>')


def _columns(values: Mapping[str, dict]) -> list[tuple[str, str, str, str]]:
    """The table's columns after renderer and status, each (key in ``values``, header, tooltip, metric key
    that formats it): only those some renderer has a value for, but ΔE and its noise yardstick."""
    def some(key: str) -> bool:
        return any(is_finite(v.get(key)) for v in values.values())

    cols = [("spp", "spp", "samples per pixel (a convergence experiment's highest)", "spp")]
    if any(v.get("seeds", 1) > 1 for v in values.values()):
        cols.append(("seeds", "seeds", "seeds the figures are medians over", "seeds"))
    cols += [("delta_e2000_mean", "ΔE mean", column_label("delta_e2000_mean")[1], "delta_e2000_mean"),
             ("noise_delta_e2000_mean", "noise-alone ΔE", column_label("noise_delta_e2000_mean")[1],
              "noise_delta_e2000_mean")]
    cols += [(k, *column_label(k), k) for k in SECTION_SUMMARY_COLUMNS if some(k)]
    regions = dict.fromkeys(r for v in values.values() for r in nested_regions(v))
    return cols + [(f"{REGION_PREFIX}{r}.delta_e2000_mean", f"ΔE {r}", "ΔE mean on the region's pixels",
                    "delta_e2000_mean") for r in regions]


def _table(runs: pd.DataFrame, summary: pd.DataFrame | None) -> str:
    """The sortable per-renderer table (escaped): outcome, and the figures of :func:`_columns`."""
    names = renderer_order(runs, {})
    medians = at_max_spp(runs)
    figures = {str(r["renderer"]): r for r in summary.to_dict("records")} if summary is not None else {}
    values = {n: {**medians.get(n, {}), **{k: v for k, v in figures.get(n, {}).items()
                                            if k.startswith(SECTION_SUMMARY_COLUMNS) or k == "interval_basis"}}
              for n in names}
    cols = _columns(values)
    def th(key: str, header: str, tip: str, num: bool = True) -> str:
        cls = ' class="num"' if num else ""
        return (f'<th data-key="{escape(key)}" title="{escape(tip)}"{cls}>{escape(header)}'
                '<span class="arrow"></span></th>')

    head = th("renderer", "renderer", "", False) + th("status", "status", "", False)
    head += "".join(th(k, h, tip) for k, h, tip, _ in cols)
    body = []
    for info in renderer_info(runs, names, {}):
        ok, name = info["status"] == "ok", info["name"]
        status = info["status"] if ok else f'{info["status"]}: {info["reason"]}'
        cells = [f'<td data-key="renderer" data-sort="{escape(name)}">{escape(name)}</td>',
                 f'<td data-key="status" data-sort="{escape(info["status"])}">{escape(status)}</td>']
        for key, _, _, fmt in cols:
            v = values[name].get(key) if ok else None
            text, sort = (format_value(fmt, v), repr(float(v))) if is_finite(v) else ("—", "")
            extra, title = interval_note(key, values[name]) if is_finite(v) else ("", "")
            if key == "bias2_fraction" and ok and (share := bias_share_note(values[name])):
                (text, title), extra = share, ""
            title_attr = f' title="{escape(title)}"' if title else ""
            cells.append(f'<td data-key="{escape(key)}" data-sort="{sort}" class="num"{title_attr}>'
                         f'{escape(text + extra)}</td>')
        body.append(f"<tr>{''.join(cells)}</tr>")
    return (f'<table class="summary sortable"><thead><tr class="cols">{head}</tr></thead>'
            f'<tbody>{"".join(body)}</tbody></table>')


def scene_section(scene, reference: np.ndarray, rows: Sequence[dict], images: Mapping[str, np.ndarray],
                  link: str, summary: pd.DataFrame | None = None, link_text: str | None = None) -> str:
    """HTML fragment: ``scene``'s reference and images, a table with a row per renderer, a link to its report.

    ``rows`` are result rows (:meth:`cornell_harness.workflows.runner.RunRecord.row`, or
    an experiment folder's results as records): one per renderer for a
    comparison, one per renderer, seed and spp for a convergence experiment,
    whose table then shows each renderer at its highest spp, medians over
    seeds (:func:`cornell_harness.reports.tables.at_max_spp`), with the columns of
    :data:`SECTION_SUMMARY_COLUMNS` its ``summary`` has. ``images`` are the ok
    renderers' images by name; ``link_text`` defaults to "Full report for SCENE".
    """
    exposure = metrics.display_exposure(reference, scene.quantity)
    figures = [_thumbnail(reference, exposure, "reference")]
    figures += [_thumbnail(img, exposure, name) for name, img in images.items()]
    text = link_text or f"Full report for {scene.name}"
    return (f'<p class="note">{escape(scene.description)}. <a href="{escape(link)}">{escape(text)}</a>.</p>\n'
            f'<div class="region-maps">{"".join(figures)}</div>\n'
            f'<div class="table-wrap">{_table(pd.DataFrame(list(rows)), summary)}</div>')
