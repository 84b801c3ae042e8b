"""Every exported figure in a real browser: no text is cut, none overlaps another, all lie inside the figure.

A report with ``figures=True`` on a sweep whose setting names are long
(``pathtracer[sampler="independent",rr_depth=3]``), six renderers whose
speed/accuracy points nearly coincide (their spp tags would collide) and
bias/variance bars for all six; each SVG in ``figures/`` is opened by itself in
Chromium (the launcher of :mod:`tests.reports.test_report_browser`), and every
``<text>`` element's box, as the browser lays it out, is checked. Only the SVGs
are converted-free here: PDF and PNG come from the same SVG.
"""

from __future__ import annotations

import pytest

from tests import report_fixtures as rf
from tests.reports.test_report_browser import PAGE_TIMEOUT_MS, browser  # noqa: F401  (the fixture, reused)

#: name -> (noise per sample, bias, seconds per spp, approximations): the sweep's points nearly coincide.
SWEEP = {
    'pathtracer[sampler="independent",rr_depth=3]': (0.6, 0.0, 0.010, []),
    'pathtracer[sampler="sobol",rr_depth=3]': (0.58, 0.0, 0.0102, []),
    'mitsuba[integrator="volpath",max_depth=8]': (0.57, 0.0, 0.0104, []),
    "ambient-occlusion": (0.3, 0.1, 0.003, ["no indirect light"]),
    "mitsuba": (0.55, 0.0, 0.011, []),
    "sppm": (0.25, 0.04, 0.004, []),
}
#: Touching boxes are fine; this much overlap (CSS px) is not.
TOUCH_PX = 0.5


@pytest.fixture(scope="module")
def figures_dir(tmp_path_factory):
    from cornell_harness.reports import figures

    with pytest.MonkeyPatch.context() as mp:
        for name, params in SWEEP.items():
            mp.setitem(rf.RENDERERS, name, params)
        case = rf.make_case(16, 16, names=tuple(SWEEP), spps=(1, 2, 4, 8, 16), seeds=(0, 1), not_run=False)
        # two renderers whose bias is not significant: their note is the longer "bias not significant"
        case["summary"]["bias2_fraction_low"] = [-0.1, -0.1, 0.01, 0.2, 0.01, 0.05]
        mp.setattr(figures, "_converter", lambda: (None, "not needed: the test reads the SVGs"))
        path = rf.write_case(tmp_path_factory.mktemp("figs") / "report.html", case, figures=True)
    return path.parent / "figures"


#: For one <svg> (the document's, or each shown chart of the page): its box and each <text>'s class, own text
#: (without its <title> tooltip) and box, in CSS px as the browser lays them out.
_TEXT_BOXES = """svg => { const r = svg.getBoundingClientRect();
  const own = el => Array.from(el.childNodes).filter(n => n.nodeName !== 'title').map(n => n.textContent).join('');
  return {id: svg.id, svg: [r.left, r.top, r.right, r.bottom],
          texts: Array.from(svg.querySelectorAll('text')).map(el => { const b = el.getBoundingClientRect();
            return {cls: el.getAttribute('class') || '', text: own(el), box: [b.left, b.top, b.right, b.bottom]}; })};
}"""


def _meet(a, b) -> bool:
    return min(a[2], b[2]) - max(a[0], b[0]) > TOUCH_PX and min(a[3], b[3]) - max(a[1], b[1]) > TOUCH_PX


def test_every_figure_text_whole_apart_and_inside(browser, figures_dir):  # noqa: F811
    svgs = sorted(figures_dir.glob("*.svg"))
    kinds = {p.name.split("-")[0] for p in svgs}
    assert len(svgs) >= 10 and kinds == {"convergence", "speed", "bias", "images.svg"}, [p.name for p in svgs]
    ctx = browser.new_context(viewport={"width": 1400, "height": 1000}, device_scale_factor=1)
    ctx.set_default_timeout(PAGE_TIMEOUT_MS)
    pg = ctx.new_page()
    try:
        problems, tags = [], 0
        for path in svgs:
            pg.goto(path.as_uri(), wait_until="load")
            got = pg.evaluate_handle("document.documentElement").evaluate(_TEXT_BOXES)
            tags += sum(t["cls"] == "point-tag" for t in got["texts"])
            # the image grid (cornell_harness.reports.image_figure) has row labels, no legend of series: text checks only
            problems += _problems(path.name, got, bars=path.name.startswith("bias"), names=path.name != "images.svg")
        assert not problems, "\n".join(problems)
        assert tags >= 10  # the tags that fit are drawn (the others are in the points' tooltips)
    finally:
        ctx.close()


def test_page_charts_text_whole_and_apart(browser, figures_dir):  # noqa: F811
    """The same on the report page, whose stylesheet sets the charts' text sizes: every chart shown."""
    ctx = browser.new_context(viewport={"width": 1400, "height": 1000}, device_scale_factor=1)
    ctx.set_default_timeout(PAGE_TIMEOUT_MS)
    pg = ctx.new_page()
    try:
        pg.goto((figures_dir.parent / "report.html").as_uri(), wait_until="load")
        charts = pg.eval_on_selector_all(
            "svg.chart", f"svgs => svgs.filter(s => s.getBoundingClientRect().width > 0).map({_TEXT_BOXES})")
        assert {c["id"] for c in charts} >= {"conv-spp-rmse", "conv-time-rmse", "pareto-rmse", "bias-variance"}
        problems = [p for c in charts for p in _problems(c["id"], c, bars=c["id"] == "bias-variance")]
        assert not problems, "\n".join(problems)
    finally:
        ctx.close()


def _problems(where: str, got: dict, bars: bool, names: bool = True) -> list[str]:
    """What is wrong with one chart's text: cut, outside the chart, meeting another; a renderer not whole."""
    texts, (x0, y0, x1, y1) = [t for t in got["texts"] if t["text"].strip()], got["svg"]
    out = []
    for i, a in enumerate(texts):
        if a["text"].endswith("…"):
            out.append(f"{where}: cut: {a['text']!r}")
        b = a["box"]
        if not (x0 - TOUCH_PX <= b[0] and b[2] <= x1 + TOUCH_PX and y0 - TOUCH_PX <= b[1] and b[3] <= y1 + TOUCH_PX):
            out.append(f"{where}: outside the chart: {a['text']!r} {b} not in {got['svg']}")
        out += [f"{where}: {a['text']!r} meets {c['text']!r}: {b} {c['box']}"
                for c in texts[i + 1:] if _meet(b, c["box"])]
    legend = [t["text"] for t in texts if t["cls"] == "legend-label"]
    ticks = [t["text"] for t in texts if t["cls"] == "tick x"] if bars else []
    out += [f"{where}: {name!r} is not shown whole: {legend + ticks}" for name in SWEEP
            if names and name not in legend + ticks]
    return out
