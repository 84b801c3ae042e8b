"""The report section "Recursive ray tracing and its hacks" (docs/whitted.md): what the Whitted variants, and the other
approximations beside them, miss of the reference's light in each region of a scene.

One row per renderer (the Whitted variants first), one column per region; a cell is the share of the
reference's light the renderer misses there (:func:`cornell_harness.evaluate.missing_light.missing_light`) and the
region's mean ΔE00, read off the comparison's results rows. ``cbox demo`` shows it for its caustics
comparison; ``docs/whitted.md`` (``benchmarks/whitted.py``) has the measured table over seeds at equal time.
"""

from __future__ import annotations

import math
from html import escape
from typing import Mapping, Sequence

from cornell_harness.evaluate.missing_light import region_table
from cornell_harness.evaluate.regions import nested_regions

TITLE = "Recursive ray tracing and its hacks"
#: The renderer whose rows lead: the Whitted variants (``whitted``, ``whitted[...]``).
WHITTED = "whitted"

INTRO = (
    "Whitted-style recursive ray tracing follows mirror and glass paths to max_depth and takes direct light by "
    "shadow rays only: no diffuse interreflection (an ambient term stands in for it) and no caustics. Glass in a "
    "shadow ray's way is a hack: <em>boolean</em> lets no light through, <em>attenuate</em> (Pierce's shadow "
    "attenuation) lets it through straight, scaled by the Fresnel transmittance, <em>ignore</em> pretends the glass "
    "is not there. Each cell: the share of the reference's light the renderer misses in the region (negative: it "
    "adds light), and the region's mean ΔE00. One seed, at the comparison's spp: the figures' standard errors "
    "(in each cell's tooltip) hold only the reference's noise; docs/whitted.md has them over seeds, at equal time."
)


def renderer_rows_order(names: Sequence[str]) -> list[str]:
    """``names`` with the Whitted variants first, each group in its given order."""
    whitted = [n for n in names if n == WHITTED or n.startswith(WHITTED + "[")]
    return whitted + [n for n in names if n not in whitted]


def _cell(fig: Mapping) -> tuple[str, str]:
    """A cell's text and tooltip: missing share and ΔE; "—" for a region the renderer has no figure in."""
    share, de = fig["share"], fig["delta_e"]
    if not math.isfinite(share):
        return "—", ""
    text = f"{100 * share:+.1f}% · ΔE {de:.2f}" if math.isfinite(de) else f"{100 * share:+.1f}%"
    tip = (f"missing share {100 * share:.2f}% ± {100 * fig['share_se']:.2f}% (1 SE); bias {fig['bias']:.4g} "
           f"± {fig['bias_se']:.2g}; {fig['seeds']} seed(s), {fig['spp']} spp")
    return text.replace("-", "\u2212"), tip  # the typographic minus, as the docs write it


def hacks_table(rows: Sequence[Mapping], ref_noise: Mapping[str, Mapping]) -> str:
    """HTML table (escaped): renderer × region, each cell :func:`_cell`; ``rows`` are results rows."""
    ok = [r for r in rows if r.get("status") == "ok"]
    regions = [r for r in dict.fromkeys(k for row in ok for k in nested_regions(row)) if r in ref_noise]
    figures = {(f["renderer"], f["region"]): f for f in region_table(ok, regions, ref_noise)}
    names = renderer_rows_order(list(dict.fromkeys(str(r["renderer"]) for r in ok)))
    head = "<th>renderer</th>" + "".join(
        f'<th class="num" title="reference mean {ref_noise[g]["mean"]:.4g}">{escape(g)}</th>' for g in regions)
    body = []
    for name in names:
        cells = []
        for g in regions:
            text, tip = _cell(figures[(name, g)])
            cells.append(f'<td class="num" title="{escape(tip)}">{escape(text)}</td>')
        body.append(f"<tr><td>{escape(name)}</td>{''.join(cells)}</tr>")
    return (f'<table class="summary"><thead><tr class="cols">{head}</tr></thead>'
            f'<tbody>{"".join(body)}</tbody></table>')


def whitted_section(rows: Sequence[Mapping], ref_noise: Mapping[str, Mapping], scene_name: str) -> str:
    """HTML fragment of the section: what it shows, and :func:`hacks_table`; a note when no Whitted row ran."""
    names = {str(r["renderer"]) for r in rows if r.get("status") == "ok"}
    missing = "" if any(n == WHITTED or n.startswith(WHITTED + "[") for n in names) else (
        f'<p class="note">No {WHITTED} render ran here: the table shows the other renderers only.</p>\n')
    return (f'<p class="note">{escape(scene_name)}. {INTRO}</p>\n{missing}'
            f'<div class="table-wrap">{hacks_table(rows, ref_noise)}</div>')
