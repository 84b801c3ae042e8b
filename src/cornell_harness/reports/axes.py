"""The frame every report chart is drawn in: size and legend place (:class:`Layout`), log axes, ticks, legend;
and the one estimate of how much room a text takes (:func:`text_width`, :func:`text_box`, :func:`wrap`).

:class:`Axes` maps values to a log-log plot area, draws its frame (clip path, grid, ticks, labels) and its
legend, and wraps the parts into one ``<svg>``; :mod:`cornell_harness.reports.plots` draws the charts in it. Text is placed
by the estimate, so no text is cut and none meets another: tick labels are thinned until they keep apart,
legends wrap and the chart grows to hold them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from html import escape

from cornell_harness.reports.plotmath import format_tick, log_ticks

#: Okabe & Ito (2008) colour-blind-safe palette, then Tableau's for more renderers.
PALETTE = (
    "#56b4e9", "#e69f00", "#009e73", "#f0e442", "#cc79a7", "#d55e00", "#0072b2",
    "#9aa1ad", "#8c564b", "#bcbd22", "#17becf", "#e377c2",
)


@dataclass(frozen=True)
class Layout:
    """A chart's size (viewBox units), margins, text size and legend place; with a ``style``, standalone."""

    width: int = 640
    height: int = 400  # without a legend below the plot, which adds to it
    left: int = 70
    right: int = 180  # the legend's column, unless it is below
    top: int = 30
    bottom: int = 52
    font: float = 11.5  # size of tick and legend text: to estimate how wide a label is
    legend_row: float = 19
    legend_below: bool = False
    label_font: float = 12.5  # size of the axes' labels (the page's stylesheet: 12.5 px)
    style: str = ""  # a stylesheet to embed: the SVG then stands alone (xmlns, its own background)
    width_in: float | None = None  # printed width of a standalone SVG


#: The report page's charts: the page's stylesheet themes them.
PAGE = Layout()



#: Where the y axis' label is (its baseline, rotated), from the left edge.
YLABEL_X = 16
#: A legend label starts this far right of its mark's left end.
LEGEND_TEXT_X = 28
#: A legend right of the plot is at most this share of the chart's width wide; longer labels wrap.
LEGEND_MAX = 0.45


def _spaced(ticks_for, most: int, boxes) -> list[float]:
    """The ticks ``ticks_for(m)`` for the largest ``m <= most`` whose labels' ``boxes`` do not meet."""
    for m in range(most, 1, -1):
        ticks = ticks_for(m)
        bs = boxes(ticks)
        if not any(overlaps(a, b, gap=2) for i, a in enumerate(bs) for b in bs[i + 1:]):
            return ticks
    return ticks_for(2)


def color_for(index: int) -> str:
    return PALETTE[index % len(PALETTE)]


def num(v: float) -> str:
    return f"{v:.2f}".rstrip("0").rstrip(".")


# --------------------------------------------------------------------------
# Text boxes: every chart places its text by these estimates, so no two texts meet
# --------------------------------------------------------------------------

#: A character's estimated width, in font sizes: above the mean of DejaVu Sans and Helvetica (about 0.55), so
#: an estimated box holds the drawn text.
CHAR_WIDTH = 0.62
#: A text's box above and below its baseline, in font sizes (DejaVu Sans: 0.93 and 0.24, Helvetica less).
ASCENT, DESCENT = 0.95, 0.25
#: Baseline to baseline of wrapped lines, in font sizes: more than a box's height, so lines do not meet.
LINE = 1.25
#: Where a label may break: after these characters (and a space, which stays at the end of its line).
_BREAK_AFTER = ",[( -"

Box = tuple[float, float, float, float]  # x0, y0, x1, y1


def text_width(text: str, font: float) -> float:
    """Estimated width of ``text`` at font size ``font`` (a trailing space is not counted)."""
    return CHAR_WIDTH * font * len(text.rstrip(" "))


def text_box(x: float, y: float, text: str, font: float, anchor: str = "start", lines: int = 1) -> Box:
    """Estimated box of ``text`` (its widest line) with its first baseline at ``y``, anchored at ``x``."""
    w = text_width(text, font)
    x0 = x - {"start": 0.0, "middle": w / 2, "end": w}[anchor]
    return x0, y - ASCENT * font, x0 + w, y + DESCENT * font + (lines - 1) * LINE * font


def overlaps(a: Box, b: Box, gap: float = 0.0) -> bool:
    """True when boxes ``a`` and ``b`` come closer than ``gap``."""
    return a[0] < b[2] + gap and b[0] < a[2] + gap and a[1] < b[3] + gap and b[1] < a[3] + gap


