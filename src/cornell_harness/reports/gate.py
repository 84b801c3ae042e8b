"""The gate's section of the HTML report: verdicts, where the image disagrees, and the p-values.

For each expectation: its verdict (pass, fail or inconclusive), its checks (pass, skipped, FAIL, ERROR or
INCONCLUSIVE, and by how much; a crash's traceback folded under its message); for an unbiased one, the
relative-bias interval of every region and channel; for an
agreement test, a map of |z| per tile (magma, 0..6, failing tiles boxed in
white) and a histogram of the tile p-values, which is flat for a renderer
that agrees with the reference and piles up at 0 where it does not.
"""

from __future__ import annotations

from html import escape

import numpy as np

from cornell_harness.evaluate.relative_bias import interval_text
from cornell_harness.reports.ci import no_bound_note
from cornell_harness.reports.images import apply_colormap, png_data_uri

Z_MAX = 6.0
TILE_PX = 8  # on-screen pixels per tile in the z map
BINS = 20


def z_map_png(z_tiles: np.ndarray, failing: np.ndarray) -> str:
    """|z| per tile (max over channels) as a magma PNG data URI; failing tiles outlined."""
    z = np.nanmax(np.abs(z_tiles), axis=-1)
    rgb = apply_colormap(np.minimum(z, Z_MAX), 0.0, Z_MAX, "magma")
    big = np.repeat(np.repeat(rgb, TILE_PX, axis=0), TILE_PX, axis=1)
    for r, c in zip(*np.nonzero(failing.any(axis=-1))):
        y0, x0 = r * TILE_PX, c * TILE_PX
        big[y0, x0:x0 + TILE_PX] = big[y0 + TILE_PX - 1, x0:x0 + TILE_PX] = 255
        big[y0:y0 + TILE_PX, x0] = big[y0:y0 + TILE_PX, x0 + TILE_PX - 1] = 255
    return png_data_uri(big)


def p_histogram_svg(p: np.ndarray, level: float, width: int = 320, height: int = 140) -> str:
    """Histogram of p-values in [0, 1] with the flat line a well-calibrated test gives."""
    p = np.asarray(p, float).ravel()
    counts, _ = np.histogram(p, bins=BINS, range=(0, 1))
    expected = p.size / BINS
    top = max(counts.max(initial=0), expected) * 1.15 or 1
    pad_l, pad_b = 34, 22
    w, h = width - pad_l - 6, height - pad_b - 6
    bw = w / BINS
    bars = "".join(
        f'<rect x="{pad_l + i * bw + 1:.1f}" y="{6 + h - h * n / top:.1f}" width="{bw - 2:.1f}" '
        f'height="{h * n / top:.1f}" fill="{"#e4572e" if i == 0 and p.size and (p < level).any() else "#5fa8d3"}"/>'
        for i, n in enumerate(counts))
    y_exp = 6 + h - h * expected / top
    return (f'<svg class="phist" viewBox="0 0 {width} {height}" width="{width}" height="{height}" role="img" '
            f'aria-label="histogram of tile p-values">{bars}'
            f'<line x1="{pad_l}" x2="{pad_l + w}" y1="{y_exp:.1f}" y2="{y_exp:.1f}" stroke="#ddd" '
            f'stroke-dasharray="4 3"/><text x="{pad_l + w}" y="{y_exp - 3:.1f}" text-anchor="end" fill="#bbb" '
            f'font-size="10">uniform (agreement)</text>'
            f'<line x1="{pad_l}" x2="{pad_l + w}" y1="{6 + h}" y2="{6 + h}" stroke="#888"/>'
            f'<text x="{pad_l}" y="{height - 6}" fill="#bbb" font-size="10">0</text>'
            f'<text x="{pad_l + w}" y="{height - 6}" fill="#bbb" font-size="10" text-anchor="end">1</text>'
            f'<text x="{pad_l + w / 2}" y="{height - 6}" fill="#bbb" font-size="10" text-anchor="middle">'
            f'p-value per tile and channel</text>'
            f'<text x="4" y="14" fill="#bbb" font-size="10">{int(top)}</text></svg>')


def _check_row(c) -> str:
    """One check's row: its result as JUnit has it (pass, skipped, FAIL, ERROR), a crash's traceback folded in."""
    css = "skipped" if c.skipped else "fail" if c.inconclusive else "pass" if c.passed else "fail"
    tb = (f'<details class="traceback"><summary>traceback</summary><pre>{escape(c.traceback.rstrip())}</pre>'
          f'</details>' if c.traceback else "")
    return (f'<tr class="{css}"><td>{escape(c.name)}</td><td>{escape(c.word)}</td>'
            f'<td>{escape(c.message)}{tb}</td></tr>')


