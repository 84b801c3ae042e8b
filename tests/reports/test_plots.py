"""The charts' text on the SVG strings: never cut, every long label whole, no two estimated text boxes meeting.

Each ``<text>`` of a chart is given the box that :mod:`cornell_harness.reports.axes` estimates for it (its anchor, lines and a
rotation of -90°), the same estimate the charts place their text by; the browser checks the drawn boxes
(tests/reports/test_figures_browser.py).
"""

from __future__ import annotations

import math
import random
import re
import xml.etree.ElementTree as ET

import pytest

from cornell_harness.reports import bars, plots
from cornell_harness.reports.axes import ASCENT, CHAR_WIDTH, DESCENT, LINE, overlaps, pieces, text_width, wrap
from cornell_harness.reports.figures import PRINT

LONG = ['pathtracer[sampler="independent",rr_depth=3]', 'pathtracer[sampler="sobol",rr_depth=3]',
        'mitsuba[integrator="volpath",max_depth=8]', "ambient-occlusion", "mitsuba", "sppm"]
LAYOUTS = pytest.mark.parametrize("layout", [plots.PAGE, PRINT], ids=["page", "print"])


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _texts(svg: str) -> tuple[list[dict], tuple[float, float]]:
    """Every non-empty ``<text>``: class, its own text (tspans joined, no tooltip), estimated box; and the
    viewBox's size."""
    root = ET.fromstring(svg)
    _, _, w, h = map(float, root.get("viewBox").split())
    out = []
    for el in root.iter():
        if _local(el.tag) != "text":
            continue
        cls = el.get("class", "")
        spans = [c for c in el if _local(c.tag) == "tspan"]
        # its text or its lines, without a <title> (a tooltip, not drawn)
        lines = [c.text or "" for c in spans] if spans else [(el.text or "") + "".join(c.tail or "" for c in el)]
        if not "".join(lines).strip():
            continue
        font = PRINT.label_font if cls.startswith("label") else float(root.get("font-size"))
        width = max(text_width(line, font) for line in lines)
        anchor = el.get("text-anchor", "start")
        down = DESCENT * font + (len(lines) - 1) * LINE * font
        m = re.fullmatch(r"translate\(([-\d.]+) ([-\d.]+)\) rotate\(-90\)", el.get("transform", ""))
        if m:  # rotated: its length runs up the page from the anchor, its lines to the right
            a, b = map(float, m.groups())
            x0 = float(el.get("x", 0)) - {"start": 0, "middle": width / 2, "end": width}[anchor]
            box = (a - ASCENT * font, b - x0 - width, a + down, b - x0)
        else:
            x, y = float(el.get("x")), float(el.get("y"))
            x0 = x - {"start": 0, "middle": width / 2, "end": width}[anchor]
            box = (x0, y - ASCENT * font, x0 + width, y + down)
        out.append({"cls": cls, "text": "".join(lines), "lines": lines, "box": box, "name": el.get("data-renderer")})
    return out, (w, h)


def _check_layout(svg: str) -> list[dict]:
    texts, (w, h) = _texts(svg)
    for t in texts:
        assert not t["text"].endswith("…"), t
        x0, y0, x1, y1 = t["box"]
        assert -0.01 <= x0 and x1 <= w + 0.01 and -0.01 <= y0 and y1 <= h + 0.01, (t, w, h)
    for i, a in enumerate(texts):
        for b in texts[i + 1:]:
            assert not overlaps(a["box"], b["box"]), (a, b)
    return texts


def _series(names=LONG):
    return [plots.Series(n, plots.color_for(i), [1, 4, 16, 64], [1 / (i + 1), .5 / (i + 1), .25 / (i + 1), .12 / (i + 1)],
                         [.9 / (i + 1)] * 4, [1.1 / (i + 1)] * 4, xlo=[.9, 3.6, 14, 60], xhi=[1.1, 4.4, 18, 70])
            for i, n in enumerate(names)]