def pieces(text: str) -> list[str]:
    """``text`` cut after each break character (``pathtracer[`` ``sampler="independent",`` ``rr_depth=3]``)."""
    out, cur = [], ""
    for ch in text:
        cur += ch
        if ch in _BREAK_AFTER:
            out.append(cur)
            cur = ""
    return out + ([cur] if cur else [])


def widest_piece(text: str, font: float) -> float:
    return max((text_width(p, font) for p in pieces(text)), default=0.0)


def wrap(text: str, width: float, font: float) -> list[str]:
    """``text`` in lines no wider than ``width``, broken at :data:`_BREAK_AFTER` characters; a piece wider than
    ``width`` alone is cut where it must be. Joined, the lines are ``text`` again."""
    per_line = max(1, int(width / (CHAR_WIDTH * font)))
    lines: list[str] = []
    cur = ""
    for piece in pieces(text):
        if text_width(cur + piece, font) <= width:
            cur += piece
            continue
        if cur:
            lines.append(cur)
        while text_width(piece, font) > width:
            lines.append(piece[:per_line])
            piece = piece[per_line:]
        cur = piece
    return lines + ([cur] if cur else []) or [""]


def text_lines(lines: list[str], x: float, font: float) -> str:
    """The inside of a ``<text>`` element: its one line, or a ``<tspan>`` per line, each :data:`LINE` below."""
    if len(lines) == 1:
        return escape(lines[0])
    return "".join(f'<tspan x="{num(x)}" dy="{0 if i == 0 else num(LINE * font)}">{escape(line)}</tspan>'
                   for i, line in enumerate(lines))


# --------------------------------------------------------------------------
# Axes
# --------------------------------------------------------------------------


