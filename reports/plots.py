"""Small, dependency-free SVG charts for the HTML report.

Every chart is a string of inline SVG, drawn here from numbers so the report
needs no plotting library and no script to show them. Classes (``series``,
``band``, ``guide``, ``frontier``, ``bar``...) carry the meaning, so the report's
stylesheet themes them and tests can find them; colours of series are
presentation attributes. A :class:`Layout` says how big a chart is and where
its legend goes: :data:`PAGE` for the report, styled by the page; one with a
``style`` of its own makes a standalone SVG (:mod:`reports.figures`).

- :func:`line_plot_svg`: log-log error curves, one line per renderer with a
  min–max band across seeds and an optional slope guide (convergence plots);
- :func:`scatter_svg`: log-log speed/accuracy points with the Pareto frontier;
- :func:`bars_svg`: grouped bars on a log axis (bias² and variance);
- the numbers behind them (ticks, domains, the Pareto front) are :mod:`reports.plotmath`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from html import escape
from typing import Sequence

from reports.plotmath import format_tick, log_domain, log_ticks, pareto_front

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

#: The slope guide starts this factor above the highest first point.
GUIDE_OFFSET = 1.5


def color_for(index: int) -> str:
    return PALETTE[index % len(PALETTE)]


def _f(v: float) -> str:
    return f"{v:.2f}".rstrip("0").rstrip(".")


def _short(name: str, n: int = 20) -> str:
    return name if len(name) <= n else name[: n - 1] + "…"


# --------------------------------------------------------------------------
# Axes
# --------------------------------------------------------------------------


@dataclass
class _Axes:
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
            f'<clipPath id="{uid}-clip"><rect x="{l}" y="{t}" width="{_f(pw)}" height="{_f(ph)}"/></clipPath>'
        )
        # Fallback presentation attributes (a stylesheet overrides them) so that an SVG cut out of the page
        # shows its plot area, grid and axes without the page's stylesheet.
        self.parts.append(f'<rect class="plot-bg" x="{l}" y="{t}" width="{_f(pw)}" height="{_f(ph)}" fill="none"/>')
        if xticks:
            # as many ticks as labels of ~3.6 characters fit side by side: 9 on the page, fewer in print
            for v in log_ticks(*self.xdom, base2=xbase2, max_ticks=max(3, int(pw / (3.6 * self.layout.font)))):
                px = self.x(v)
                self.parts.append(
                    f'<line class="grid" x1="{_f(px)}" y1="{t}" x2="{_f(px)}" y2="{_f(t + ph)}" stroke="#bbb"/>')
                self.parts.append(
                    f'<text class="tick x" x="{_f(px)}" y="{_f(t + ph + 16)}" text-anchor="middle">'
                    f"{escape(format_tick(v))}</text>"
                )
        for v in log_ticks(*self.ydom, max_ticks=7):
            py = self.y(v)
            self.parts.append(
                f'<line class="grid" x1="{l}" y1="{_f(py)}" x2="{_f(l + pw)}" y2="{_f(py)}" stroke="#bbb"/>')
            self.parts.append(
                f'<text class="tick y" x="{l - 6}" y="{_f(py + 4)}" text-anchor="end">{escape(format_tick(v))}</text>'
            )
        self.parts.append(
            f'<rect class="axis" x="{l}" y="{t}" width="{_f(pw)}" height="{_f(ph)}" fill="none" stroke="#888"/>')
        self.parts.append(
            f'<text class="label x" x="{_f(l + pw / 2)}" y="{self.height - 12}" text-anchor="middle">'
            f"{escape(xlabel)}</text>"
        )
        self.parts.append(
            f'<text class="label y" transform="translate(16 {_f(t + ph / 2)}) rotate(-90)" text-anchor="middle">'
            f"{escape(ylabel)}</text>"
        )

    def legend(self, entries: list[tuple[str, str, str]]) -> None:
        """entries: (kind, colour, label); kind is 'line', 'dash', 'band', 'dot', 'ring' or 'rect'.

        One per row right of the plot; or, with ``layout.legend_below``, in as many columns as fit under
        it, the chart growing to hold them: a standalone figure's legend is inside its viewBox.
        """
        lay = self.layout
        if lay.legend_below:
            col = 28 + 0.62 * lay.font * max((len(_short(e[2], 22)) for e in entries), default=0) + 8
            cols = max(1, int((self.width - 8) // col))
            spots = [(8 + (i % cols) * col, self.height + 6 + (i // cols) * lay.legend_row)
                     for i in range(len(entries))]
            self.legend_height = spots[-1][1] + 10 - self.height if spots else 0.0
        else:
            spots = [(self.width - self.right + 14, self.top + 6 + i * lay.legend_row) for i in range(len(entries))]
        for (kind, color, label), (x0, y) in zip(entries, spots):
            x1 = _f(x0 + 22)
            if kind in ("line", "dash"):
                # the dashed entry is the slope guide: its class lets a theme colour it as the guide
                dash = ' stroke-dasharray="6 4"' if kind == "dash" else ""
                self.parts.append(
                    f'<line class="legend-mark{" guide-mark" if dash else ""}" x1="{_f(x0)}" y1="{_f(y)}" x2="{x1}" '
                    f'y2="{_f(y)}" stroke="{color}" stroke-width="2.5"{dash}/>'
                )
            elif kind == "band":
                self.parts.append(
                    f'<rect class="legend-mark" x="{_f(x0)}" y="{_f(y - 5)}" width="22" height="10" '
                    f'fill="{color}" fill-opacity="0.25"/>'
                )
            elif kind == "rect":
                self.parts.append(
                    f'<rect class="legend-mark" x="{_f(x0 + 5)}" y="{_f(y - 6)}" width="12" height="12" '
                    f'fill="{color}"/>'
                )
            elif kind == "ring":
                self.parts.append(
                    f'<line class="legend-mark frontier-mark" x1="{_f(x0)}" y1="{_f(y)}" x2="{x1}" y2="{_f(y)}" '
                    f'stroke="{color}" stroke-width="6" stroke-opacity="0.45" stroke-linecap="round"/>'
                )
            else:
                self.parts.append(
                    f'<circle class="legend-mark" cx="{_f(x0 + 11)}" cy="{_f(y)}" r="4" fill="{color}"/>')
            title = f"<title>{escape(label)}</title>" if len(label) > 22 else ""
            self.parts.append(
                f'<text class="legend-label" x="{_f(x0 + 28)}" y="{_f(y + 4)}">'
                f"{title}{escape(_short(label, 22))}</text>"
            )

    def svg(self, uid: str, cls: str, aria: str, extra_attrs: str = "") -> str:
        lay, h = self.layout, self.height + self.legend_height
        own = ""
        if lay.style:  # standalone: namespaced, sized for print, its own stylesheet and a light background
            size = f' width="{lay.width_in:g}in" height="{lay.width_in * h / self.width:.3f}in"' if lay.width_in else ""
            extra_attrs = f' xmlns="http://www.w3.org/2000/svg"{size}{extra_attrs}'
            own = (f'<style>{lay.style}</style>'
                   f'<rect class="figure-bg" width="{self.width}" height="{_f(h)}" fill="#fff"/>')
        return (
            f'<svg id="{uid}" class="chart {cls}" viewBox="0 0 {self.width} {_f(h)}" role="img" '
            f'aria-label="{escape(aria)}" font-family="sans-serif" font-size="{lay.font:g}"{extra_attrs}>'
            + own
            + "".join(self.parts)
            + "</svg>"
        )


# --------------------------------------------------------------------------
# Charts
# --------------------------------------------------------------------------


@dataclass
class Series:
    """One renderer's curve: median ``y`` at each ``x``, optional per-point band [lo, hi]."""

    name: str
    color: str
    x: list[float]
    y: list[float]
    lo: list[float] | None = None
    hi: list[float] | None = None
    labels: list[str] | None = None  # tooltip of each point


