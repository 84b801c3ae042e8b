"""Small, dependency-free SVG charts for the HTML report.

Every chart is a string of inline SVG, drawn here from numbers so the report
needs no plotting library and no script to show them. Classes (``series``,
``band``, ``guide``, ``frontier``, ``bar``...) carry the meaning, so the report's
stylesheet themes them and tests can find them; colours of series are
presentation attributes. A :class:`Layout` says how big a chart is and where
its legend goes: :data:`PAGE` for the report, styled by the page; one with a
``style`` of its own makes a standalone SVG (:mod:`cornell_harness.reports.figures`).

- :func:`line_plot_svg`: log-log error curves, one line per renderer with a
  band across seeds (the report's: 95% confidence intervals), horizontal
  whiskers where x is uncertain too (time) and an optional slope guide (convergence plots);
- :func:`scatter_svg`: log-log speed/accuracy points, with 95% CI whiskers where given, and the Pareto frontier;
  grouped bars (bias² and variance) are :mod:`cornell_harness.reports.bars`';
- the frame they are drawn in (layout, axes, legend) and the estimate of text boxes are :mod:`cornell_harness.reports.axes`';
  the numbers behind them (ticks, domains, the Pareto front) are :mod:`cornell_harness.reports.plotmath`'s.

No text is cut and no two texts meet, by those estimates: legends and names wrap (the chart growing to hold
them), names that do not wrap stand vertical, notes take rows, and a point's tag goes to the first free side
of it or is left to its tooltip. A series', point's or group's ``label`` is the text shown for it;
``data-renderer`` and the tooltips keep its ``name``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from html import escape
from typing import Sequence

from cornell_harness.reports.axes import PAGE as PAGE, PALETTE as PALETTE, Axes as _Axes, Layout as Layout
from cornell_harness.reports.axes import ASCENT, DESCENT, Box, overlaps, text_box
from cornell_harness.reports.axes import color_for as color_for, num as _f
from cornell_harness.reports.plotmath import log_domain, pareto_front

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


def shown(item) -> str:
    """The text a legend or a bar's tick label shows for an item (a :class:`Series`, :class:`Point` or
    :class:`~cornell_harness.reports.bars.BarGroup`): its display ``label``, else its ``name``."""
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
    entries = [("line", s.color, shown(s)) for s in series]
    if any(s.lo is not None for s in series):
        entries.append(("band", "#9aa1ad", band_label))
    if any(s.xlo is not None for s in series):
        entries.append(("whisker", "#9aa1ad", whisker_label))
    if anchor is not None:
        entries.append(("dash", "#c8ccd4", guide_label))
    ax = _Axes(xdom, ydom, layout, entries)
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
    ax.legend()
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
    label: str = ""  # the renderer's text in the legend instead of ``name`` (``data-renderer`` keeps the name)
    censored: bool = False  # x is only a lower bound: drawn at the axis' right edge, an arrow from x to it


#: A censored point's right edge lies at least this factor past its x, so the arrow from x to it shows.
CENSORED_REACH = 2.0


def scatter_svg(
    points: Sequence[Point],
    *,
    uid: str,
    xlabel: str,
    ylabel: str,
    extra_attrs: str = "",
    layout: Layout = PAGE,
    censored_label: str = "beyond the axis: x only a lower bound",
) -> str:
    """Log-log scatter with the Pareto frontier (lower x and lower y are better) drawn and marked, and each
    point's 95% CI whiskers where it has them (clipped to the axes, which span the points). Each point's
    ``tag`` goes where it meets no other tag and no point (:func:`place_tags`), or is left to the tooltip.

    A ``censored`` point (its x only a lower bound) is drawn at the right edge of the axis, which lies at least
    :data:`CENSORED_REACH` past its x, as a triangle pointing right at the end of a dashed arrow from its x;
    the legend says what that means (``censored_label``) and the frontier takes it at the edge."""
    pts = [p for p in points if _usable(p.x, p.y)]
    xdom = log_domain([p.x * (CENSORED_REACH if p.censored else 1.0) for p in pts])
    ydom = log_domain([p.y for p in pts])
    if not pts or xdom is None or ydom is None:
        return f'<p class="note">No positive values to plot for {escape(ylabel)}.</p>'
    xs = [10.0 ** xdom[1] if p.censored else p.x for p in pts]  # where each point is drawn
    names = list(dict.fromkeys(p.name for p in pts))
    colors = {p.name: p.color for p in pts}
    texts = {p.name: shown(p) for p in reversed(pts)}  # the first point's, where they disagree
    whiskers = [("whisker", "#9aa1ad", "95% CI")] if any(p.xlo is not None or p.ylo is not None for p in pts) else []
    arrows = [("arrow", "#9aa1ad", censored_label)] if any(p.censored for p in pts) else []
    ax = _Axes(xdom, ydom, layout, [("dot", colors[n], texts[n]) for n in names]
               + [("ring", "#ffd166", "Pareto frontier")] + whiskers + arrows)
    ax.frame(uid, xlabel, ylabel)
    clip = f'clip-path="url(#{uid}-clip)"'
    front = pareto_front(xs, [p.y for p in pts])
    if front:
        d = " L ".join(f"{_f(ax.x(xs[i]))} {_f(ax.y(pts[i].y))}" for i in front)
        ax.parts.append(f'<path class="frontier" d="M {d}" fill="none" stroke="#e0a800" stroke-width="7" '
                        f'stroke-opacity="0.35" stroke-linecap="round" stroke-linejoin="round" {clip}/>')
    on_front = set(front)
    # Lines joining each renderer's own points, faint, so its trade-off curve reads.
    by_name: dict[str, list[tuple[float, Point]]] = {}
    for x, p in zip(xs, pts):
        by_name.setdefault(p.name, []).append((x, p))
    for name, ps in by_name.items():
        if len(ps) >= 2:
            ps = sorted(ps, key=lambda xp: xp[0])
            d = " L ".join(f"{_f(ax.x(x))} {_f(ax.y(p.y))}" for x, p in ps)
            ax.parts.append(
                f'<path class="trail" data-renderer="{escape(name)}" d="M {d}" fill="none" '
                f'stroke="{ps[0][1].color}" stroke-opacity="0.45" stroke-width="1.2" {clip}/>'
            )
    for x, p in zip(xs, pts):
        if not p.censored:
            _whisker(ax, p.name, p.color, x, p.y, p.xlo, p.xhi, clip)
        _whisker(ax, p.name, p.color, x, p.y, p.ylo, p.yhi, clip, axis="y")
    radius = [5 if i in on_front else 3.6 for i in range(len(pts))]
    for i, (x, p) in enumerate(zip(xs, pts)):
        cls = "point on-front" if i in on_front else "point"
        tip = f"<title>{escape(p.tip)}{' — on the Pareto frontier' if i in on_front else ''}</title>"
        if p.censored:
            _censored_mark(ax, p, cls, tip, radius[i], clip)
            continue
        ax.parts.append(
            f'<circle class="{cls}" data-renderer="{escape(p.name)}" cx="{_f(ax.x(x))}" cy="{_f(ax.y(p.y))}" '
            f'r="{radius[i]}" fill="{p.color}">{tip}</circle>'
        )
    centres = [(ax.x(x), ax.y(p.y)) for x, p in zip(xs, pts)]
    area = (ax.left, ax.top, ax.left + ax.pw, ax.top + ax.ph)
    for (x, y, anchor), p in zip(place_tags(centres, radius, [p.tag for p in pts], area, layout.font), pts):
        if anchor:
            ax.parts.append(f'<text class="point-tag" data-renderer="{escape(p.name)}" x="{_f(x)}" y="{_f(y)}" '
                            f'text-anchor="{anchor}">{escape(p.tag)}</text>')
    ax.legend()
    return ax.svg(uid, "scatter-plot", f"{ylabel} against {xlabel}", extra_attrs)


def _censored_mark(ax: "_Axes", p: Point, cls: str, tip: str, r: float, clip: str) -> None:
    """A censored point: a dashed arrow from its x (a lower bound) to the right edge, where a triangle pointing
    right marks it (``censored`` among its classes)."""
    x0, x1, y = ax.x(p.x), ax.left + ax.pw, ax.y(p.y)
    ax.parts.append(f'<path class="censored-arrow" data-renderer="{escape(p.name)}" d="M {_f(x0)} {_f(y)} L '
                    f'{_f(x1 - 2 * r)} {_f(y)}" stroke="{p.color}" stroke-width="1.6" stroke-dasharray="4 3" '
                    f'fill="none" {clip}/>')
    ax.parts.append(f'<path class="{cls} censored" data-renderer="{escape(p.name)}" d="M {_f(x1 - 2.6 * r)} '
                    f'{_f(y - 1.6 * r)} L {_f(x1)} {_f(y)} L {_f(x1 - 2.6 * r)} {_f(y + 1.6 * r)} Z" '
                    f'fill="{p.color}">{tip}</path>')


def place_tags(centres: Sequence[tuple[float, float]], radius: Sequence[float], tags: Sequence[str],
               area: Box, font: float) -> list[tuple[float, float, str]]:
    """Where each point's tag goes: (x, y, text-anchor) of its baseline, the first of right-up, right-down,
    left-up, left-down, above and below whose estimated box (:func:`cornell_harness.reports.axes.text_box`) lies in ``area``,
    meets no tag placed before it and no point, and is plainly nearer its own point than any other
    (:func:`_own`); ``(0, 0, "")`` for an empty tag, one with no room (its point's tooltip still says it) or
    one that a point under this one already shows."""
    dots = [(cx - r, cy - r, cx + r, cy + r) for (cx, cy), r in zip(centres, radius)]
    placed: list[Box] = []
    told: list[tuple[float, float, str]] = []  # the points whose tags are placed, and their tags
    out = []
    # baselines beside a point: the box just above or just below its centre, 1 apart more than a tag's gap
    up, down = -0.1 * font - 1 - DESCENT * font, 0.1 * font + 1 + ASCENT * font
    for (cx, cy), r, tag in zip(centres, radius, tags):
        spot = (0.0, 0.0, "")
        said = any(t == tag and abs(x - cx) <= r and abs(y - cy) <= r for x, y, t in told)
        if tag and not said:  # a tag that a point on this one already has would only say it twice
            d = r + 2.5
            for x, y, anchor in ((cx + d, cy + up, "start"), (cx + d, cy + down, "start"),
                                 (cx - d, cy + up, "end"), (cx - d, cy + down, "end"),
                                 (cx, cy - r - 2 - DESCENT * font, "middle"),
                                 (cx, cy + r + 2 + ASCENT * font, "middle")):
                box = text_box(x, y, tag, font, anchor)
                inside = area[0] + 1 <= box[0] and box[2] <= area[2] - 1 and area[1] + 1 <= box[1] \
                    and box[3] <= area[3] - 1
                if inside and not any(overlaps(box, b, gap=1) for b in placed + dots) and _own(box, cx, cy, r, centres,
                                                                                        radius):
                    placed.append(box)
                    told.append((cx, cy, tag))
                    spot = (x, y, anchor)
                    break
        out.append(spot)
    return out


#: A tag is this much (viewBox units) nearer its own point's marker than any other point's, so it reads as its.
OWN_MARGIN = 3.0


def _own(box: Box, cx: float, cy: float, r: float, centres: Sequence[tuple[float, float]],
         radius: Sequence[float]) -> bool:
    """Whether ``box`` is at least :data:`OWN_MARGIN` nearer the marker at (cx, cy) than every other marker
    (those under this one, which share its place, aside): a tag between two points would say the wrong one's."""
    def gap(x: float, y: float, rad: float) -> float:
        return math.hypot(max(box[0] - x, 0.0, x - box[2]), max(box[1] - y, 0.0, y - box[3])) - rad
    own = gap(cx, cy, r)
    return all(gap(x, y, rad) >= own + OWN_MARGIN for (x, y), rad in zip(centres, radius)
               if math.hypot(x - cx, y - cy) > r)