def test_wrap_breaks_at_brackets_commas_and_spaces_and_keeps_every_character():
    assert pieces('pathtracer[sampler="independent",rr_depth=3]') == [
        "pathtracer[", 'sampler="independent",', "rr_depth=3]"]
    font = 10.0
    room = text_width('sampler="independent",', font)
    assert wrap(LONG[0], room, font) == ["pathtracer[", 'sampler="independent",', "rr_depth=3]"]
    assert wrap("bias not significant", text_width("significant", font), font) == ["bias not ", "significant"]
    for text in [*LONG, "a" * 50, "x, y, z", ""]:
        for chars in (3, 7, 12, 30):
            room = chars * CHAR_WIDTH * font
            lines = wrap(text, room, font)
            assert "".join(lines) == text  # nothing dropped, nothing added
            assert all(text_width(line, font) <= room + 1e-9 for line in lines), (text, chars, lines)
    assert wrap("a" * 25, 10 * CHAR_WIDTH * 10, 10) == ["a" * 10, "a" * 10, "a" * 5]  # cut only where it must


@LAYOUTS
def test_line_plot_legend_holds_every_label_whole(layout):
    svg = plots.line_plot_svg(_series(), uid="u", xlabel="wall time (s)", ylabel="RMSE", layout=layout)
    texts = _check_layout(svg)
    legend = [t for t in texts if t["cls"] == "legend-label"]
    assert [t["text"] for t in legend] == [*LONG, "min–max over seeds", "95% CI of the time", "slope −½ (∝ 1/√N)"]
    assert len(legend[0]["lines"]) >= 2  # the longest wraps (page: beside the plot; print: a column's width)
    if not layout.legend_below:  # the legend's column grew for `sampler="independent",`; the plot kept its size
        root = ET.fromstring(svg)
        assert float(root.get("viewBox").split()[2]) > layout.width
        plot = [el for el in root.iter() if _local(el.tag) == "rect" and el.get("class") == "axis"][0]
        assert float(plot.get("width")) == layout.width - layout.left - layout.right


def test_short_labels_stay_one_line_and_print_legend_takes_columns():
    svg = plots.line_plot_svg(_series(["a", "bb", "ccc"]), uid="u", xlabel="spp", ylabel="RMSE", layout=PRINT,
                              guide_slope=None)
    texts = _check_layout(svg)
    legend = [t for t in texts if t["cls"] == "legend-label"]
    assert [t["lines"] for t in legend[:3]] == [["a"], ["bb"], ["ccc"]]
    assert len({t["box"][0] for t in legend}) >= 2  # side by side, not one per row
    page = plots.line_plot_svg(_series(["a", "bb", "ccc"]), uid="u", xlabel="spp", ylabel="RMSE", guide_slope=None)
    assert 'viewBox="0 0 640 400"' in page  # nothing long: the page's size is unchanged


def test_series_label_is_shown_and_name_kept_for_the_page():
    s = _series(LONG[:2])
    s[0].label = "PT (independent)"
    svg = plots.line_plot_svg(s, uid="u", xlabel="spp", ylabel="RMSE")
    legend = [t["text"] for t in _check_layout(svg) if t["cls"] == "legend-label"]
    assert legend[:2] == ["PT (independent)", LONG[1]]
    assert 'data-renderer="pathtracer[sampler=&quot;independent&quot;,rr_depth=3]"' in svg
    groups = [bars.BarGroup(n, [1e-3, 2e-3], label="PT" if i == 0 else "") for i, n in enumerate(LONG[:2])]
    bar_svg = bars.bars_svg(groups, (("bias²", "#e69f00"), ("variance", "#56b4e9")), uid="b", ylabel="m")
    names = [t["text"] for t in _check_layout(bar_svg) if t["cls"] == "tick x"]
    assert names == ["PT", LONG[1]] and f"<title>{LONG[0].replace(chr(34), '&quot;')}</title>" in bar_svg
    points = [plots.Point(n, "#000", 1.0 + i, 2.0 + i, tip="tooltip", label="S" if i == 0 else "")
              for i, n in enumerate(LONG[:2])]
    scatter = plots.scatter_svg(points, uid="s", xlabel="t", ylabel="e")
    assert [t["text"] for t in _check_layout(scatter) if t["cls"] == "legend-label"][:2] == ["S", LONG[1]]
    assert "<title>tooltip" in scatter


def _points(spread: float):
    """Six renderers at four spp whose points lie within ``spread`` (relative) of each other."""
    return [plots.Point(n, plots.color_for(i), 0.01 * s * (1 + spread * i), s ** -0.5 * (1 + spread * i),
                        tip=f"{n} {s}", tag=str(s))
            for i, n in enumerate(LONG) for s in (1, 4, 16, 64)]