def _usable(*vals: float) -> bool:
    return all(v is not None and math.isfinite(v) and v > 0 for v in vals)


def _guide_anchor(series: Sequence[Series]) -> tuple[float, float] | None:
    """Where the slope guide starts: a little above the first point of the series that starts highest
    (preferring real curves of two or more points), so it runs beside the data, not on it."""
    firsts = []
    for s in series:
        pts = [(x, y) for x, y in zip(s.x, s.y) if _usable(x, y)]
        if pts:
            firsts.append((len(pts) >= 2, pts[0][1], pts[0][0]))
    if not firsts:
        return None
    _, y_first, x_first = max(firsts)
    return x_first, y_first * GUIDE_OFFSET


def _draw_band(ax: "_Axes", s: Series, clip: str) -> None:
    """The series' min-max band over seeds, where it has one that is not flat."""
    if s.lo is None or s.hi is None:
        return
    pts = [(x, lo, hi) for x, lo, hi in zip(s.x, s.lo, s.hi) if _usable(x, lo, hi)]
    if len(pts) >= 2 and any(hi > lo for _, lo, hi in pts):
        upper = " L ".join(f"{_f(ax.x(x))} {_f(ax.y(hi))}" for x, _, hi in pts)
        lower = " L ".join(f"{_f(ax.x(x))} {_f(ax.y(lo))}" for x, lo, _ in reversed(pts))
        ax.parts.append(
            f'<path class="band" data-renderer="{escape(s.name)}" d="M {upper} L {lower} Z" '
            f'fill="{s.color}" fill-opacity="0.18" stroke="none" {clip}/>'
        )


