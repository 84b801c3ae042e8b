"""The HTML report in a real browser: it loads without errors, draws, and its controls work.

Drives Debian's ``chromium`` with Playwright (``pip install playwright``; the
browser comes from ``apt-get install chromium``, as ``playwright install``
cannot download one here). Skipped, with the reason, when either is missing.
A full-page screenshot is saved to ``test-output/report_browser.png``. Also a
standalone figure from ``figures/`` opened by itself, the light and dark themes
and their toggle and the print stylesheet (the navigation bar and wide tables: test_report_layout_browser.py).
"""

from __future__ import annotations

import io
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tests import report_fixtures as rf

ROOT = Path(__file__).resolve().parents[2]
OUT_DIR = ROOT / "test-output"
SCREENSHOT = OUT_DIR / "report_browser.png"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update"]
N = 64  # image size: big enough to look like the Cornell box, small enough to be quick


def _chromium() -> str | None:
    for candidate in (os.environ.get("CBOX_CHROMIUM"), "/usr/bin/chromium", shutil.which("chromium"),
                      shutil.which("chromium-browser")):
        if candidate and Path(candidate).is_file():
            return candidate
    return None


@pytest.fixture(scope="module")
def case():
    return rf.make_case(N, N)


@pytest.fixture(scope="module")
def report_url(tmp_path_factory, case):
    path = rf.write_case(tmp_path_factory.mktemp("browser") / "report.html", case, figures=True)
    return path.as_uri()


#: Playwright's limit on launching Chromium and on each page action (its default: 30 s). Only a hang guard: the
#: report loads and every action ends within a second or two on a quiet machine; Chromium's start under two CPU
#: burners or on a shared CI runner takes several times that, never this.
PAGE_TIMEOUT_MS = 180_000


@pytest.fixture(scope="module")
def browser():
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.skip("playwright is not installed (pip install playwright); needed to open the report in a browser")
    exe = _chromium()
    if exe is None:
        pytest.skip("chromium is not installed (apt-get install -y chromium; or set CBOX_CHROMIUM to its path)")
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=exe, args=CHROMIUM_ARGS, headless=True, timeout=PAGE_TIMEOUT_MS)
        try:
            yield b
        finally:
            b.close()


@pytest.fixture
def page(browser, report_url):
    ctx = browser.new_context(viewport={"width": 1400, "height": 1000}, device_scale_factor=1)
    ctx.set_default_timeout(PAGE_TIMEOUT_MS)
    pg = ctx.new_page()
    pg.errors = []  # console errors and uncaught exceptions
    pg.on("console", lambda m: pg.errors.append(f"console.{m.type}: {m.text}") if m.type == "error" else None)
    pg.on("pageerror", lambda e: pg.errors.append(f"pageerror: {e}"))
    pg.on("request", lambda r: pg.errors.append(f"network request: {r.url}")
          if not r.url.startswith(("file:", "data:", "blob:", "about:")) else None)
    pg.goto(report_url, wait_until="load")
    yield pg
    ctx.close()


def _no_errors(pg):
    assert pg.errors == [], f"browser errors (screenshot: {SCREENSHOT}): {pg.errors}"


def _view(pg) -> str:
    return pg.evaluate("document.getElementById('view').toDataURL()")


def _set_range(pg, selector: str, value: float) -> None:
    pg.evaluate(
        "([s, v]) => { const el = document.querySelector(s); el.value = v;"
        " el.dispatchEvent(new Event('input', {bubbles: true})); }",
        [selector, value],
    )


def test_loads_without_errors_and_screenshot(page):
    OUT_DIR.mkdir(exist_ok=True)
    page.screenshot(path=str(SCREENSHOT), full_page=True)
    assert SCREENSHOT.stat().st_size > 10_000, f"screenshot too small: {SCREENSHOT}"
    _no_errors(page)