@LAYOUTS
@pytest.mark.parametrize("spread", [0.0, 0.01, 0.1])
def test_scatter_tags_never_meet(layout, spread):
    svg = plots.scatter_svg(_points(spread), uid="s", xlabel="t", ylabel="e", layout=layout)
    texts = _check_layout(svg)
    tags = [t for t in texts if t["cls"] == "point-tag"]
    assert 4 <= len(tags) <= 24  # the first renderer's tags always fit; coincident ones are left to tooltips
    if spread == 0.0:  # six points on each other: their spp said once
        assert sorted(t["text"] for t in tags) == ["1", "16", "4", "64"]
    root = ET.fromstring(svg)
    plot = [el for el in root.iter() if _local(el.tag) == "rect" and el.get("class") == "axis"][0]
    px, py, pw, ph = (float(plot.get(k)) for k in ("x", "y", "width", "height"))
    for t in tags:  # inside the plot, so the clip never cuts one
        assert px <= t["box"][0] and t["box"][2] <= px + pw and py <= t["box"][1] and t["box"][3] <= py + ph


@LAYOUTS
def test_crowded_scatter_tags_meet_nothing_and_sit_by_their_own_point(layout):
    """Twelve renderers' points packed close (a fixed seed): no tag meets another tag or any point's marker, and
    each tag is nearer its own point's marker than any other's by a margin, so it cannot be read as another's.
    A tag left out is still in its point's tooltip."""
    rng = random.Random(7)
    points = [plots.Point(f"r{i}", plots.color_for(i), 10 ** rng.uniform(0, 0.3), 10 ** rng.uniform(0, 0.25),
                          tip=f"r{i} {s} spp", tag=str(s)) for i in range(12) for s in (1, 4, 16, 64)]
    svg = plots.scatter_svg(points, uid="s", xlabel="t", ylabel="e", layout=layout)
    texts = _check_layout(svg)
    tags = [t for t in texts if t["cls"] == "point-tag"]
    root = ET.fromstring(svg)
    dots = [{"name": el.get("data-renderer"), "c": (float(el.get("cx")), float(el.get("cy"))), "r": float(el.get("r")),
             "tip": "".join(el.itertext())} for el in root.iter() if el.get("class", "").startswith("point ")
            or el.get("class") == "point"]
    assert len(dots) == 48 and 8 <= len(tags) < 48  # crowded: some tags go to their tooltips

    def gap(box, dot):
        (x, y), r = dot["c"], dot["r"]
        return math.hypot(max(box[0] - x, 0, x - box[2]), max(box[1] - y, 0, y - box[3])) - r

    for t in tags:
        assert all(gap(t["box"], d) >= 1 for d in dots), t  # covers no marker
        own = [d for d in dots if d["name"] == t["name"] and d["tip"].startswith(f"{t['name']} {t['text']} spp")]
        assert len(own) == 1
        assert all(gap(t["box"], d) >= gap(t["box"], own[0]) + plots.OWN_MARGIN for d in dots
                   if d is not own[0] and math.dist(d["c"], own[0]["c"]) > own[0]["r"]), t
    assert all(" spp" in d["tip"] for d in dots)


def test_a_censored_point_is_drawn_at_the_right_edge_with_an_arrow_from_its_bound():
    """x only a lower bound (a lag that did not settle within the sequence): the triangle's tip on the plot's right
    edge, the dashed arrow starting at the bound's x (read off the 20 and 50 ticks, log axis), the legend saying
    what it means; no such entry where nothing is censored."""
    points = [plots.Point("a", "#111", 5.0, 0.2), plots.Point("b", "#222", 40.0, 0.1, censored=True)]
    svg = plots.scatter_svg(points, uid="c", xlabel="lag", ylabel="f", censored_label="beyond")
    left, width = map(float, re.search(r'<clipPath id="c-clip"><rect x="([\d.]+)" y="[\d.]+" width="([\d.]+)"',
                                       svg).groups())
    tip = re.search(r'class="point[^"]* censored" data-renderer="b" d="M [\d.]+ [\d.]+ L ([\d.]+) ', svg)
    assert float(tip.group(1)) == pytest.approx(left + width)
    ticks = {t: float(x) for x, t in re.findall(r'class="tick x" x="([\d.]+)"[^>]*>(\d+)<', svg)}
    expected = ticks["20"] + math.log(2.0) / math.log(2.5) * (ticks["50"] - ticks["20"])
    start = re.search(r'class="censored-arrow" data-renderer="b" d="M ([\d.]+) ', svg)
    assert float(start.group(1)) == pytest.approx(expected, abs=0.02)
    assert ">beyond<" in svg and svg.count("censored-mark") == 2
    plain = plots.scatter_svg(points[:1] + [plots.Point("b", "#222", 40.0, 0.1)], uid="c", xlabel="lag", ylabel="f")
    assert "censored" not in plain


