"""Grouped bars on a log axis as inline SVG (the report's bias² and variance per renderer).

Drawn in the frame of :mod:`cornell_harness.reports.axes`, as the charts of :mod:`cornell_harness.reports.plots`
are. No text is cut and no two texts meet: a group's name wraps under its bars, names that do not wrap stand
vertical, and the notes above the groups take rows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from html import escape
from typing import Sequence

from cornell_harness.reports.axes import PAGE, Axes as _Axes, Layout
from cornell_harness.reports.axes import ASCENT, CHAR_WIDTH as CHAR, DESCENT, LINE, text_lines, text_width, widest_piece, wrap
from cornell_harness.reports.axes import num as _f
from cornell_harness.reports.plotmath import log_domain
from cornell_harness.reports.plots import shown


@dataclass
class BarGroup:
    name: str
    values: list[float]  # one per bar kind
    note: str = ""  # text above the group
    lo: list[float] | None = None  # each bar's 95% CI, drawn as an error bar where known
    hi: list[float] | None = None
    label: str = ""  # shown under the group instead of ``name`` (``data-renderer`` and tooltips keep the name)


def bars_svg(
    groups: Sequence[BarGroup],
    kinds: Sequence[tuple[str, str]],
    *,
    uid: str,
    ylabel: str,
    extra_attrs: str = "",
    layout: Layout = PAGE,
) -> str:
    """Grouped bars on a log y axis; ``kinds`` = (label, colour) of each bar in a group.

    A value that is not positive (a bias² estimate below zero: no measurable
    bias; see :func:`cornell_harness.reports.numbers.format_value`) or not finite gets no bar but a small "≈ 0" or "n/a" mark.
    A group's ``lo`` / ``hi`` draw error bars (``class="whisker"``), from the axis where the low end is not
    positive. Each group's name is under it in full (:func:`bar_names`), its note above the plot, in as many
    rows as keep neighbouring notes apart (:func:`note_rows`); the chart grows to hold both.
    """
    vals = [v for g in groups for v in (*g.values, *(g.hi or ()))]
    ydom = log_domain(vals, pad=0.1)
    if ydom is None or not groups:
        return '<p class="note">No positive values to plot.</p>'
    ydom = (ydom[0] - 0.15 * (ydom[1] - ydom[0]), ydom[1])  # room below the smallest bar
    bars = any(g.hi is not None for g in groups)
    ax = _Axes((0.0, 1.0), ydom, layout,
               [("rect", color, label) for label, color in kinds] + ([("whisker", "#555", "95% CI")] if bars else []))
    font, step = layout.font, LINE * layout.font
    n, k = len(groups), len(kinds)
    slot = ax.pw / n
    centres = [ax.left + slot * (gi + 0.5) for gi in range(n)]
    names, vertical, name_depth = bar_names([shown(g) for g in groups], slot, font)
    name_depth = max(0.0, name_depth - layout.bottom)  # the bottom margin has room for an axis label
    notes, note_height = note_rows([g.note for g in groups], centres, (ax.left, ax.left + ax.pw), font)
    ax.top += note_height
    ax.height += note_height + name_depth
    ax.bottom += name_depth
    ax.frame(uid, "", ylabel, xticks=False)
    bw = min(34.0, 0.75 * slot / k)
    base = ax.top + ax.ph
    for gi, g in enumerate(groups):
        cx = centres[gi]
        x0 = cx - bw * k / 2
        missing = 0
        for bi, ((label, color), v) in enumerate(zip(kinds, g.values)):
            bx = x0 + bi * bw
            if v is not None and math.isfinite(v) and v > 0:
                top = ax.y(v)
                ax.parts.append(
                    f'<rect class="bar" data-renderer="{escape(g.name)}" data-kind="{escape(label)}" '
                    f'x="{_f(bx + 1)}" y="{_f(top)}" width="{_f(bw - 2)}" height="{_f(base - top)}" fill="{color}">'
                    f"<title>{escape(g.name)}: {escape(label)} = {v:.3e}</title></rect>"
                )
            hi = g.hi[bi] if g.hi is not None else None
            if not (v is not None and math.isfinite(v) and v > 0 or hi is not None and math.isfinite(hi) and hi > 0):
                # no bar and no error bar from the axis: say why
                mark = "n/a" if v is None or not math.isfinite(v) else ("0" if v == 0 else "≈ 0")
                # marks of neighbouring bars wider than a bar go one above the other
                lift = missing * step if missing and text_width(mark, font) > bw - 2 else 0
                missing += 1
                ax.parts.append(
                    f'<text class="bar-missing" x="{_f(bx + bw / 2)}" y="{_f(base - 6 - lift)}" '
                    f'text-anchor="middle">{mark}<title>{escape(g.name)}: {escape(label)} = {escape(str(v))}</title>'
                    "</text>"
                )
            if hi is not None and math.isfinite(hi) and hi > 0:
                lo = g.lo[bi] if g.lo is not None else None
                y_lo = ax.y(lo) if lo is not None and math.isfinite(lo) and lo > 0 else base
                y_hi, mx = ax.y(hi), bx + bw / 2
                ax.parts.append(
                    f'<path class="whisker" data-renderer="{escape(g.name)}" data-kind="{escape(label)}" '
                    f'd="M {_f(mx)} {_f(y_lo)} L {_f(mx)} {_f(y_hi)} M {_f(mx - 3)} {_f(y_hi)} L {_f(mx + 3)} '
                    f'{_f(y_hi)}" stroke="#555" stroke-width="1.2" fill="none"/>')
        if notes[gi] is not None:
            nx, ny, lines = notes[gi]
            ax.parts.append(f'<text class="bar-note" data-renderer="{escape(g.name)}" x="{_f(nx)}" '
                            f'y="{_f(layout.top + ny)}" text-anchor="middle">{text_lines(lines, nx, font)}</text>')
        lines = names[gi]
        if vertical:  # read bottom to top, ending under the group; lines side by side, centred on it
            first = cx + 0.35 * font - (len(lines) - 1) * step / 2
            ax.parts.append(
                f'<text class="tick x" data-renderer="{escape(g.name)}" x="0" y="0" text-anchor="end" '
                f'transform="translate({_f(first)} {_f(base + 8)}) rotate(-90)"><title>{escape(g.name)}</title>'
                f"{text_lines(lines, 0, font)}</text>")
        else:
            ax.parts.append(
                f'<text class="tick x" data-renderer="{escape(g.name)}" x="{_f(cx)}" y="{_f(base + 18)}" '
                f'text-anchor="middle"><title>{escape(g.name)}</title>{text_lines(lines, cx, font)}</text>')
    ax.legend()
    return ax.svg(uid, "bar-plot", ylabel, extra_attrs)


#: At most this many lines of a group's name under its bars before the names turn vertical.
NAME_LINES = 3


def bar_names(names: Sequence[str], slot: float, font: float) -> tuple[list[list[str]], bool, float]:
    """Each group's name in lines, whether they stand vertical, and how far below the plot they reach.

    Horizontal where every name wraps (at its break characters, not within a word) into at most
    :data:`NAME_LINES` lines of its ``slot``'s width; otherwise vertical, each in as few lines side by side as
    the slot holds, as short as that allows. Never cut."""
    step, room = LINE * font, slot - 0.6 * font
    if all(widest_piece(t, font) <= room and len(wrap(t, room, font)) <= NAME_LINES for t in names):
        lines = [wrap(t, room, font) for t in names]
        return lines, False, 18 + (max(map(len, lines)) - 1) * step + DESCENT * font + 6
    most = max(1, int((slot - 0.3 * font - (ASCENT + DESCENT) * font) / step) + 1)  # lines across a slot
    lines = []
    for t in names:
        width = widest_piece(t, font)
        while len(wrap(t, width, font)) > most:
            width += CHAR * font
        lines.append(wrap(t, width, font))
    longest = max(text_width(line, font) for ls in lines for line in ls)
    return lines, True, 8 + longest + 6


def note_rows(notes: Sequence[str], centres: Sequence[float], span: tuple[float, float], font: float
              ) -> tuple[list[tuple[float, float, list[str]] | None], float]:
    """Each group's note as (x, baseline below the chart's top margin, lines), and the height they take above
    the plot. Notes take the first row where they meet no other note (first fit), so neighbouring notes never
    run together; each on one line, or, where that takes less height, those too wide for their share of the
    width on two."""
    step, gap = LINE * font, 0.8 * font
    slot = (span[1] - span[0]) / max(1, len(notes))
    best = None
    for split in (False, True):
        rows: list[list[tuple[float, float]]] = []  # per row, the x extents of its notes
        heights: list[int] = []  # per row, its lines
        spots: list[tuple[float, int, list[str]] | None] = []
        for note, cx in zip(notes, centres):
            if not note:
                spots.append(None)
                continue
            lines = [note]
            if split and text_width(note, font) > slot - gap and " " in note:
                cut = min((i for i, ch in enumerate(note) if ch == " "), key=lambda i: abs(2 * i - len(note)))
                lines = [note[:cut + 1], note[cut + 1:]]
            w = max(text_width(line, font) for line in lines)
            x = min(max(cx, span[0] + w / 2 + 2), span[1] - w / 2 - 2)  # inside the plot's width
            extent = (x - w / 2, x + w / 2)
            r = next((r for r, row in enumerate(rows)
                      if all(extent[0] >= b + gap or extent[1] + gap <= a for a, b in row)), len(rows))
            if r == len(rows):
                rows.append([])
                heights.append(0)
            rows[r].append(extent)
            heights[r] = max(heights[r], len(lines))
            spots.append((x, r, lines))
        if best is None or sum(heights) < best[0]:
            best = (sum(heights), heights, spots)
    total, heights, spots = best
    tops = [sum(heights[:r]) * step for r in range(len(heights))]
    out = [None if s is None else (s[0], tops[s[1]] + ASCENT * font + 2, s[2]) for s in spots]
    return out, (total * step + 6 if total else 0.0)
