"""Grouped bars on a log axis as inline SVG (the report's bias² and variance per renderer).

Drawn in the frame of :mod:`cornell_harness.reports.axes`, as the charts of :mod:`cornell_harness.reports.plots`
are. No text is cut and no two texts meet: a group's name wraps under its bars, names that do not wrap stand
vertical, and a group's note is a short mark just above its own bars, its meaning in the legend.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from html import escape
from typing import Sequence

from cornell_harness.reports.axes import PAGE, Axes as _Axes, Layout
from cornell_harness.reports.axes import ASCENT, CHAR_WIDTH as CHAR, DESCENT, LINE, Box, overlaps, text_box, text_lines
from cornell_harness.reports.axes import text_width, widest_piece, wrap
from cornell_harness.reports.axes import num as _f
from cornell_harness.reports.plotmath import log_domain
from cornell_harness.reports.plots import shown


@dataclass
class BarGroup:
    name: str
    values: list[float]  # one per bar kind
    note: str = ""  # a short mark above the group's bars ("n.s.", "91 %"); its meaning goes in the legend
    lo: list[float] | None = None  # each bar's 95% CI, drawn as an error bar where known
    hi: list[float] | None = None
    label: str = ""  # shown under the group instead of ``name`` (``data-renderer`` and tooltips keep the name)
    note_tip: str = ""  # the note in full, the mark's tooltip


def bars_svg(
    groups: Sequence[BarGroup],
    kinds: Sequence[tuple[str, str]],
    *,
    uid: str,
    ylabel: str,
    extra_attrs: str = "",
    layout: Layout = PAGE,
    note_key: Sequence[str] = (),
) -> str:
    """Grouped bars on a log y axis; ``kinds`` = (label, colour) of each bar in a group.

    A value that is not positive (a bias² estimate below zero: no measurable
    bias; see :func:`cornell_harness.reports.numbers.format_value`) or not finite gets no bar but a small "≈ 0" or "n/a" mark.
    A group's ``lo`` / ``hi`` draw error bars (``class="whisker"``), from the axis where the low end is not
    positive. Each group's name is under it in full (:func:`bar_names`); its note is a short mark just above
    its own bars, centred on them (:func:`place_notes`), and ``note_key`` (what the marks mean) ends the legend.
    The y axis keeps a row of room over the tallest noted group, so its mark stays inside the plot.
    """
    vals = [v for g in groups for v in (*g.values, *(g.hi or ()))]
    ydom = log_domain(vals, pad=0.1)
    if ydom is None or not groups:
        return '<p class="note">No positive values to plot.</p>'
    ydom = (ydom[0] - 0.15 * (ydom[1] - ydom[0]), ydom[1])  # room below the smallest bar
    font, step = layout.font, LINE * layout.font
    n, k = len(groups), len(kinds)
    # Marks stand upright where one is wider than its group's share of the plot (at most that wide: the axes
    # below only widen the left margin); the y axis leaves room for one over the tallest noted group.
    notes = [g.note for g in groups]
    upright = any(text_width(t, font) > (layout.width - layout.left - layout.right) / n - 0.6 * font for t in notes)
    tall = max((text_width(t, font) if upright else (ASCENT + DESCENT) * font for t in notes if t), default=0.0)
    head = (tall + 5) / (layout.height - layout.top - layout.bottom)  # the plot's height, which stays
    for g in groups:
        top = max(_positive([*g.values, *(g.hi or ())]), default=None)
        if g.note and top is not None and head < 0.5:
            ydom = (ydom[0], max(ydom[1], ydom[0] + (math.log10(top) - ydom[0]) / (1 - head)))
    bars = any(g.hi is not None for g in groups)
    ax = _Axes((0.0, 1.0), ydom, layout,
               [("rect", color, label) for label, color in kinds] + ([("whisker", "#555", "95% CI")] if bars else [])
               + [("note", "", key) for key in note_key])
    slot = ax.pw / n
    centres = [ax.left + slot * (gi + 0.5) for gi in range(n)]
    names, vertical, name_depth = bar_names([shown(g) for g in groups], slot, font)
    name_depth = max(0.0, name_depth - layout.bottom)  # the bottom margin has room for an axis label
    ax.height += name_depth
    ax.bottom += name_depth
    bw = min(34.0, 0.75 * slot / k)
    drawn = [_group_parts(ax, g, kinds, centres[gi] - bw * k / 2, bw, step)[1] for gi, g in enumerate(groups)]
    spots = place_notes(notes, centres, drawn, ax.top, font, upright)
    lift = max(0.0, 2 - min((box[1] for box in spots if box), default=2))
    ax.top += lift  # marks that had to go above the plot: the chart grows to hold them
    ax.height += lift
    ax.frame(uid, "", ylabel, xticks=False)
    base = ax.top + ax.ph
    for gi, g in enumerate(groups):
        cx = centres[gi]
        ax.parts += _group_parts(ax, g, kinds, cx - bw * k / 2, bw, step)[0]
        if spots[gi] is not None:
            ax.parts.append(_note_text(g, spots[gi], lift, font, upright))
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


def _positive(vals) -> list[float]:
    return [v for v in vals if v is not None and math.isfinite(v) and v > 0]


def _group_parts(ax: _Axes, g: BarGroup, kinds: Sequence[tuple[str, str]], x0: float, bw: float, step: float
                 ) -> tuple[list[str], list[Box]]:
    """One group's bars, error bars and "≈ 0" / "n/a" marks from ``x0``: their SVG and their boxes."""
    font, base = ax.layout.font, ax.top + ax.ph
    parts: list[str] = []
    boxes: list[Box] = []
    missing = 0
    for bi, ((label, color), v) in enumerate(zip(kinds, g.values)):
        bx = x0 + bi * bw
        if _positive([v]):
            top = ax.y(v)
            boxes.append((bx + 1, top, bx + bw - 1, base))
            parts.append(
                f'<rect class="bar" data-renderer="{escape(g.name)}" data-kind="{escape(label)}" '
                f'x="{_f(bx + 1)}" y="{_f(top)}" width="{_f(bw - 2)}" height="{_f(base - top)}" fill="{color}">'
                f"<title>{escape(g.name)}: {escape(label)} = {v:.3e}</title></rect>"
            )
        hi = g.hi[bi] if g.hi is not None else None
        if not _positive([v]) and not _positive([hi]):  # no bar and no error bar from the axis: say why
            mark = "n/a" if v is None or not math.isfinite(v) else ("0" if v == 0 else "≈ 0")
            # marks of neighbouring bars wider than a bar go one above the other
            lift = missing * step if missing and text_width(mark, font) > bw - 2 else 0
            missing += 1
            boxes.append(text_box(bx + bw / 2, base - 6 - lift, mark, font, "middle"))
            parts.append(
                f'<text class="bar-missing" data-renderer="{escape(g.name)}" x="{_f(bx + bw / 2)}" y="{_f(base - 6 - lift)}" '
                f'text-anchor="middle">{mark}<title>{escape(g.name)}: {escape(label)} = {escape(str(v))}</title>'
                "</text>"
            )
        if _positive([hi]):
            lo = g.lo[bi] if g.lo is not None else None
            y_lo = ax.y(lo) if _positive([lo]) else base
            y_hi, mx = ax.y(hi), bx + bw / 2
            boxes.append((mx - 3, y_hi, mx + 3, y_lo))
            parts.append(
                f'<path class="whisker" data-renderer="{escape(g.name)}" data-kind="{escape(label)}" '
                f'd="M {_f(mx)} {_f(y_lo)} L {_f(mx)} {_f(y_hi)} M {_f(mx - 3)} {_f(y_hi)} L {_f(mx + 3)} '
                f'{_f(y_hi)}" stroke="#555" stroke-width="1.2" fill="none"/>')
    return parts, boxes


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