def test_place_tags_tries_each_side_then_drops():
    area = (0.0, 0.0, 200.0, 200.0)
    spots = plots.place_tags([(100, 100), (100, 100), (100, 100), (100, 100), (100, 100), (100, 100), (100, 100)],
                             [3.6] * 7, ["4", "1", "16", "64", "2", "8", "32"], area, 10.0)
    anchors = [a for _, _, a in spots]
    assert anchors[:6] == ["start", "start", "end", "end", "middle", "middle"] and anchors[6] == ""
    (x, y, anchor), = plots.place_tags([(5, 5)], [3.6], ["4"], area, 10.0)  # no room above: right-down
    assert anchor == "start" and x > 5 and y - ASCENT * 10 > 5
    (_, _, anchor), = plots.place_tags([(195, 195)], [3.6], ["4"], area, 10.0)  # in the corner: left-up
    assert anchor == "end"
    assert plots.place_tags([(50, 50)], [3.6], [""], area, 10.0) == [(0.0, 0.0, "")]


def _shapes(svg: str) -> tuple[dict[str, list], list[dict]]:
    """The bar chart's drawn boxes by renderer (bars, error bars, "≈ 0" marks) and each bar's x extent."""
    root = ET.fromstring(svg)
    font = float(root.get("font-size"))
    boxes: dict[str, list] = {}
    rects = []
    for el in root.iter():
        cls, name = el.get("class", ""), el.get("data-renderer")
        if cls == "bar":
            x, y, w, h = (float(el.get(k)) for k in ("x", "y", "width", "height"))
            boxes.setdefault(name, []).append((x, y, x + w, y + h))
            rects.append({"name": name, "kind": el.get("data-kind"), "x0": x, "x1": x + w})
        elif cls == "whisker":
            nums = [float(v) for v in re.findall(r"[-\d.]+", el.get("d"))]
            xs, ys = nums[0::2], nums[1::2]
            boxes.setdefault(name, []).append((min(xs), min(ys), max(xs), max(ys)))
        elif cls == "bar-missing":
            x, y = float(el.get("x")), float(el.get("y"))
            w = text_width(el.text, font)
            boxes.setdefault(name, []).append((x - w / 2, y - ASCENT * font, x + w / 2, y + DESCENT * font))
    return boxes, rects


def _notes_by_own_bars(svg: str, groups, near: bool = True) -> None:
    """Each group's note mark: whole, over its own bias² bar within a bar's width, above its group's highest
    box (``near``: just above), and clear of every other group's bars, error bars and marks."""
    texts = _check_layout(svg)
    marks = {t["name"]: t for t in texts if t["cls"] == "bar-note"}
    assert sorted(t["text"] for t in marks.values()) == sorted(g.note for g in groups if g.note)
    boxes, rects = _shapes(svg)
    font = float(ET.fromstring(svg).get("font-size"))
    for name, t in marks.items():
        bar = next((r for r in rects if r["name"] == name and r["kind"] == "bias²"), None)
        x0, y0, x1, y1 = t["box"]
        centre = (x0 + x1) / 2
        if bar is not None:  # a bar's width (its drawn width and the gap of 2 beside it)
            width = bar["x1"] - bar["x0"] + 2
            assert abs(centre - (bar["x0"] + bar["x1"]) / 2) <= width, (name, t, bar)
        own_top = min(b[1] for b in boxes[name])
        assert y1 <= own_top and (not near or own_top - y1 <= 2 * LINE * font + 5), (name, t["box"], own_top)
        for other, bs in boxes.items():
            if other != name:
                assert not any(overlaps(t["box"], b) for b in bs), (name, other)


