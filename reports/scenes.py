"""A section about another scene's comparison, for a report that leads with one scene (``cbox demo``).

The fragment shows the scene's reference and every renderer's image side by
side (display-encoded with the reference's exposure, as the main viewer
does), a table of each renderer's outcome with its image-wide ΔE, the noise
yardstick beside it, and the ΔE mean of every named region, and a link to
that scene's own full report. It is escaped here, like the gate's section.
"""

from __future__ import annotations

from html import escape
from typing import Mapping, Sequence

import numpy as np

from harness.evaluate import metrics
from harness.evaluate.regions import nested_regions
from reports.images import png_data_uri, to_uint8
from reports.tables import format_value


def _thumbnail(image: np.ndarray, exposure: float, caption: str) -> str:
    pixels = to_uint8(metrics.display_encode(np.nan_to_num(image, nan=0.0), exposure))
    return (f'<figure><img alt="{escape(caption)}" src="{png_data_uri(pixels)}">'
            f'<figcaption>{escape(caption)}</figcaption></figure>')


def scene_section(scene, reference: np.ndarray, rows: Sequence[dict], images: Mapping[str, np.ndarray],
                  link: str) -> str:
    """HTML fragment: ``scene``'s reference and images, per-renderer (and per-region) ΔE, a link to its report.

    ``rows`` are result rows (:meth:`harness.workflows.runner.RunRecord.row`),
    ``images`` the ok renderers' images by name.
    """
    exposure = metrics.display_exposure(reference, scene.quantity)
    figures = [_thumbnail(reference, exposure, "reference")]
    figures += [_thumbnail(img, exposure, name) for name, img in images.items()]
    regions = list(nested_regions(rows[0]) if rows else {})
    for row in rows[1:]:
        regions += [r for r in nested_regions(row) if r not in regions]
    head = "".join(f"<th>{escape(h)}</th>" for h in ("renderer", "status", "spp", "ΔE mean", "noise-alone ΔE"))
    head += "".join(f'<th class="num" title="ΔE mean on the region&#39;s pixels">ΔE {escape(r)}</th>' for r in regions)
    body = []
    for row in rows:
        ok = row.get("status") == "ok"
        per_region = nested_regions(row)
        cells = [escape(str(row.get("renderer"))),
                 escape(row["status"] if ok else f'{row.get("status")}: {row.get("reason")}'),
                 escape(str(row.get("spp"))),
                 escape(format_value("delta_e2000_mean", row.get("delta_e2000_mean")) if ok else "—"),
                 escape(format_value("noise_delta_e2000_mean", row.get("noise_delta_e2000_mean")) if ok else "—")]
        cells += [escape(format_value("delta_e2000_mean", per_region.get(r, {}).get("delta_e2000_mean"))
                         if ok else "—") for r in regions]
        body.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    return (f'<p class="note">{escape(scene.description)}. '
            f'<a href="{escape(link)}">Full report for {escape(scene.name)}</a>.</p>\n'
            f'<div class="region-maps">{"".join(figures)}</div>\n'
            f'<div class="table-wrap"><table class="summary"><thead><tr class="cols">{head}</tr></thead>'
            f'<tbody>{"".join(body)}</tbody></table></div>')