def place_notes(notes: Sequence[str], centres: Sequence[float], drawn: Sequence[Sequence[Box]], top: float,
                font: float, upright: bool = False) -> list[Box | None]:
    """Each group's note mark's box, or None where it has none: centred on its group, just above the group's
    highest bar, error bar or mark (``drawn``: each group's boxes), read across or, ``upright``, bottom to top;
    lifted a row at a time while it meets another group's boxes or a mark placed before it. A mark that would
    cross the plot's top edge (``top``) goes above it; the caller grows the chart to hold one above its top
    margin."""
    step, gap = LINE * font, 1.0
    placed: list[Box] = []
    out: list[Box | None] = []
    for gi, (note, cx, boxes) in enumerate(zip(notes, centres, drawn)):
        others = [b for j, bs in enumerate(drawn) if j != gi for b in bs]
        if not note:
            out.append(None)
            continue
        w = text_width(note, font)
        across, up = ((cx - w / 2, cx + w / 2), (ASCENT + DESCENT) * font) if not upright else \
            ((cx - 0.6 * font, cx + 0.6 * font), w)  # upright: its baseline 0.35 font right of the centre
        bottom = min((b[1] for b in boxes), default=top) - 3
        while True:
            box = (across[0], bottom - up, across[1], bottom)
            if box[1] < top + 1 < box[3] + 2:  # across the plot's top edge: above it
                bottom = top - 2
                continue
            if not any(overlaps(box, b, gap) for b in placed + others):
                break
            bottom -= step
        placed.append(box)
        out.append(box)
    return out


def _note_text(g: BarGroup, box: Box, lift: float, font: float, upright: bool) -> str:
    """A group's note mark in its box (:func:`place_notes`), ``lift`` lower down the chart; its tooltip in full."""
    tip = f"<title>{escape(g.name)}: {escape(g.note_tip or g.note)}</title>"
    head = f'<text class="bar-note" data-renderer="{escape(g.name)}"'
    if upright:
        return (f'{head} x="0" y="0" text-anchor="start" transform="translate({_f(box[0] + ASCENT * font)} '
                f'{_f(box[3] + lift)}) rotate(-90)">{escape(g.note)}{tip}</text>')
    return (f'{head} x="{_f((box[0] + box[2]) / 2)}" y="{_f(box[3] - DESCENT * font + lift)}" '
            f'text-anchor="middle">{escape(g.note)}{tip}</text>')