def test_every_image_decodes(page):
    imgs = page.evaluate("Array.from(document.images).map(i => [i.getAttribute('data-mode'), i.complete, i.naturalWidth])")
    # The three colour bars, and the regions' overlay (the report's scene names regions).
    assert sorted(str(m) for m, _, _ in imgs) == ["None", "de", "flip", "relmse"], \
        f"expected the three colour bars and the regions overlay, got {imgs} (screenshot: {SCREENSHOT})"
    for mode, complete, width in imgs:
        assert complete and width > 0, f"image {mode} did not decode (screenshot: {SCREENSHOT})"
    _no_errors(page)


def test_every_canvas_is_drawn(page, case):
    stats = page.evaluate("""Array.from(document.querySelectorAll('canvas')).map(c => {
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        let sum = 0, min = 255, max = 0;
        for (let i = 0; i < d.length; i += 4) { const v = d[i] + d[i+1] + d[i+2]; sum += v;
          if (v < min) min = v; if (v > max) max = v; }
        return {id: c.id, cls: c.className, w: c.width, h: c.height, sum: sum, min: min, max: max};
    })""")
    ok_names = [n for n in case["images"]]
    assert len(stats) == 1 + len(ok_names), f"expected the viewer and one thumbnail per renderer: {stats}"
    for s in stats:
        assert s["w"] > 0 and s["h"] > 0 and s["sum"] > 0 and s["max"] > s["min"], (
            f"canvas {s} is blank (screenshot: {SCREENSHOT})")
    _no_errors(page)


def test_exposure_slider_changes_the_image_and_reset_restores_it(page):
    before = _view(page)
    _set_range(page, "#exposure", 2.5)
    brighter = _view(page)
    assert brighter != before, f"exposure slider did not change the canvas (screenshot: {SCREENSHOT})"
    assert page.inner_text("#exposure-val").startswith("+2.5")
    mean = "(() => { const c = document.getElementById('view'); const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data; let s = 0; for (let i = 0; i < d.length; i += 4) s += d[i] + d[i+1] + d[i+2]; return s; })()"
    s_bright = page.evaluate(mean)
    _set_range(page, "#exposure", -3)
    assert page.evaluate(mean) < s_bright, "lower exposure should darken the image"
    page.click("#exposure-reset")
    assert _view(page) == before, "reset should restore the initial exposure"
    _no_errors(page)


def test_flip_toggle_swaps_renderer_and_reference(page):
    before = _view(page)
    page.click("#flip-toggle")
    flipped = _view(page)
    assert flipped != before, f"flip toggle did not change the canvas (screenshot: {SCREENSHOT})"
    assert page.inner_text("#tag-left") == "reference"
    page.keyboard.press("f")  # the key does the same, and flips back
    assert _view(page) == before
    _no_errors(page)


def test_split_slider_moves_the_boundary(page):
    before = _view(page)
    _set_range(page, "#split", 100)  # all renderer
    all_renderer = _view(page)
    assert all_renderer != before
    _set_range(page, "#split", 0)  # all reference
    assert _view(page) not in (before, all_renderer)
    _no_errors(page)


def test_mode_switches_show_error_maps_with_legends(page):
    before = _view(page)
    seen = {before}
    for mode in ("de", "relmse", "flip"):
        page.click(f'#modes button[data-mode="{mode}"]')
        now = _view(page)
        assert now not in seen, f"mode {mode} did not change the canvas (screenshot: {SCREENSHOT})"
        seen.add(now)
        assert page.is_visible(f"#legend-{mode}"), f"legend of {mode} not shown"
        assert page.is_visible(f'#legend-{mode} img.bar')
        for other in ("de", "relmse", "flip"):
            if other != mode:
                assert not page.is_visible(f"#legend-{other}")
    page.keyboard.press("1")
    assert _view(page) == before
    _no_errors(page)