@dataclass
class Axes:
    """A log-log plot area of ``layout``'s size, its frame and its legend (``entries``: (kind, colour, label);
    kind is 'line', 'dash', 'band', 'whisker', 'dot', 'ring', 'rect', 'arrow' (a censored point's), or 'note': a
    line of text with no mark, such as what the notes on a chart mean).

    Text is never cut: the left margin holds the widest y tick label, a legend at the right is as wide as its
    longest label needs (the figure growing), wrapped where a label is longer still; a legend below wraps and
    takes as many columns as keep it shortest. A chart may grow ``top`` and ``height`` before :meth:`frame`
    for text of its own above or below the plot (:func:`cornell_harness.reports.bars.bars_svg`).
    """

    xdom: tuple[float, float]
    ydom: tuple[float, float]
    layout: Layout = PAGE
    entries: list[tuple[str, str, str]] = field(default_factory=list)
    parts: list[str] = field(default_factory=list)
    legend_height: float = 0.0  # what the legend adds below the plot's height

    def __post_init__(self) -> None:
        lay, font = self.layout, self.layout.font
        self.top, self.bottom, self.height = lay.top, lay.bottom, lay.height
        self.yticks = _spaced(lambda m: log_ticks(*self.ydom, max_ticks=m), 7, self._ytick_boxes)
        widest = max((text_width(format_tick(v), font) for v in self.yticks), default=0.0)
        # the y label's box (rotated: its height across), a gap, the tick labels, the tick gap
        self.left = max(lay.left, math.ceil(YLABEL_X + DESCENT * lay.label_font + 4 + widest + 6))
        self.right = lay.right
        self.legend_lines = [[label] for _, _, label in self.entries]
        if self.entries and not lay.legend_below:
            room = lay.right - 14 - LEGEND_TEXT_X - 6  # the column's room for text
            longest = max(widest_piece(label, font) for _, _, label in self.entries)
            room = max(room, min(longest, LEGEND_MAX * lay.width))
            self.legend_lines = [wrap(label, room, font) for _, _, label in self.entries]
            used = max(text_width(line, font) for lines in self.legend_lines for line in lines)
            self.right = max(lay.right, math.ceil(14 + LEGEND_TEXT_X + used + 6))
        self.width = lay.width + self.right - lay.right

    @property
    def pw(self) -> float:
        return self.width - self.left - self.right

    @property
    def ph(self) -> float:
        return self.height - self.top - self.bottom

    def x(self, v: float) -> float:
        return self.left + (math.log10(v) - self.xdom[0]) / (self.xdom[1] - self.xdom[0]) * self.pw

    def y(self, v: float) -> float:
        return self.top + (1 - (math.log10(v) - self.ydom[0]) / (self.ydom[1] - self.ydom[0])) * self.ph

    def _ytick_boxes(self, ticks: list[float]) -> list[Box]:
        return [text_box(self.layout.left - 6, self.y(v) + 4, format_tick(v), self.layout.font, "end")
                for v in ticks]

    def _xtick_boxes(self, ticks: list[float]) -> list[Box]:
        return [text_box(self.x(v), self.top + self.ph + 16, format_tick(v), self.layout.font, "middle")
                for v in ticks]

    def frame(self, uid: str, xlabel: str, ylabel: str, xbase2: bool = False, xticks: bool = True) -> None:
        l, t, pw, ph = self.left, self.top, self.pw, self.ph
        self.parts.append(
            f'<clipPath id="{uid}-clip"><rect x="{l}" y="{num(t)}" width="{num(pw)}" height="{num(ph)}"/></clipPath>'
        )
        # Fallback presentation attributes (a stylesheet overrides them) so that an SVG cut out of the page
        # shows its plot area, grid and axes without the page's stylesheet.
        self.parts.append(
            f'<rect class="plot-bg" x="{l}" y="{num(t)}" width="{num(pw)}" height="{num(ph)}" fill="none"/>')
        font, below = self.layout.font, t + ph + 16
        # as many x ticks as labels of ~3.6 characters fit side by side (9 on the page, fewer in print), fewer
        # where the labels would still meet
        most = max(3, int(pw / (3.6 * font)))
        xs = _spaced(lambda m: log_ticks(*self.xdom, base2=xbase2, max_ticks=m), most, self._xtick_boxes) \
            if xticks else []
        labelled: list[Box] = []
        for v in xs:
            px = self.x(v)
            self.parts.append(
                f'<line class="grid" x1="{num(px)}" y1="{num(t)}" x2="{num(px)}" y2="{num(t + ph)}" stroke="#bbb"/>')
            box = text_box(px, below, format_tick(v), font, "middle")
            if 0 <= box[0] and box[2] <= self.width:  # a label that would leave the chart is left out
                labelled.append(box)
                self.parts.append(f'<text class="tick x" x="{num(px)}" y="{num(below)}" text-anchor="middle">'
                                  f"{escape(format_tick(v))}</text>")
        for v in self.yticks:
            py = self.y(v)
            self.parts.append(
                f'<line class="grid" x1="{l}" y1="{num(py)}" x2="{num(l + pw)}" y2="{num(py)}" stroke="#bbb"/>')
            if not any(overlaps(text_box(l - 6, py + 4, format_tick(v), font, "end"), b) for b in labelled):
                self.parts.append(f'<text class="tick y" x="{l - 6}" y="{num(py + 4)}" text-anchor="end">'
                                  f"{escape(format_tick(v))}</text>")
        self.parts.append(
            f'<rect class="axis" x="{l}" y="{num(t)}" width="{num(pw)}" height="{num(ph)}" fill="none" stroke="#888"/>')
        if xlabel:
            self.parts.append(
                f'<text class="label x" x="{num(l + pw / 2)}" y="{num(self.height - 12)}" text-anchor="middle">'
                f"{escape(xlabel)}</text>"
            )
        self.parts.append(
            f'<text class="label y" transform="translate({YLABEL_X} {num(t + ph / 2)}) rotate(-90)" '
            f'text-anchor="middle">{escape(ylabel)}</text>'
        )

    def _legend_spots(self) -> list[tuple[float, float]]:
        """Where each entry's mark goes (its label's first baseline is 4 below); sets ``legend_height``."""
        lay, font, n = self.layout, self.layout.font, len(self.entries)
        if not n:
            return []
        step = LINE * font
        if not lay.legend_below:
            spots, y = [], self.top + 6
            for lines in self.legend_lines:
                spots.append((self.width - self.right + 14, y))
                y += lay.legend_row + (len(lines) - 1) * step
            bottom = spots[-1][1] + 4 + (len(self.legend_lines[-1]) - 1) * step + DESCENT * font + 4
            self.legend_height = max(0.0, bottom - self.height)
            return spots
        best = None
        avail = self.width - 16
        for cols in range(1, n + 1):
            room = avail / cols - LEGEND_TEXT_X - 8
            labels = [label for _, _, label in self.entries]
            if cols > 1 and (room < 4 * CHAR_WIDTH * font or max(widest_piece(t, font) for t in labels) > room):
                break
            lines = [wrap(t, room, font) for t in labels]
            rows = [max(len(ls) for ls in lines[r:r + cols]) for r in range(0, n, cols)]
            height = sum(lay.legend_row + (k - 1) * step for k in rows)
            if best is None or height < best[0]:
                best = (height, cols, lines, rows)
        _, cols, self.legend_lines, rows = best
        colw, spots, y = avail / cols, [], self.height + 6
        for r, k in enumerate(rows):
            spots += [(8 + c * colw, y) for c in range(min(cols, n - r * cols))]
            y += lay.legend_row + (k - 1) * step
        self.legend_height = spots[-1][1] + 10 + (rows[-1] - 1) * step - self.height
        return spots

    def legend(self) -> None:
        """The legend of ``entries``: right of the plot, one per row, or with ``layout.legend_below`` in columns
        under it, the chart growing to hold it (a standalone figure's legend is inside its viewBox)."""
        spots = self._legend_spots()  # first: it wraps the labels of a legend below
        for (kind, color, label), lines, (x0, y) in zip(self.entries, self.legend_lines, spots):
            x1 = num(x0 + 22)
            if kind in ("line", "dash"):
                # the dashed entry is the slope guide: its class lets a theme colour it as the guide
                dash = ' stroke-dasharray="6 4"' if kind == "dash" else ""
                self.parts.append(
                    f'<line class="legend-mark{" guide-mark" if dash else ""}" x1="{num(x0)}" y1="{num(y)}" x2="{x1}" '
                    f'y2="{num(y)}" stroke="{color}" stroke-width="2.5"{dash}/>'
                )
            elif kind == "band":
                self.parts.append(
                    f'<rect class="legend-mark" x="{num(x0)}" y="{num(y - 5)}" width="22" height="10" '
                    f'fill="{color}" fill-opacity="0.25"/>'
                )
            elif kind == "whisker":
                self.parts.append(
                    f'<path class="legend-mark whisker-mark" d="M {num(x0 + 2)} {num(y)} L {num(x0 + 20)} {num(y)} '
                    f'M {num(x0 + 2)} {num(y - 4)} L {num(x0 + 2)} {num(y + 4)} M {num(x0 + 20)} {num(y - 4)} '
                    f'L {num(x0 + 20)} {num(y + 4)}" stroke="{color}" stroke-width="1.4" fill="none"/>'
                )
            elif kind == "rect":
                self.parts.append(
                    f'<rect class="legend-mark" x="{num(x0 + 5)}" y="{num(y - 6)}" width="12" height="12" '
                    f'fill="{color}"/>'
                )
            elif kind == "ring":
                self.parts.append(
                    f'<line class="legend-mark frontier-mark" x1="{num(x0)}" y1="{num(y)}" x2="{x1}" y2="{num(y)}" '
                    f'stroke="{color}" stroke-width="6" stroke-opacity="0.45" stroke-linecap="round"/>'
                )
            elif kind == "dot":
                self.parts.append(
                    f'<circle class="legend-mark" cx="{num(x0 + 11)}" cy="{num(y)}" r="4" fill="{color}"/>')
            elif kind == "arrow":
                self.parts.append(
                    f'<path class="legend-mark censored-mark" d="M {num(x0 + 2)} {num(y)} L {num(x0 + 15)} {num(y)}" '
                    f'stroke="{color}" stroke-width="1.4" stroke-dasharray="4 3" fill="none"/>'
                    f'<path class="legend-mark censored-mark" d="M {num(x0 + 14)} {num(y - 5)} L {num(x0 + 21)} '
                    f'{num(y)} L {num(x0 + 14)} {num(y + 5)} Z" fill="{color}"/>')
            tx = x0 + (LEGEND_TEXT_X if kind != "note" else 0)  # a line of text alone starts where marks do
            self.parts.append(
                f'<text class="legend-label" x="{num(tx)}" y="{num(y + 4)}">'
                f"{text_lines(lines, tx, self.layout.font)}</text>"
            )

    def svg(self, uid: str, cls: str, aria: str, extra_attrs: str = "") -> str:
        lay, h = self.layout, self.height + self.legend_height
        own = ""
        if lay.style:  # standalone: namespaced, sized for print, its own stylesheet and a light background
            size = f' width="{lay.width_in:g}in" height="{lay.width_in * h / self.width:.3f}in"' if lay.width_in else ""
            extra_attrs = f' xmlns="http://www.w3.org/2000/svg"{size}{extra_attrs}'
            own = (f'<style>{lay.style}</style>'
                   f'<rect class="figure-bg" width="{self.width}" height="{num(h)}" fill="#fff"/>')
        return (
            f'<svg id="{uid}" class="chart {cls}" viewBox="0 0 {self.width} {num(h)}" role="img" '
            f'aria-label="{escape(aria)}" font-family="sans-serif" font-size="{lay.font:g}"{extra_attrs}>'
            + own
            + "".join(self.parts)
            + "</svg>"
        )
