"""Small, dependency-free SVG charts for the HTML report.

Every chart is a string of inline SVG, drawn here from numbers so the report
needs no plotting library and no script to show them. Classes (``series``,
``band``, ``guide``, ``frontier``, ``bar``...) carry the meaning, so the report's
stylesheet themes them and tests can find them; colours of series are
presentation attributes.

- :func:`line_plot_svg`: log-log error curves, one line per renderer with a
  min–max band across seeds and an optional slope guide (convergence plots);
- :func:`scatter_svg`: log-log speed/accuracy points with the Pareto frontier;
- :func:`bars_svg`: grouped bars on a log axis (bias² and variance);
- :func:`pareto_front`: the pure function behind the frontier.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from html import escape
from typing import Sequence

import numpy as np

#: Okabe & Ito (2008) colour-blind-safe palette, then Tableau's for more renderers.
PALETTE = (
    "#56b4e9", "#e69f00", "#009e73", "#f0e442", "#cc79a7", "#d55e00", "#0072b2",
    "#9aa1ad", "#8c564b", "#bcbd22", "#17becf", "#e377c2",
)

WIDTH, HEIGHT = 640, 400
MARGIN_LEFT, MARGIN_RIGHT, MARGIN_TOP, MARGIN_BOTTOM = 70, 180, 30, 52

#: The slope guide starts this factor above the highest first point.
GUIDE_OFFSET = 1.5

_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def color_for(index: int) -> str:
    return PALETTE[index % len(PALETTE)]


# --------------------------------------------------------------------------
# Pure helpers
# --------------------------------------------------------------------------


def pareto_front(x: Sequence[float], y: Sequence[float]) -> list[int]:
    """Indices of the points that no other point beats in both ``x`` and ``y`` (lower is better).

    A point is dominated when another is at least as good in both coordinates
    and strictly better in one; identical points do not dominate each other,
    so both stay on the front. Points with a NaN or infinite coordinate are
    never on it. The result is ordered by increasing ``x`` (then ``y``).
    """
    xs = np.asarray(x, dtype=np.float64)
    ys = np.asarray(y, dtype=np.float64)
    if xs.shape != ys.shape:
        raise ValueError(f"x and y differ in length: {xs.shape} vs {ys.shape}")
    valid = [i for i in range(xs.size) if math.isfinite(xs[i]) and math.isfinite(ys[i])]
    front = []
    for i in valid:
        dominated = any(
            xs[j] <= xs[i] and ys[j] <= ys[i] and (xs[j] < xs[i] or ys[j] < ys[i]) for j in valid if j != i
        )
        if not dominated:
            front.append(i)
    return sorted(front, key=lambda i: (xs[i], ys[i], i))


def format_tick(v: float) -> str:
    """A tick label: plain for moderate values, ``2×10⁻⁵`` style otherwise."""
    if v == 0 or not math.isfinite(v):
        return "0" if v == 0 else str(v)
    if 1e-3 <= abs(v) < 1e5:
        return f"{v:g}"
    exp = int(math.floor(math.log10(abs(v)) + 1e-9))
    mant = v / 10**exp
    power = "10" + str(exp).translate(_SUPERSCRIPT)
    if abs(mant - 1) < 1e-6:
        return power
    return f"{mant:g}×{power}"


def log_domain(values: Sequence[float], pad: float = 0.06) -> tuple[float, float] | None:
    """log10 extent of the positive finite ``values``, padded; None if there are none."""
    v = np.asarray([x for x in values if x is not None and math.isfinite(x) and x > 0], dtype=np.float64)
    if v.size == 0:
        return None
    lo, hi = math.log10(v.min()), math.log10(v.max())
    if hi - lo < 0.3:  # a nearly flat series still gets a readable axis
        mid = 0.5 * (lo + hi)
        lo, hi = mid - 0.15, mid + 0.15
    span = hi - lo
    return lo - pad * span, hi + pad * span


def log_ticks(lo: float, hi: float, base2: bool = False, max_ticks: int = 9) -> list[float]:
    """Tick values inside the log10 domain [lo, hi]: powers of 2 (``base2``) or 1-2-5 decades."""
    if base2:
        k0, k1 = math.ceil(lo / math.log10(2) - 1e-9), math.floor(hi / math.log10(2) + 1e-9)
        ks = list(range(k0, k1 + 1))
        step = 1
        while len(ks[::step]) > max_ticks:
            step += 1
        return [2.0**k for k in ks[::step]]
    def thin(ticks: list[float]) -> list[float]:
        step = 1
        while len(ticks[::step]) > max_ticks:
            step += 1
        return ticks[::step]

    decades, one25, all9 = (
        [m * 10.0**e for e in range(math.floor(lo) - 1, math.ceil(hi) + 1) for m in mults
         if lo - 1e-9 <= math.log10(m * 10.0**e) <= hi + 1e-9]
        for mults in ((1,), (1, 2, 5), (1, 2, 3, 4, 5, 6, 7, 8, 9))
    )
    if len(decades) >= 3:
        return thin(decades)
    if 2 <= len(one25) <= max_ticks:
        return one25
    for ticks in (decades, one25, all9):
        if len(ticks) >= 2:
            return thin(ticks)
    return [10.0 ** (0.5 * (lo + hi))]


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
    width: int = WIDTH
    height: int = HEIGHT
    left: int = MARGIN_LEFT
    right: int = MARGIN_RIGHT
    top: int = MARGIN_TOP
    bottom: int = MARGIN_BOTTOM
    parts: list[str] = field(default_factory=list)

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
        self.parts.append(f'<rect class="plot-bg" x="{l}" y="{t}" width="{_f(pw)}" height="{_f(ph)}"/>')
        if xticks:
            for v in log_ticks(*self.xdom, base2=xbase2):
                px = self.x(v)
                self.parts.append(f'<line class="grid" x1="{_f(px)}" y1="{t}" x2="{_f(px)}" y2="{_f(t + ph)}"/>')
                self.parts.append(
                    f'<text class="tick x" x="{_f(px)}" y="{_f(t + ph + 16)}" text-anchor="middle">'
                    f"{escape(format_tick(v))}</text>"
                )
        for v in log_ticks(*self.ydom, max_ticks=7):
            py = self.y(v)
            self.parts.append(f'<line class="grid" x1="{l}" y1="{_f(py)}" x2="{_f(l + pw)}" y2="{_f(py)}"/>')
            self.parts.append(
                f'<text class="tick y" x="{l - 6}" y="{_f(py + 4)}" text-anchor="end">{escape(format_tick(v))}</text>'
            )
        self.parts.append(f'<rect class="axis" x="{l}" y="{t}" width="{_f(pw)}" height="{_f(ph)}" fill="none"/>')
        self.parts.append(
            f'<text class="label x" x="{_f(l + pw / 2)}" y="{self.height - 12}" text-anchor="middle">'
            f"{escape(xlabel)}</text>"
        )
        self.parts.append(
            f'<text class="label y" transform="translate(16 {_f(t + ph / 2)}) rotate(-90)" text-anchor="middle">'
            f"{escape(ylabel)}</text>"
        )

    def legend(self, entries: list[tuple[str, str, str]], y0: float | None = None) -> None:
        """entries: (kind, colour, label); kind is 'line', 'dash', 'band', 'dot', 'ring' or 'rect'."""
        x0 = self.width - self.right + 14
        y = self.top + 6 if y0 is None else y0
        for kind, color, label in entries:
            if kind in ("line", "dash"):
                dash = ' stroke-dasharray="6 4"' if kind == "dash" else ""
                self.parts.append(
                    f'<line class="legend-mark" x1="{x0}" y1="{_f(y)}" x2="{x0 + 22}" y2="{_f(y)}" '
                    f'stroke="{color}" stroke-width="2.5"{dash}/>'
                )
            elif kind == "band":
                self.parts.append(
                    f'<rect class="legend-mark" x="{x0}" y="{_f(y - 5)}" width="22" height="10" '
                    f'fill="{color}" fill-opacity="0.25"/>'
                )
            elif kind == "rect":
                self.parts.append(
                    f'<rect class="legend-mark" x="{x0 + 5}" y="{_f(y - 6)}" width="12" height="12" fill="{color}"/>'
                )
            elif kind == "ring":
                self.parts.append(
                    f'<line class="legend-mark" x1="{x0}" y1="{_f(y)}" x2="{x0 + 22}" y2="{_f(y)}" '
                    f'stroke="{color}" stroke-width="6" stroke-opacity="0.45" stroke-linecap="round"/>'
                )
            else:
                self.parts.append(f'<circle class="legend-mark" cx="{x0 + 11}" cy="{_f(y)}" r="4" fill="{color}"/>')
            title = f"<title>{escape(label)}</title>" if len(label) > 22 else ""
            self.parts.append(
                f'<text class="legend-label" x="{x0 + 28}" y="{_f(y + 4)}">{title}{escape(_short(label, 22))}</text>'
            )
            y += 19

    def svg(self, uid: str, cls: str, aria: str, extra_attrs: str = "") -> str:
        return (
            f'<svg id="{uid}" class="chart {cls}" viewBox="0 0 {self.width} {self.height}" role="img" '
            f'aria-label="{escape(aria)}"{extra_attrs}>'
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
    ax = _Axes(xdom, ydom)
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
            f'fill="none" stroke-dasharray="6 4" {clip}><title>{escape(guide_label)}</title></path>'
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
) -> str:
    """Log-log scatter with the Pareto frontier (lower x and lower y are better) drawn and marked."""
    pts = [p for p in points if _usable(p.x, p.y)]
    xdom, ydom = log_domain([p.x for p in pts]), log_domain([p.y for p in pts])
    if not pts or xdom is None or ydom is None:
        return f'<p class="note">No positive values to plot for {escape(ylabel)}.</p>'
    ax = _Axes(xdom, ydom)
    ax.frame(uid, xlabel, ylabel)
    clip = f'clip-path="url(#{uid}-clip)"'
    front = pareto_front([p.x for p in pts], [p.y for p in pts])
    if front:
        d = " L ".join(f"{_f(ax.x(pts[i].x))} {_f(ax.y(pts[i].y))}" for i in front)
        ax.parts.append(f'<path class="frontier" d="M {d}" fill="none" {clip}/>')
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
) -> str:
    """Grouped bars on a log y axis; ``kinds`` = (label, colour) of each bar in a group.

    A value that is not positive (a bias² estimate below zero: no measurable
    bias) or not finite gets no bar but a small "≤ 0" or "n/a" mark.
    """
    vals = [v for g in groups for v in g.values]
    ydom = log_domain(vals, pad=0.1)
    if ydom is None or not groups:
        return '<p class="note">No positive values to plot.</p>'
    ydom = (ydom[0] - 0.15 * (ydom[1] - ydom[0]), ydom[1])  # room below the smallest bar
    ax = _Axes((0.0, 1.0), ydom, bottom=70)
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
                mark = "n/a" if v is None or not math.isfinite(v) else ("0" if v == 0 else "< 0")
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
            f"<title>{escape(g.name)}</title>{escape(_short(g.name, max(6, int(slot / 7.5))))}</text>"
        )
    ax.legend([("rect", color, label) for label, color in kinds])
    return ax.svg(uid, "bar-plot", ylabel, extra_attrs)