def test_zoom_and_pixel_readout(page, case):
    canvas = page.locator("#view")
    canvas.scroll_into_view_if_needed()
    box = canvas.bounding_box()
    before = _view(page)
    cx, cy = box["x"] + box["width"] * 0.3, box["y"] + box["height"] * 0.6
    page.mouse.move(cx, cy)
    for _ in range(6):
        page.mouse.wheel(0, -400)
    zoomed = _view(page)
    assert zoomed != before, f"wheel did not zoom (screenshot: {SCREENSHOT})"
    st = page.evaluate("({scale: cboxViewer.state.scale, fit: cboxViewer.state.fit})")
    assert st["scale"] / st["fit"] >= 16, f"zoom should reach 16x: {st}"
    page.screenshot(path=str(OUT_DIR / "report_browser_zoom.png"), clip=box)
    # pan by dragging
    page.mouse.move(cx, cy)
    page.mouse.down()
    page.mouse.move(cx + 60, cy + 40, steps=4)
    page.mouse.up()
    assert _view(page) != zoomed, "dragging did not pan"
    # the readout names the pixel under the cursor and its radiance (float16 as embedded)
    page.mouse.move(cx, cy)
    xy = page.inner_text("#ro-xy")
    x, y = (int(v) for v in xy.split(","))
    assert 0 <= x < N and 0 <= y < N
    name = next(iter(case["images"]))
    img = case["images"][name].astype(np.float16).astype(np.float64)
    ref = case["reference"].image.astype(np.float16).astype(np.float64)
    for c in range(3):
        got = float(page.inner_text(f"#ro-r{c}"))
        assert got == pytest.approx(img[y, x, c], rel=2e-3, abs=1e-6), (xy, c)
        got = float(page.inner_text(f"#ro-f{c}"))
        assert got == pytest.approx(ref[y, x, c], rel=2e-3, abs=1e-6), (xy, c)
    assert page.inner_text("#ro-de") != "—"
    page.click("#zoom-fit")
    assert _view(page) != zoomed
    _no_errors(page)


def test_renderer_picker(page, case):
    before = _view(page)
    buttons = page.locator("#picker button")
    assert buttons.count() == len(case["images"])
    buttons.nth(1).click()
    assert _view(page) != before
    assert page.inner_text("#tag-left") == list(case["images"])[1]
    _no_errors(page)


def test_table_sorts_on_click(page):
    def order():
        return page.evaluate(
            "Array.from(document.querySelectorAll('#summary-table tbody tr')).map(r => r.getAttribute('data-renderer'))")

    def values(key):
        return page.evaluate(
            f"Array.from(document.querySelectorAll('#summary-table tbody tr td[data-key=\"{key}\"]'))"
            ".map(td => td.getAttribute('data-sort')).filter(v => v !== '').map(Number)")

    page.click('#summary-table th[data-key="rmse"]')
    v = values("rmse")
    assert v == sorted(v) and len(v) == 3
    assert order()[-3:] == ["zeta-skip", "eta-missing", "theta-crash"]  # not-run rows last
    page.click('#summary-table th[data-key="rmse"]')
    assert values("rmse") == sorted(v, reverse=True)
    _no_errors(page)


def test_plots_present_and_metric_selector(page, case):
    n_ok = len(case["images"])
    for uid in ("conv-spp-rmse", "conv-time-rmse", "pareto-rmse"):
        assert page.is_visible(f"#{uid}"), uid
        assert page.locator(f"#{uid} path").count() > 0
    assert page.locator("#conv-spp-rmse path.series").count() == n_ok
    assert page.locator('#conv-spp-rmse path.guide[data-slope="-0.5"]').count() == 1
    assert page.locator("#pareto-rmse path.frontier").count() == 1
    assert page.locator("#bias-variance rect.bar").count() >= n_ok
    page.click('#convergence [data-metric-button="delta_e2000_mean"]')
    assert page.is_visible("#conv-spp-delta_e2000_mean") and not page.is_visible("#conv-spp-rmse")
    assert page.is_visible("#pareto-delta_e2000_mean") and not page.is_visible("#pareto-rmse")
    _no_errors(page)


