"""The report's layout in a real browser: navigation lands below the sticky bar, the bar hides what scrolls
under it, and a wide table scrolls in its own box instead of widening the page.

The report is the synthetic case of tests/report_fixtures.py with extra sections like ``cbox demo``'s (a scene's
comparison, a region table per scene, more than fit one line of the bar), one of them a table far wider than the
window. Uses the Chromium launcher of tests/reports/test_report_browser.py (skipped, with the reason, without
Playwright or chromium).
"""

from __future__ import annotations

import pytest

from tests import report_fixtures as rf
from tests.reports.test_report_browser import PAGE_TIMEOUT_MS, browser  # noqa: F401 (the fixture)

WIDTH = 1400  # CSS px: a laptop's window
WIDE_COLUMNS = 60  # columns of the wide table: several windows wide


def _sections(case) -> list[tuple[str, str, str]]:
    from cornell_harness.reports.scenes import scene_section

    rows = case["runs"].to_dict("records")
    scene = scene_section(case["scene"], case["reference"].image, rows, case["images"], "caustics/report.html")
    head = "".join(f"<th>region number {i}</th>" for i in range(WIDE_COLUMNS))
    cells = "".join(f'<td class="num">{i / 7:.6f}</td>' for i in range(WIDE_COLUMNS))
    wide = (f'<div class="table-wrap" id="wide-wrap"><table class="summary"><thead><tr class="cols">{head}</tr>'
            f"</thead><tbody><tr>{cells}</tr></tbody></table></div>")
    sections = [("cornell-box-caustics", "cornell-box-caustics", scene),
                ("caustics-whitted", "Recursive ray tracing and its hacks", wide)]
    # More sections, so that the bar wraps onto three lines at WIDTH (a fixed scroll margin covered the title).
    sections += [(f"scene-{i}", f"cornell-box-variant-{i} comparison", "<p>text</p>") for i in range(8)]
    return sections


@pytest.fixture(scope="module")
def report_url(tmp_path_factory):
    case = rf.make_case(32, 32)
    path = rf.write_case(tmp_path_factory.mktemp("layout") / "report.html", case, sections=_sections(case))
    return path.as_uri()


@pytest.fixture
def page(browser, report_url):  # noqa: F811 (the fixture)
    def open_page(width: int = WIDTH, scheme: str = "light"):
        ctx = browser.new_context(viewport={"width": width, "height": 900}, device_scale_factor=1,
                                  reduced_motion="reduce", color_scheme=scheme)
        ctx.set_default_timeout(PAGE_TIMEOUT_MS)
        contexts.append(ctx)
        pg = ctx.new_page()
        pg.errors = []
        pg.on("pageerror", lambda e: pg.errors.append(f"pageerror: {e}"))
        pg.goto(report_url, wait_until="load")
        return pg

    contexts = []
    yield open_page
    for ctx in contexts:
        ctx.close()


_NAV_AND_TITLE = """id => [document.querySelector('nav.toc').getBoundingClientRect().bottom,
    document.getElementById(id).querySelector('h2').getBoundingClientRect().top, window.scrollY]"""


@pytest.mark.parametrize("width", [WIDTH, 900])
def test_every_navigation_link_lands_below_the_sticky_bar(page, width):
    pg = page(width)
    nav = pg.evaluate("document.querySelector('nav.toc').getBoundingClientRect().height")
    assert nav > 80, f"the bar should wrap onto several lines here ({nav} px), else the test shows nothing"
    targets = pg.evaluate("Array.from(document.querySelectorAll('nav.toc a')).map(a => a.hash.slice(1))")
    assert "caustics-whitted" in targets and "how-to-read" in targets, targets
    for target in targets:
        pg.click(f'nav.toc a[href="#{target}"]')
        bottom, title, scrolled = pg.evaluate(_NAV_AND_TITLE, target)
        if scrolled + 1 >= pg.evaluate("document.documentElement.scrollHeight - window.innerHeight"):
            assert title >= bottom, (target, bottom, title)  # the page's end: as far as it scrolls
            continue
        assert bottom + 2 <= title < bottom + 40, (target, bottom, title)  # below the bar, not far below
    assert pg.errors == []


@pytest.mark.parametrize("scheme", ["light", "dark"])
def test_the_sticky_bar_is_opaque(page, scheme):
    pg = page(scheme=scheme)
    colour = pg.evaluate("getComputedStyle(document.querySelector('nav.toc')).backgroundColor")
    parts = [float(v) for v in colour[colour.index("(") + 1:colour.index(")")].split(",")]
    assert colour.startswith("rgb") and len(parts) in (3, 4), colour
    alpha = parts[3] if len(parts) == 4 else 1.0
    assert alpha == 1.0, f"the bar lets the content show through: {colour}"


def test_a_wide_table_scrolls_in_its_box_not_the_page(page):
    pg = page()
    sizes = pg.evaluate("""() => { const w = document.getElementById('wide-wrap');
        return {page: document.documentElement.scrollWidth, view: window.innerWidth,
                table: w.querySelector('table').getBoundingClientRect().width, box: w.clientWidth,
                scrolls: w.scrollWidth, overflow: getComputedStyle(w).overflowX}; }""")
    assert sizes["table"] > sizes["view"], f"the table should be wider than the window: {sizes}"
    assert sizes["page"] <= sizes["view"], f"the page scrolls sideways: {sizes}"
    assert sizes["box"] < sizes["scrolls"] and sizes["overflow"] == "auto", f"the box should scroll: {sizes}"
    pg.evaluate("document.getElementById('wide-wrap').scrollLeft = 10000")
    assert pg.evaluate("document.getElementById('wide-wrap').scrollLeft") > 0
