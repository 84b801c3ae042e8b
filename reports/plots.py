"""Small, dependency-free SVG charts for the HTML report.

Every chart is a string of inline SVG, drawn here from numbers so the report
needs no plotting library and no script to show them. Classes (``series``,
``band``, ``guide``, ``frontier``, ``bar``...) carry the meaning, so the report's
stylesheet themes them and tests can find them; colours of series are
presentation attributes. A :class:`Layout` says how big a chart is and where
its legend goes: :data:`PAGE` for the report, styled by the page; one with a
``style`` of its own makes a standalone SVG (:mod:`reports.figures`).

- :func:`line_plot_svg`: log-log error curves, one line per renderer with a
  band across seeds (the report's: 95% confidence intervals), horizontal
  whiskers where x is uncertain too (time) and an optional slope guide (convergence plots);
- :func:`scatter_svg`: log-log speed/accuracy points, with 95% CI whiskers where given, and the Pareto frontier;
- :func:`bars_svg`: grouped bars on a log axis (bias² and variance);
- the frame they are drawn in (layout, axes, legend) is :mod:`reports.axes`'; the numbers behind them
  (ticks, domains, the Pareto front) are :mod:`reports.plotmath`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from html import escape
from typing import Sequence

from reports.axes import PAGE as PAGE, PALETTE as PALETTE, Axes as _Axes, Layout as Layout
from reports.axes import color_for as color_for, num as _f, short as _short
from reports.plotmath import log_domain, pareto_front

#: The slope guide starts this factor above the highest first point.
GUIDE_OFFSET = 1.5


# --------------------------------------------------------------------------
# Charts
# --------------------------------------------------------------------------


@dataclass
class Series:
    """One renderer's curve: median ``y`` at each ``x``, optional per-point band [lo, hi] and x whiskers
    [xlo, xhi] (a time's interval)."""

    name: str
    color: str
    x: list[float]
    y: list[float]
    lo: list[float] | None = None
    hi: list[float] | None = None
    labels: list[str] | None = None  # tooltip of each point
    xlo: list[float] | None = None
    xhi: list[float] | None = None
    label: str = ""  # shown in the legend instead of ``name`` (``data-renderer`` and tooltips keep the name)


def shown(item: "Series | Point | BarGroup") -> str:
    """The text a legend or a bar's tick label shows for an item: its display ``label``, else its ``name``."""
    return item.label or item.name


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


def _whisker(ax: "_Axes", name: str, color: str, x: float, y: float, lo: float | None, hi: float | None,
             clip: str, axis: str = "x") -> None:
    """An interval [lo, hi] through (x, y) along ``axis``, with end caps; nothing where it is unknown or flat."""
    if not (_usable(x, y) and lo is not None and hi is not None and _usable(lo, hi) and hi > lo):
        return
    if axis == "x":
        a, b, c = ax.x(lo), ax.x(hi), ax.y(y)
        d = f"M {_f(a)} {_f(c)} L {_f(b)} {_f(c)} M {_f(a)} {_f(c - 3)} L {_f(a)} {_f(c + 3)} " \
            f"M {_f(b)} {_f(c - 3)} L {_f(b)} {_f(c + 3)}"
    else:
        a, b, c = ax.y(lo), ax.y(hi), ax.x(x)
        d = f"M {_f(c)} {_f(a)} L {_f(c)} {_f(b)} M {_f(c - 3)} {_f(a)} L {_f(c + 3)} {_f(a)} " \
            f"M {_f(c - 3)} {_f(b)} L {_f(c + 3)} {_f(b)}"
    ax.parts.append(f'<path class="whisker" data-renderer="{escape(name)}" data-axis="{axis}" d="{d}" '
                    f'stroke="{color}" stroke-opacity="0.7" stroke-width="1.2" fill="none" {clip}/>')


def _draw_band(ax: "_Axes", s: Series, clip: str) -> None:
    """The series' band over seeds (the report's: a 95% CI), where it has one that is not flat."""
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
    band_label: str = "min–max over seeds",
    whisker_label: str = "95% CI of the time",
) -> str:
    """Log-log lines (one ``<path class="series">`` per series), bands, x whiskers and a slope guide.

    The axes span the points and the bands; whiskers are clipped to them (an interval of 2 seeds can be wide).
    """
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
        if s.xlo is not None and s.xhi is not None:
            for x, y, lo, hi in zip(s.x, s.y, s.xlo, s.xhi):
                _whisker(ax, s.name, s.color, x, y, lo, hi, clip)
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
    entries = [("line", s.color, shown(s)) for s in series]
    if any(s.lo is not None for s in series):
        entries.append(("band", "#9aa1ad", band_label))
    if any(s.xlo is not None for s in series):
        entries.append(("whisker", "#9aa1ad", whisker_label))
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
    tip: str = ""  # tooltip
    tag: str = ""  # short text drawn beside the point (e.g. its spp)
    xlo: float | None = None  # 95% CI whiskers, where known
    xhi: float | None = None
    ylo: float | None = None
    yhi: float | None = None
    label: str = ""  # the renderer's display text in the legend (``data-renderer`` keeps ``name``)