# --------------------------------------------------------------------------
# Standalone figures, themes, print, navigation
# --------------------------------------------------------------------------


def _rgb(css: str) -> tuple[float, ...]:
    """'rgb(1, 2, 3)' or 'rgba(1, 2, 3, 0.5)' -> (1, 2, 3)."""
    return tuple(float(v) for v in css[css.index("(") + 1:css.index(")")].split(",")[:3])


def _lum(css: str) -> float:
    r, g, b = _rgb(css)
    return 0.2126 * r + 0.7152 * g + 0.0722 * b


def _context_page(browser, url: str, **options):
    ctx = browser.new_context(viewport={"width": 1400, "height": 1000}, device_scale_factor=1, **options)
    ctx.set_default_timeout(PAGE_TIMEOUT_MS)
    pg = ctx.new_page()
    pg.errors = []
    pg.on("pageerror", lambda e: pg.errors.append(f"pageerror: {e}"))
    pg.goto(url, wait_until="load")
    return ctx, pg


_FIGURE_PROBE = """() => {
  const svg = document.documentElement, vb = svg.viewBox.baseVal, r = svg.getBoundingClientRect();
  const shown = el => { const s = getComputedStyle(el);
    return s.display !== 'none' && s.visibility !== 'hidden' && parseFloat(s.opacity) > 0; };
  const pick = sel => Array.from(svg.querySelectorAll(sel)).map(el => { const b = el.getBBox();
    return {box: [b.x, b.y, b.x + b.width, b.y + b.height], shown: shown(el), stroke: getComputedStyle(el).stroke,
            text: el.textContent}; });
  return {tag: svg.tagName, viewBox: [vb.x, vb.y, vb.x + vb.width, vb.y + vb.height],
          client: [r.left, r.top, r.width, r.height], series: pick('path.series'), guide: pick('path.guide'),
          labels: pick('text.legend-label'), marks: pick('.legend-mark'),
          plotBg: getComputedStyle(svg.querySelector('.plot-bg')).fill,
          labelFill: getComputedStyle(svg.querySelector('text.legend-label')).fill};
}"""


def test_standalone_figure_renders_alone(browser, report_url, case):
    """A figure file opened by itself (no report stylesheet; the browser set to dark) shows its lines, guide
    and legend on a light background, all within its viewBox."""
    url = report_url.rsplit("/", 1)[0] + "/figures/convergence-spp-rmse.svg"
    ctx, pg = _context_page(browser, url, color_scheme="dark")
    try:
        f = pg.evaluate(_FIGURE_PROBE)
        x0, y0, x1, y1 = f["viewBox"]

        def meets_view(b):  # along a non-zero length (a flat series' box has no height)
            w, h = min(b[2], x1) - max(b[0], x0), min(b[3], y1) - max(b[1], y0)
            return w >= 0 and h >= 0 and max(w, h) > 0

        assert f["tag"] == "svg" and len(f["series"]) == len(case["images"]) and len(f["guide"]) == 1, f
        for el in f["series"] + f["guide"]:  # drawn, stroked, and (at least partly: the guide is clipped) in view
            assert el["shown"] and el["stroke"] != "none" and meets_view(el["box"]), el
        for el in f["series"]:
            assert x0 <= el["box"][0] and el["box"][2] <= x1 and y0 <= el["box"][1] and el["box"][3] <= y1, el
        assert [el["text"] for el in f["labels"]][:len(case["images"])] == list(case["images"])
        assert len(f["marks"]) == len(f["labels"]) == len(case["images"]) + 2  # renderers, band, guide
        for el in f["labels"] + f["marks"]:  # the whole legend inside the figure
            b = el["box"]
            assert el["shown"] and b[2] > b[0] and (b[3] > b[1] or not el["text"]), el  # a line mark is flat
            assert x0 <= b[0] and b[2] <= x1 and y0 <= b[1] and b[3] <= y1, (el, f["viewBox"])
        assert _lum(f["plotBg"]) > 250 and _lum(f["labelFill"]) < 60, (f["plotBg"], f["labelFill"])
        left, top, width, height = f["client"]
        shot = Image.open(io.BytesIO(pg.screenshot(clip={"x": left, "y": top, "width": width, "height": height})))
        lum = np.asarray(shot.convert("L"), dtype=np.float64)
        assert np.median(lum) > 240 and lum[:3, :3].min() > 250, "the figure's background should be light"
        assert (lum < 100).mean() > 0.002, "dark text and lines on it"
        assert pg.errors == []
    finally:
        ctx.close()


