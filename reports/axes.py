"""The frame every report chart is drawn in: size and legend place (:class:`Layout`), log axes, ticks, legend.

:class:`Axes` maps values to a log-log plot area, draws its frame (clip path, grid, ticks, labels) and its
legend, and wraps the parts into one ``<svg>``; :mod:`reports.plots` draws the charts in it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from html import escape

from reports.plotmath import format_tick, log_ticks

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
    style: str = ""  # a stylesheet to embed: the SVG then stands alone (xmlns, its own background)
    width_in: float | None = None  # printed width of a standalone SVG


#: The report page's charts: the page's stylesheet themes them.
PAGE = Layout()



def color_for(index: int) -> str:
    return PALETTE[index % len(PALETTE)]


def num(v: float) -> str:
    return f"{v:.2f}".rstrip("0").rstrip(".")


def short(name: str, n: int = 20) -> str:
    return name if len(name) <= n else name[: n - 1] + "…"


# --------------------------------------------------------------------------
# Axes
# --------------------------------------------------------------------------


@dataclass
class Axes:
    xdom: tuple[float, float]
    ydom: tuple[float, float]
    layout: Layout = PAGE
    extra_bottom: int = 0  # more room below the plot (the bars' names)
    parts: list[str] = field(default_factory=list)
    legend_height: float = 0.0  # what a legend below the plot adds to the height

    def __post_init__(self) -> None:
        lay = self.layout
        self.width, self.height = lay.width, lay.height
        self.left, self.right, self.top, self.bottom = lay.left, lay.right, lay.top, lay.bottom + self.extra_bottom

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

    def frame(self, uid: str, xlabel: str, ylabel: str, xbase2: bool = False, xticks: bool = True) -> None:
        l, t, pw, ph = self.left, self.top, self.pw, self.ph
        self.parts.append(
            f'<clipPath id="{uid}-clip"><rect x="{l}" y="{t}" width="{num(pw)}" height="{num(ph)}"/></clipPath>'
        )
        # Fallback presentation attributes (a stylesheet overrides them) so that an SVG cut out of the page
        # shows its plot area, grid and axes without the page's stylesheet.
        self.parts.append(f'<rect class="plot-bg" x="{l}" y="{t}" width="{num(pw)}" height="{num(ph)}" fill="none"/>')
        if xticks:
            # as many ticks as labels of ~3.6 characters fit side by side: 9 on the page, fewer in print
            for v in log_ticks(*self.xdom, base2=xbase2, max_ticks=max(3, int(pw / (3.6 * self.layout.font)))):
                px = self.x(v)
                self.parts.append(
                    f'<line class="grid" x1="{num(px)}" y1="{t}" x2="{num(px)}" y2="{num(t + ph)}" stroke="#bbb"/>')
                self.parts.append(
                    f'<text class="tick x" x="{num(px)}" y="{num(t + ph + 16)}" text-anchor="middle">'
                    f"{escape(format_tick(v))}</text>"
                )
        for v in log_ticks(*self.ydom, max_ticks=7):
            py = self.y(v)
            self.parts.append(
                f'<line class="grid" x1="{l}" y1="{num(py)}" x2="{num(l + pw)}" y2="{num(py)}" stroke="#bbb"/>')
            self.parts.append(
                f'<text class="tick y" x="{l - 6}" y="{num(py + 4)}" text-anchor="end">{escape(format_tick(v))}</text>'
            )
        self.parts.append(
            f'<rect class="axis" x="{l}" y="{t}" width="{num(pw)}" height="{num(ph)}" fill="none" stroke="#888"/>')
        self.parts.append(
            f'<text class="label x" x="{num(l + pw / 2)}" y="{self.height - 12}" text-anchor="middle">'
            f"{escape(xlabel)}</text>"
        )
        self.parts.append(
            f'<text class="label y" transform="translate(16 {num(t + ph / 2)}) rotate(-90)" text-anchor="middle">'
            f"{escape(ylabel)}</text>"
        )

    def legend(self, entries: list[tuple[str, str, str]]) -> None:
        """entries: (kind, colour, label); kind is 'line', 'dash', 'band', 'whisker', 'dot', 'ring' or 'rect'.

        One per row right of the plot; or, with ``layout.legend_below``, in as many columns as fit under
        it, the chart growing to hold them: a standalone figure's legend is inside its viewBox.
        """
        lay = self.layout
        if lay.legend_below:
            col = 28 + 0.62 * lay.font * max((len(short(e[2], 22)) for e in entries), default=0) + 8
            cols = max(1, int((self.width - 8) // col))
            spots = [(8 + (i % cols) * col, self.height + 6 + (i // cols) * lay.legend_row)
                     for i in range(len(entries))]
            self.legend_height = spots[-1][1] + 10 - self.height if spots else 0.0
        else:
            spots = [(self.width - self.right + 14, self.top + 6 + i * lay.legend_row) for i in range(len(entries))]
        for (kind, color, label), (x0, y) in zip(entries, spots):
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
            else:
                self.parts.append(
                    f'<circle class="legend-mark" cx="{num(x0 + 11)}" cy="{num(y)}" r="4" fill="{color}"/>')
            title = f"<title>{escape(label)}</title>" if len(label) > 22 else ""
            self.parts.append(
                f'<text class="legend-label" x="{num(x0 + 28)}" y="{num(y + 4)}">'
                f"{title}{escape(short(label, 22))}</text>"
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