def scatter_svg(
    points: Sequence[Point],
    *,
    uid: str,
    xlabel: str,
    ylabel: str,
    extra_attrs: str = "",
    layout: Layout = PAGE,
) -> str:
    """Log-log scatter with the Pareto frontier (lower x and lower y are better) drawn and marked, and each
    point's 95% CI whiskers where it has them (clipped to the axes, which span the points)."""
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
    for p in pts:
        _whisker(ax, p.name, p.color, p.x, p.y, p.xlo, p.xhi, clip)
        _whisker(ax, p.name, p.color, p.x, p.y, p.ylo, p.yhi, clip, axis="y")
    for i, p in enumerate(pts):
        cls = "point on-front" if i in on_front else "point"
        tip = f"<title>{escape(p.tip)}{' — on the Pareto frontier' if i in on_front else ''}</title>"
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
    texts = {p.name: shown(p) for p in reversed(pts)}  # the first point's label, where points disagree
    whiskers = [("whisker", "#9aa1ad", "95% CI")] if any(p.xlo is not None or p.ylo is not None for p in pts) else []
    ax.legend([("dot", colors[n], texts[n]) for n in names] + [("ring", "#ffd166", "Pareto frontier")] + whiskers)
    return ax.svg(uid, "scatter-plot", f"{ylabel} against {xlabel}", extra_attrs)


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
    bias; see :func:`reports.tables.format_value`) or not finite gets no bar but a small "≈ 0" or "n/a" mark.
    A group's ``lo`` / ``hi`` draw error bars (``class="whisker"``), from the axis where the low end is not
    positive.
    """
    vals = [v for g in groups for v in (*g.values, *(g.hi or ()))]
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
            hi = g.hi[bi] if g.hi is not None else None
            if hi is not None and math.isfinite(hi) and hi > 0:
                lo = g.lo[bi] if g.lo is not None else None
                y_lo = ax.y(lo) if lo is not None and math.isfinite(lo) and lo > 0 else base
                y_hi, mx = ax.y(hi), bx + bw / 2
                tops.append(y_hi)
                ax.parts.append(
                    f'<path class="whisker" data-renderer="{escape(g.name)}" data-kind="{escape(label)}" '
                    f'd="M {_f(mx)} {_f(y_lo)} L {_f(mx)} {_f(y_hi)} M {_f(mx - 3)} {_f(y_hi)} L {_f(mx + 3)} '
                    f'{_f(y_hi)}" stroke="#555" stroke-width="1.2" fill="none"/>')
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
            f"<title>{escape(g.name)}</title>{escape(_short(shown(g), max(6, int(slot / (0.65 * layout.font)))))}</text>"
        )
    bars = any(g.hi is not None for g in groups)
    ax.legend([("rect", color, label) for label, color in kinds] + ([("whisker", "#555", "95% CI")] if bars else []))
    return ax.svg(uid, "bar-plot", ylabel, extra_attrs)