def _background(pg) -> float:
    return _lum(pg.evaluate("getComputedStyle(document.documentElement).backgroundColor"))


@pytest.mark.parametrize("scheme", ["light", "dark"])
def test_colour_scheme_followed_and_toggle_overrides_it(browser, report_url, scheme):
    ctx, pg = _context_page(browser, report_url, color_scheme=scheme)
    try:
        light = _background(pg) > 200
        assert light == (scheme == "light") and (_background(pg) < 60) == (scheme == "dark"), _background(pg)
        guide = pg.evaluate("""() => { const s = el => getComputedStyle(document.querySelector(el));
            return [s('#conv-spp-rmse .plot-bg').fill, s('#conv-spp-rmse path.guide').stroke,
                    s('#conv-spp-rmse .guide-mark').stroke]; }""")
        assert abs(_lum(guide[0]) - _lum(guide[1])) > 80 and guide[1] == guide[2], guide  # the guide shows
        pg.click("#theme-toggle")
        assert (_background(pg) > 200) == (not light) and (_background(pg) < 60) == light
        assert pg.evaluate("document.documentElement.getAttribute('data-theme')") == ("dark" if light else "light")
        pg.reload(wait_until="load")  # remembered
        assert (_background(pg) > 200) == (not light)
        assert pg.errors == []
    finally:
        ctx.close()


def test_print_is_light_without_sticky_bar_or_controls(browser, report_url):
    ctx, pg = _context_page(browser, report_url, color_scheme="dark")
    try:
        assert _background(pg) < 60 and pg.is_visible("nav.toc") and pg.is_visible("#theme-toggle")
        pg.emulate_media(media="print")
        assert _background(pg) > 240
        for selector in ("nav.toc", "#theme-toggle", ".metric-select", "#image-viewer .controls", ".downloads"):
            assert not pg.is_visible(selector), selector
        assert _lum(pg.evaluate("getComputedStyle(document.querySelector('#conv-spp-rmse .plot-bg')).fill")) > 240
        # The wide summary gives way to its split tables (tests/reports/test_report_print.py: on A4, in detail).
        assert not pg.is_visible("#summary-table") and pg.is_visible("table.print-split")
        fits = pg.evaluate("""() => Array.from(document.querySelectorAll('table.print-split')).every(t =>
            t.getBoundingClientRect().right <= document.body.getBoundingClientRect().right + 1)""")
        assert fits, "the summary's tables should fit the printed page's width"
    finally:
        ctx.close()


def test_decisive_columns_on_screen_without_scrolling(page):
    widths = page.evaluate("""() => { const th = k => document.querySelector(`#summary-table th[data-key="${k}"]`);
        return {page: document.documentElement.scrollWidth, view: window.innerWidth,
                wrap: document.querySelector('#summary .table-wrap').getBoundingClientRect().right,
                share: th('bias2_fraction').getBoundingClientRect().right}; }""")
    assert widths["page"] <= widths["view"], f"the page scrolls sideways: {widths}"
    assert widths["share"] <= widths["wrap"], f"the bias share column is off screen: {widths}"
