"""The report printed on A4 in a real browser: the ~30-column summary split into tables of at most 8 columns
(src/cornell_harness/reports/print_tables.py), nothing wider than the page, a reasonable page count.

Uses the Chromium launcher of tests/reports/test_report_browser.py (skipped, with the reason, without Playwright
or chromium). The report is the synthetic case of tests/report_fixtures.py with the summary
:func:`cornell_harness.evaluate.summary.summary_table` makes of it (every figure with its bounds, four times to a target,
the per-region split) and thresholds: about 30 columns on screen.
"""

from __future__ import annotations

import re

import pytest

from cornell_harness.evaluate.summary import summary_table
from cornell_harness.reports.print_tables import MAX_COLUMNS, column_chunks, print_tables
from tests import report_fixtures as rf
from tests.reports.test_report_browser import PAGE_TIMEOUT_MS, browser  # noqa: F401 (the fixture)

#: The width between the report's print margins (report.css: @page margin 14mm 12mm) on A4 at 96 dpi:
#: (210 − 2 × 12) mm = 186 mm = 703 CSS px.
PRINTABLE_PX = round((210 - 2 * 12) / 25.4 * 96)
#: A4 pages the report may take: its header, summary, images, charts and cards print in about 6.
MAX_PAGES = 8


@pytest.fixture(scope="module")
def wide_report(tmp_path_factory):
    case = rf.make_case(64, 64)
    names = ("alpha-tracer", "beta-photons", "gamma-raster")
    images = {n: [case["raw"][n, s, 64] for s in (0, 1, 2)] for n in names}
    summary = summary_table(case["runs"], images, case["reference"], case["scene"])
    return rf.write_case(tmp_path_factory.mktemp("print") / "report.html", case, summary=summary)


_TABLES = """() => Array.from(document.querySelectorAll('table')).filter(t => t.getClientRects().length > 0)
  .map(t => ({id: t.id, cls: t.className, right: t.getBoundingClientRect().right,
              width: t.getBoundingClientRect().width,
              columns: Math.max(...Array.from(t.rows).map(r => Array.from(r.cells)
                                  .reduce((n, c) => n + c.colSpan, 0)))}))"""


def test_print_splits_the_summary_and_fits_a4(browser, wide_report):  # noqa: F811 (the fixture)
    ctx = browser.new_context(viewport={"width": PRINTABLE_PX, "height": 1000}, device_scale_factor=1)
    ctx.set_default_timeout(PAGE_TIMEOUT_MS)
    try:
        pg = ctx.new_page()
        pg.goto(wide_report.as_uri(), wait_until="load")
        screen = pg.evaluate(_TABLES)
        wide = [t for t in screen if t["id"] == "summary-table"]
        assert wide and wide[0]["columns"] >= 28, f"the test needs a wide summary: {wide}"
        assert not [t for t in screen if "print-split" in t["cls"]], "the split tables show on screen"

        pg.emulate_media(media="print")
        printed = pg.evaluate(_TABLES)
        assert not [t for t in printed if t["id"] == "summary-table"], "the wide table prints"
        split = [t for t in printed if "print-split" in t["cls"]]
        assert len(split) >= -(-(wide[0]["columns"] - 1) // MAX_COLUMNS), split
        for t in printed:
            assert t["columns"] <= MAX_COLUMNS + 1, t
            assert t["width"] <= PRINTABLE_PX + 0.5 and t["right"] <= PRINTABLE_PX + 0.5, t
        overflow = pg.evaluate("document.documentElement.scrollWidth")
        assert overflow <= PRINTABLE_PX, f"the printed page scrolls sideways: {overflow} px > {PRINTABLE_PX}"
        canvas = pg.evaluate("(() => { const r = document.getElementById('view').getBoundingClientRect();"
                             " return [r.width, r.height]; })()")
        assert canvas[1] == pytest.approx(canvas[0], abs=2), f"the 64 × 64 image prints as {canvas}"
        charts = pg.evaluate("""() => Array.from(document.querySelectorAll('svg.chart'))
            .filter(s => s.getClientRects().length > 0).map(s => s.getBoundingClientRect().right)""")
        assert charts and max(charts) <= PRINTABLE_PX + 0.5, charts

        pdf = pg.pdf(format="A4")
        pages = len(re.findall(rb"/Type\s*/Page(?![s\w])", pdf))
        assert 1 <= pages <= MAX_PAGES, f"{pages} A4 pages"
    finally:
        ctx.close()


def test_column_chunks_keep_groups_whole_where_they_fit():
    assert column_chunks([("a", 3), ("b", 4), ("c", 3)], 8) == [[0, 1, 2, 3, 4, 5, 6], [7, 8, 9]]
    assert column_chunks([("a", 1), ("b", 11)], 4) == [[0], [1, 2, 3, 4], [5, 6, 7, 8], [9, 10, 11]]
    assert column_chunks([("a", 0), ("b", 2)], 8) == [[0, 1]]


def test_print_tables_repeat_the_renderer_and_keep_every_cell():
    head = {"head": [{"title": "", "span": 2}, {"title": "convergence", "span": 9}],
            "cols": [{"key": "renderer"}, {"key": "status"}] + [{"key": f"k{i}"} for i in range(9)]}
    ok = {"renderer": "a", "status": "ok", "cells": [{"key": c["key"], "text": c["key"]} for c in head["cols"]]}
    bad = {**ok, "renderer": "b", "status": "failed", "reason": "boom"}
    tables = print_tables(head, [ok, bad])
    assert [len(t["cols"]) for t in tables] == [1, 8, 1]  # status alone: the group of 9 does not fit beside it
    assert [c["text"] for t in tables for c in t["rows"][0]["cells"]] == [c["key"] for c in head["cols"][1:]]
    assert all(t["rows"][0]["renderer_cell"]["text"] == "renderer" for t in tables)
    assert [len(t["rows"]) for t in tables] == [2, 1, 1]  # a renderer that did not run: its reason once
    assert tables[1]["head"] == [{"title": "convergence", "span": 8}]
    labelled = print_tables(head, [ok, bad], series_labels={"a": "PT (independent)"})
    assert [r["renderer_cell"]["text"] for r in labelled[0]["rows"]] == ["PT (independent)", "renderer"]