def line_plot_svg(
    series: Sequence[Series],
    *,
    uid: str,
    xlabel: str,
    ylabel: str,
    guide_slope: float | None = -0.5,
    guide_label: str = "slope −½ (∝ 1/√N)",
    xbase2: bool = False,
    extra_attrs: str = "",
    layout: Layout = PAGE,
) -> str:
    """Log-log lines (one ``<path class="series">`` per series), bands and a slope guide."""
    xs = [v for s in series for v in s.x]
    ys = [v for s in series for v in (*s.y, *(s.lo or ()), *(s.hi or ()))]
    anchor = _guide_anchor(series) if guide_slope is not None else None
    if anchor is not None:
        ys.append(anchor[1])
    xdom, ydom = log_domain(xs), log_domain(ys)
    if xdom is None or ydom is None:
        return f'<p class="note">No positive values to plot for {escape(ylabel)}.</p>'
    ax = _Axes(xdom, ydom, layout)
    ax.frame(uid, xlabel, ylabel, xbase2=xbase2)
    clip = f'clip-path="url(#{uid}-clip)"'
    for s in series:
        _draw_band(ax, s, clip)
    if anchor is not None:
        x_first, y_first = anchor
        lx0, lx1 = xdom
        ly0 = math.log10(y_first) + guide_slope * (lx0 - math.log10(x_first))
        ly1 = ly0 + guide_slope * (lx1 - lx0)
        ax.parts.append(
            f'<path class="guide" data-slope="{guide_slope:g}" '
            f'd="M {_f(ax.x(10**lx0))} {_f(ax.y(10**ly0))} L {_f(ax.x(10**lx1))} {_f(ax.y(10**ly1))}" '
            f'fill="none" stroke="#888" stroke-width="1.6" stroke-dasharray="6 4" {clip}>'
            f"<title>{escape(guide_label)}</title></path>"
        )
    for s in series:
        pts = [(x, y, (s.labels or [None] * len(s.x))[i]) for i, (x, y) in enumerate(zip(s.x, s.y)) if _usable(x, y)]
        if not pts:
            continue
        d = " L ".join(f"{_f(ax.x(x))} {_f(ax.y(y))}" for x, y, _ in pts)
        ax.parts.append(
            f'<path class="series" data-renderer="{escape(s.name)}" d="M {d}" fill="none" '
            f'stroke="{s.color}" stroke-width="2.2" stroke-linejoin="round" {clip}/>'
        )
        for x, y, label in pts:
            tip = f"<title>{escape(label)}</title>" if label else ""
            ax.parts.append(
                f'<circle class="point" data-renderer="{escape(s.name)}" cx="{_f(ax.x(x))}" cy="{_f(ax.y(y))}" '
                f'r="3.2" fill="{s.color}">{tip}</circle>'
            )
    entries = [("line", s.color, s.name) for s in series]
    if any(s.lo is not None for s in series):
        entries.append(("band", "#9aa1ad", "min–max over seeds"))
    if anchor is not None:
        entries.append(("dash", "#c8ccd4", guide_label))
    ax.legend(entries)
    return ax.svg(uid, "line-plot", f"{ylabel} against {xlabel}", extra_attrs)


@dataclass
class Point:
    name: str  # renderer
    color: str
    x: float
    y: float
    label: str = ""  # tooltip
    tag: str = ""  # short text drawn beside the point (e.g. its spp)