def _bar_groups(names, short: bool = True):
    return [bars.BarGroup(n, [1e-3 * (i + 1) if i % 3 else -1e-5, 2e-3],
                          ("n.s." if short else "bias not significant") if i % 2 else f"{10 * i} %",
                          [5e-4, 1e-3], [2e-3, 3e-3]) for i, n in enumerate(names)]


@LAYOUTS
@pytest.mark.parametrize("names", [LONG, ["alpha", "beta", "gamma", "delta", "epsilon"],
                                   ["ambient-occlusion", "mitsuba", "pathtracer", "sppm", "bdpt", "photon-mapper"]])
def test_bar_names_whole_and_notes_by_their_bars(layout, names):
    groups = _bar_groups(names)
    svg = bars.bars_svg(groups, (("bias²", "#e69f00"), ("variance", "#56b4e9")), uid="b", ylabel="m",
                         layout=layout, note_key=["n %: bias² share", "n.s.: bias not significant"])
    texts = _check_layout(svg)
    assert [t["text"] for t in texts if t["cls"] == "tick x"] == names
    legend = [t["text"] for t in texts if t["cls"] == "legend-label"]
    assert legend[-2:] == ["n %: bias² share", "n.s.: bias not significant"]  # what the marks mean
    _notes_by_own_bars(svg, groups)


@LAYOUTS
@pytest.mark.parametrize("short", [True, False])
def test_crowded_bar_notes_stay_by_their_bars(layout, short):
    """Sixteen groups, every one noted, with bars up to the top of the plot: wider marks than a group's share
    stand upright; each still sits over its own bars, none meets another text or another group's bars. Long
    notes (taller upright than the plot's room) may go above the plot, still over their own bars."""
    names = [f"renderer-{i}" for i in range(16)]
    groups = _bar_groups(names, short)
    for i, g in enumerate(groups):
        g.values[1] = 10.0 ** (-(i % 4))  # tall and short neighbours
        g.note = g.note or "n.s."
    groups[1].note_tip = "bias not significant (its 95% interval reaches 0)"
    svg = bars.bars_svg(groups, (("bias²", "#e69f00"), ("variance", "#56b4e9")), uid="b", ylabel="m",
                         layout=layout)
    _notes_by_own_bars(svg, groups, near=short)
    assert "<title>renderer-1: bias not significant (its 95% interval reaches 0)</title>" in svg  # said in full


def test_bar_names_turn_vertical_only_when_they_do_not_wrap():
    slot, font = 60.0, 10.0
    lines, vertical, _ = bars.bar_names(["alpha", "beta-gamma"], slot, font)
    assert not vertical and lines == [["alpha"], ["beta-", "gamma"]]
    lines, vertical, depth = bars.bar_names(LONG[:2], slot, font)
    assert vertical and ["".join(ls) for ls in lines] == LONG[:2]
    assert depth >= max(text_width(line, font) for ls in lines for line in ls)


def test_place_notes_lifts_a_mark_off_a_neighbour_and_over_the_top_edge():
    font, top = 10.0, 50.0
    # group 1's mark would sit on group 0's error bar, which reaches over it: lifted a row at a time until free
    drawn = [[(40.0, 60.0, 46.0, 200.0)], [(52.0, 150.0, 60.0, 200.0)]]
    spots = bars.place_notes(["", "n.s."], [43.0, 56.0], drawn, top, font)
    assert spots[0] is None
    box = spots[1]
    assert box[3] <= 150 - 3 and not overlaps(box, drawn[0][0], 1.0) and box[1] > 60 - LINE * font - 12
    # a group reaching the plot's top edge: its mark goes above the edge, not across it
    (box,) = bars.place_notes(["n.s."], [43.0], [[(40.0, top + 2, 46.0, 200.0)]], top, font)
    assert box[3] < top  # above the edge, clear of it
    (box,) = bars.place_notes(["100 %"], [43.0], [[(40.0, 120.0, 46.0, 200.0)]], top, font, upright=True)
    assert box[2] - box[0] == pytest.approx((ASCENT + DESCENT) * font) and box[3] - box[1] == text_width("100 %", font)