def bias_table_html(t) -> str:
    """An expectation's relative-bias intervals per region and channel (a
    :class:`~cornell_harness.gate.margins.BiasTable`), with margins and verdicts where it states them."""
    b = t.intervals
    head = "<th>region</th><th>pixels</th>" + "".join(f"<th>{ch}</th>" for ch in "RGB")
    rows = []
    for i in range(len(t.regions)):
        cells = []
        for c in range(3):
            text = interval_text("", float(b.estimate[i, c]), float(b.low[i, c]), float(b.high[i, c]))
            if t.margins is not None:
                text += f" (±{100 * t.margins[i, c]:g}%: {t.verdicts[i, c]})"
            cells.append(f"<td>{escape(text)}</td>")
        rows.append(f"<tr><td>{escape(t.label(i))}</td><td>{t.pixels[i]}</td>{''.join(cells)}</tr>")
    note = ("margins stated: pass inside, inconclusive otherwise" if t.margins is not None else
            "no margin stated: these intervals bound the bias, the pass does not")
    return (f'<table class="gate-bias"><caption>relative bias, render / reference − 1, at {t.spp} spp: Fieller '
            f'intervals simultaneous at {1 - t.alpha:g} ({escape(note)})</caption><thead><tr>{head}</tr></thead>'
            f'<tbody>{"".join(rows)}</tbody></table>')


def gate_section(outcomes, alpha: float) -> str:
    """HTML fragment (escaped) for :func:`cornell_harness.reports.html.write_report`'s ``sections``."""
    failed = sum(c.failed for o in outcomes for c in o.checks)
    open_ = sum(c.inconclusive and not c.passed for o in outcomes for c in o.checks)
    skipped = sum(c.skipped for o in outcomes for c in o.checks)
    also = f" ({skipped} check(s) skipped)" if skipped else ""
    verdict = (f'<p class="gate-verdict fail">Gate failed: {failed} check(s){also}</p>' if failed else
               f'<p class="gate-verdict fail">Gate inconclusive: {open_} check(s){also}</p>' if open_ else
               f'<p class="gate-verdict pass">Gate passed{also}</p>')
    parts = [verdict, f"<p class=\"note\">Agreement tests: tiled and whole-image z-tests against the reference "
                      f"at family-wise α = {alpha:g} (Šidák). Every expectation also requires zero NaN and Inf "
                      f"pixels.</p>"]
    if note := no_bound_note(outcomes):
        parts.append(f'<p class="note">{escape(note)}</p>')
    for o in outcomes:
        e, r = o.expectation, o.record
        rows = "".join(_check_row(c) for c in o.checks)
        badge = {"pass": "ok"}.get(o.verdict, "failed")
        block = [f'<div class="gate-exp"><h3>{escape(e.name)} <span class="badge {badge}">'
                 f'{o.verdict}</span></h3>'
                 f'<p class="note">{escape(r.renderer)} · {r.spp} spp · seed {r.seed}'
                 f'{f" · {r.time_s:.2f} s" if r.time_s else ""}</p>'
                 f'<table class="gate-checks"><thead><tr><th>check</th><th>result</th><th>detail</th></tr></thead>'
                 f'<tbody>{rows}</tbody></table>']
        if o.bias is not None:
            block.append(f'<div class="table-wrap">{bias_table_html(o.bias)}</div>')  # many regions: scrolls
        a = o.agreement
        if a is not None:
            failing = a.p_tiles < a.level
            block.append(
                f'<div class="gate-maps"><figure><img alt="|z| per tile" src="{z_map_png(a.z_tiles, failing)}">'
                f'<figcaption>|z| per {a.tile}×{a.tile}-pixel tile (0..{Z_MAX:g}, magma); failing tiles boxed'
                f'</figcaption></figure><figure>{p_histogram_svg(a.p_tiles, a.level)}'
                f'<figcaption>{a.tests} tests; per-test level {a.level:.2g}</figcaption></figure></div>')
        block.append("</div>")
        parts.append("".join(block))
    return "\n".join(parts)


def gate_index_html(scenes: list[tuple[str, str, bool]]) -> str:
    """A page linking each scene's gate report: (scene name, relative link, passed)."""
    items = "\n".join(f'<li><a href="{escape(link)}">{escape(name)}</a> — '
                       f'{"passed" if ok else "<strong>failed</strong>"}</li>' for name, link, ok in scenes)
    verdict = "passed" if all(ok for _, _, ok in scenes) else "failed"
    return (f'<!doctype html>\n<html lang="en"><head><meta charset="utf-8"><title>cbox gate: {verdict}</title>'
            f'</head>\n<body><h1>cbox gate: {verdict}</h1>\n<ul>\n{items}\n</ul>\n</body></html>\n')