def scatter_svg(
    points: Sequence[Point],
    *,
    uid: str,
    xlabel: str,
    ylabel: str,
    extra_attrs: str = "",
    layout: Layout = PAGE,
) -> str:
    """Log-log scatter with the Pareto frontier (lower x and lower y are better) drawn and marked."""
    pts = [p for p in points if _usable(p.x, p.y)]
    xdom, ydom = log_domain([p.x for p in pts]), log_domain([p.y for p in pts])
    if not pts or xdom is None or ydom is None:
        return f'<p class="note">No positive values to plot for {escape(ylabel)}.</p>'
    ax = _Axes(xdom, ydom, layout)
    ax.frame(uid, xlabel, ylabel)
    clip = f'clip-path="url(#{uid}-clip)"'
    front = pareto_front([p.x for p in pts], [p.y for p in pts])
    if front:
        d = " L ".join(f"{_f(ax.x(pts[i].x))} {_f(ax.y(pts[i].y))}" for i in front)
        ax.parts.append(f'<path class="frontier" d="M {d}" fill="none" stroke="#e0a800" stroke-width="7" '
                        f'stroke-opacity="0.35" stroke-linecap="round" stroke-linejoin="round" {clip}/>')
    on_front = set(front)
    # Lines joining each renderer's own points, faint, so its trade-off curve reads.
    by_name: dict[str, list[Point]] = {}
    for p in pts:
        by_name.setdefault(p.name, []).append(p)
    for name, ps in by_name.items():
        if len(ps) >= 2:
            ps = sorted(ps, key=lambda p: p.x)
            d = " L ".join(f"{_f(ax.x(p.x))} {_f(ax.y(p.y))}" for p in ps)
            ax.parts.append(
                f'<path class="trail" data-renderer="{escape(name)}" d="M {d}" fill="none" '
                f'stroke="{ps[0].color}" stroke-opacity="0.45" stroke-width="1.2" {clip}/>'
            )
    for i, p in enumerate(pts):
        cls = "point on-front" if i in on_front else "point"
        tip = f"<title>{escape(p.label)}{' — on the Pareto frontier' if i in on_front else ''}</title>"
        ax.parts.append(
            f'<circle class="{cls}" data-renderer="{escape(p.name)}" cx="{_f(ax.x(p.x))}" cy="{_f(ax.y(p.y))}" '
            f'r="{5 if i in on_front else 3.6}" fill="{p.color}">{tip}</circle>'
        )
    if len(pts) <= 60:
        for p in pts:
            if p.tag:
                ax.parts.append(
                    f'<text class="point-tag" x="{_f(ax.x(p.x) + 6)}" y="{_f(ax.y(p.y) - 5)}" {clip}>'
                    f"{escape(p.tag)}</text>"
                )
    names = list(dict.fromkeys(p.name for p in pts))
    colors = {p.name: p.color for p in pts}
    ax.legend([("dot", colors[n], n) for n in names] + [("ring", "#ffd166", "Pareto frontier")])
    return ax.svg(uid, "scatter-plot", f"{ylabel} against {xlabel}", extra_attrs)


@dataclass
class BarGroup:
    name: str
    values: list[float]  # one per bar kind
    note: str = ""  # text above the group


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
    bias; see :func:`reports.tables.format_value`) or not finite gets no bar but a small "≈ 0" or "n/a" mark.
    """
    vals = [v for g in groups for v in g.values]
    ydom = log_domain(vals, pad=0.1)
    if ydom is None or not groups:
        return '<p class="note">No positive values to plot.</p>'
    ydom = (ydom[0] - 0.15 * (ydom[1] - ydom[0]), ydom[1])  # room below the smallest bar
    ax = _Axes((0.0, 1.0), ydom, layout, extra_bottom=18)
    ax.frame(uid, "", ylabel, xticks=False)
    n, k = len(groups), len(kinds)
    slot = ax.pw / n
    bw = min(34.0, 0.75 * slot / k)
    base = ax.top + ax.ph
    for gi, g in enumerate(groups):
        cx = ax.left + slot * (gi + 0.5)
        x0 = cx - bw * k / 2
        tops = []
        for bi, ((label, color), v) in enumerate(zip(kinds, g.values)):
            bx = x0 + bi * bw
            if v is not None and math.isfinite(v) and v > 0:
                top = ax.y(v)
                tops.append(top)
                ax.parts.append(
                    f'<rect class="bar" data-renderer="{escape(g.name)}" data-kind="{escape(label)}" '
                    f'x="{_f(bx + 1)}" y="{_f(top)}" width="{_f(bw - 2)}" height="{_f(base - top)}" fill="{color}">'
                    f"<title>{escape(g.name)}: {escape(label)} = {v:.3e}</title></rect>"
                )
            else:
                mark = "n/a" if v is None or not math.isfinite(v) else ("0" if v == 0 else "≈ 0")
                ax.parts.append(
                    f'<text class="bar-missing" x="{_f(bx + bw / 2)}" y="{_f(base - 6)}" text-anchor="middle">'
                    f"{mark}<title>{escape(g.name)}: {escape(label)} = {escape(str(v))}</title></text>"
                )
        label_y = (min(tops) if tops else base - 20) - 8
        if g.note:
            ax.parts.append(
                f'<text class="bar-note" x="{_f(cx)}" y="{_f(max(label_y, ax.top + 12))}" text-anchor="middle">'
                f"{escape(g.note)}</text>"
            )
        ax.parts.append(
            f'<text class="tick x" x="{_f(cx)}" y="{_f(base + 18)}" text-anchor="middle">'
            f"<title>{escape(g.name)}</title>{escape(_short(g.name, max(6, int(slot / (0.65 * layout.font)))))}</text>"
        )
    ax.legend([("rect", color, label) for label, color in kinds])
    return ax.svg(uid, "bar-plot", ylabel, extra_attrs)
