"""The HTML report: self-contained, complete, escaped, with exact embedded data and sound charts.

Synthetic inputs come from ``tests/report_fixtures.py``; the browser-side
behaviour is tested in ``tests/reports/test_report_browser.py``.
"""

from __future__ import annotations

import base64
import io
import json
import math
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from PIL import Image

from tests import report_fixtures as rf
from cornell_harness.evaluate import metrics
from cornell_harness.reports import images as report_images
from cornell_harness.reports.charts import SINGLE_SPP_NOTE
from cornell_harness.reports.html import write_report
from cornell_harness.reports.images import DELTA_E_RANGE, apply_colormap, f16_base64, f16_decode, rel_mse_map
from cornell_harness.reports.numbers import check_threshold, column_label, format_value, parse_time_to, value_note
from cornell_harness.reports.plotmath import format_tick, log_ticks, pareto_front

W = H = 32
OK_NAMES = ("alpha-tracer", "beta-photons", "gamma-raster")
NOT_RUN = {"zeta-skip": "skipped", "eta-missing": "unavailable", "theta-crash": "failed"}


class _Collector(HTMLParser):
    """Every tag with its attributes, in order; plus the text of <script> elements."""

    def __init__(self):
        super().__init__()
        self.tags: list[tuple[str, dict]] = []
        self.scripts: list[tuple[dict, str]] = []
        self._in_script: dict | None = None

    def handle_starttag(self, tag, attrs):
        a = {k: (v or "") for k, v in attrs}
        self.tags.append((tag, a))
        if tag == "script":
            self._in_script = a
            self.scripts.append((a, ""))

    def handle_endtag(self, tag):
        if tag == "script":
            self._in_script = None

    def handle_data(self, data):
        if self._in_script is not None:
            a, text = self.scripts[-1]
            self.scripts[-1] = (a, text + data)

    def find(self, tag=None, **attrs) -> list[dict]:
        out = []
        for t, a in self.tags:
            if tag and t != tag:
                continue
            if all((a.get(k.replace("_", "-")) == v) if v is not True else (k.replace("_", "-") in a)
                   for k, v in attrs.items()):
                out.append(a)
        return out


def _parse(text: str) -> _Collector:
    p = _Collector()
    p.feed(text)
    return p


def _data(parser: _Collector) -> dict:
    text = next(t for a, t in parser.scripts if a.get("id") == "cbox-data")
    return json.loads(text)


def _svg(text: str, uid: str) -> str:
    m = re.search(rf'<svg id="{re.escape(uid)}".*?</svg>', text, re.S)
    assert m, f"no svg {uid}"
    return m.group(0)


def _decode_png(uri: str) -> Image.Image:
    prefix = "data:image/png;base64,"
    assert uri.startswith(prefix), uri[:40]
    im = Image.open(io.BytesIO(base64.b64decode(uri[len(prefix):], validate=True)))
    im.load()
    return im


def _f16(b64: str, shape) -> np.ndarray:
    """Independent decoder: little-endian IEEE half floats."""
    raw = base64.b64decode(b64, validate=True)
    assert len(raw) == 2 * int(np.prod(shape))
    return np.frombuffer(raw, dtype="<f2").astype(np.float64).reshape(shape)


@pytest.fixture(scope="module")
def case():
    c = rf.make_case(W, H, names=OK_NAMES)
    # Thresholds that some renderers pass and some fail.
    top = c["runs"][(c["runs"]["status"] == "ok") & (c["runs"]["spp"] == 64)]
    med = top.groupby("renderer")["delta_e2000_mean"].median()
    c["thresholds"] = {"delta_e2000_mean": ("<=", float(med.median())), "ssim": (">=", 0.95),
                       "time_to_rel_mse_le_0.001": ("<=", 1.0)}
    return c


@pytest.fixture(scope="module")
def report(tmp_path_factory, case):
    path = rf.write_case(tmp_path_factory.mktemp("rep") / "sub" / "dir" / "report.html", case, figures=True)
    text = path.read_text(encoding="utf-8")
    return {"path": path, "text": text, "parser": _parse(text)}


# --------------------------------------------------------------------------
# The file
# --------------------------------------------------------------------------


def test_file_written_atomically_into_new_folders(report):
    path = report["path"]
    assert isinstance(path, Path) and path.is_file() and path.name == "report.html"
    # no temp file left behind, beside the report, among its figures or its images' PNGs
    assert sorted(p.name for p in path.parent.iterdir()) == ["figures", "images", "report.html", "summary-wide.tex",
                                                             "summary.csv", "summary.tex"]
    assert not [p.name for p in (path.parent / "figures").iterdir() if p.name.startswith(".")]
    assert not [p.name for p in (path.parent / "images").iterdir() if p.name.startswith(".")]
    assert report["text"].lstrip().lower().startswith("<!doctype html>")


def test_self_contained(report):
    text, parser = report["text"], report["parser"]
    assert "http://" not in text and "https://" not in text
    assert not re.search(r"""(src|href)\s*=\s*["']?\s*//""", text, re.I)
    for target in re.findall(r"url\(\s*['\"]?([^)'\"]*)", text, re.I):
        assert target.startswith("#") or target.startswith("data:"), target  # only in-document references
    assert "@import" not in text
    for tag, a in parser.tags:
        for key in ("src", "href"):
            if key in a:
                if tag == "a" and key == "href" and re.fullmatch(r"figures/[\w.-]+\.(svg|pdf|png)", a[key]):
                    continue  # a download link to a figure file beside the report: nothing the page loads
                assert a[key].startswith("data:") or a[key].startswith("#"), (tag, a[key][:60])
    for a, _ in parser.scripts:
        assert "src" not in a  # every script is inline
    assert not parser.find("link", rel="stylesheet")


def test_header_and_provenance(report, case):
    text = report["text"]
    scene, prov = case["scene"], case["provenance"]
    assert scene.name in text and scene.content_hash() in text
    assert "3.9.1 (llvm_ad_rgb)" in text and "2025-01-02T03:04:05+00:00" in text  # reference's provenance
    assert "4096 (64 batches × 64 spp)" in text  # reference spp
    assert case["command"] in text
    assert prov["machine"] in text and prov["date"] in text and "0, 1, 2" in text
    versions = text[text.index('id="versions"'):]
    for lib, ver in prov["versions"].items():
        assert f"<dt>{lib}</dt><dd>{ver}</dd>" in versions
    assert "<dt>threads</dt><dd>2</dd>" in text  # any other key is shown
    assert "exposure" in text.lower() and f"{metrics.exposure_scale(case['reference'].image):.4g}" in text


def test_every_renderer_appears(report):
    text, parser = report["text"], report["parser"]
    rows = [a["data-renderer"] for a in parser.find("tr") if "record" in a.get("class", "").split()]
    assert rows == [*OK_NAMES, *NOT_RUN]
    cards = [a["data-renderer"] for a in parser.find("div", **{"class": "card"})]
    assert cards == [*OK_NAMES, *NOT_RUN]
    for name in (*OK_NAMES, *NOT_RUN):
        assert name in text


def test_not_run_renderers_show_status_and_reason(report):
    text = report["text"]
    for name, status in NOT_RUN.items():
        row = re.search(rf'<tr class="record {status} not-ok" data-renderer="{name}">(.*?)</tr>', text, re.S)
        assert row, name
        assert f'<span class="badge {status}">{status}</span>' in row.group(1)
        assert 'class="reason"' in row.group(1)
    assert "does not model area_light" in text
    assert "eta is not installed; pip install eta" in text


def test_reason_and_names_are_escaped(report):
    text, parser = report["text"], report["parser"]
    assert "<script>alert" not in text
    assert "&lt;script&gt;alert(&#34;x&#34;)&lt;/script&gt; &amp; more" in text
    assert len(parser.scripts) == 2  # the data and the viewer, nothing injected


def test_title_names_and_json_escaped(tmp_path, case):
    evil = 'evil</script><b onmouseover="x">'
    images = {evil: case["images"]["alpha-tracer"]}
    runs = case["runs"][case["runs"]["renderer"] == "alpha-tracer"].assign(renderer=evil)
    path = write_report(tmp_path / "r.html", scene=case["scene"], reference=case["reference"], runs=runs,
                        images=images, provenance={}, title="My <b>title</b>")
    text = path.read_text(encoding="utf-8")
    parser = _parse(text)
    assert "My &lt;b&gt;title&lt;/b&gt;" in text
    assert "<b onmouseover" not in text and "<b>" not in text
    assert len(parser.scripts) == 2
    assert _data(parser)["renderers"][0]["name"] == evil  # the JSON round-trips the name exactly


# --------------------------------------------------------------------------
# Summary table
# --------------------------------------------------------------------------


def _cell(text: str, renderer: str, key: str) -> dict:
    row = re.search(rf'<tr class="record [^"]*" data-renderer="{re.escape(renderer)}">(.*?)</tr>', text, re.S)
    assert row, renderer
    m = re.search(rf'<td data-key="{re.escape(key)}" data-sort="([^"]*)"(?: class="([^"]*)")?(?: title="[^"]*")?>(.*?)</td>',
                  row.group(1), re.S)
    assert m, (renderer, key)
    return {"sort": m.group(1), "cls": (m.group(2) or "").split(), "text": m.group(3)}


def test_summary_rows_are_medians_at_max_spp(report, case):
    text = report["text"]
    runs = case["runs"]
    for name in OK_NAMES:
        top = runs[(runs["renderer"] == name) & (runs["spp"] == 64)]
        assert len(top) == 3
        for key in ("rmse", "delta_e2000_mean", "ssim", "time_s"):
            cell = _cell(text, name, key)
            assert float(cell["sort"]) == pytest.approx(float(top[key].median()), rel=1e-12), (name, key)
        assert _cell(text, name, "spp")["text"] == "64"
        assert _cell(text, name, "seeds")["text"] == "3"


def test_summary_figures_in_table(report, case):
    text = report["text"]
    summ = case["summary"].set_index("renderer")
    for key in ("slope_rmse_spp", "slope_rmse_time", "efficiency", "bias2", "variance", "bias2_fraction",
                "time_to_delta_e2000_mean_le_1", "time_to_rel_mse_le_0.001"):
        assert f'<th data-key="{key}"' in text, key
    for name in OK_NAMES:
        slope = _cell(text, name, "slope_rmse_spp")
        ci = summ.loc[name, "slope_rmse_spp_ci"]
        assert slope["text"] == f"{summ.loc[name, 'slope_rmse_spp']:+.2f} ± {ci:.2f}"
        frac = summ.loc[name, "bias2_fraction"]
        sort = _cell(text, name, "bias2_fraction")["sort"]
        assert (sort == "") if math.isnan(frac) else float(sort) == pytest.approx(frac), (name, sort, frac)
    assert _cell(text, "beta-photons", "time_to_delta_e2000_mean_le_1")["text"] == "not reached"
    assert "time to ΔE mean ≤ 1" in text and "time to relMSE ≤ 0.001" in text
    # the group headers
    for group in ("run", "error against the reference", "convergence", "bias / variance"):
        assert f">{group}</th>" in text


def test_threshold_colouring(report, case):
    text = report["text"]
    (_, limit), (_, ssim_limit) = case["thresholds"]["delta_e2000_mean"], case["thresholds"]["ssim"]
    seen = set()
    for name in OK_NAMES:
        de = _cell(text, name, "delta_e2000_mean")
        expected = "pass" if float(de["sort"]) <= limit else "fail"
        assert expected in de["cls"] and ({"pass", "fail"} - {expected}).isdisjoint(de["cls"]), (name, de)
        seen.add(expected)
        ss = _cell(text, name, "ssim")
        assert ("pass" if float(ss["sort"]) >= ssim_limit else "fail") in ss["cls"]
        # a column without a threshold is never coloured
        assert not {"pass", "fail"} & set(_cell(text, name, "rmse")["cls"])
    assert seen == {"pass", "fail"}  # the fixture's limit splits the renderers
    # NaN (target never reached) fails its threshold
    assert "fail" in _cell(text, "gamma-raster", "time_to_rel_mse_le_0.001")["cls"]
    assert "pass" in _cell(text, "alpha-tracer", "time_to_rel_mse_le_0.001")["cls"]
    legend = re.search(r'<span id="threshold-legend">(.*?)</span>\s*\n', text, re.S).group(1)
    assert "ΔE mean ≤" in legend and "SSIM ≥ 0.95" in legend and "passes" in legend and "fails" in legend
    # not-run rows carry no colouring
    for name in NOT_RUN:
        row = re.search(rf'data-renderer="{name}">(.*?)</tr>', text, re.S).group(1)
        assert not re.search(r'class="[^"]*\b(pass|fail)\b', row), name


def test_table_is_sortable_markup(report):
    parser = report["parser"]
    assert parser.find("table", id="summary-table")[0]["class"] == "summary sortable"
    heads = [a for a in parser.find("th") if "data-key" in a]
    assert {"renderer", "rmse", "delta_e2000_mean", "time_s"} <= {a["data-key"] for a in heads}
    js = next(t for a, t in parser.scripts if "id" not in a)
    assert "table.sortable" in js and "data-sort" in js


def test_bad_threshold_is_refused(tmp_path, case):
    with pytest.raises(ValueError, match="threshold"):
        rf.write_case(tmp_path / "r.html", case, thresholds={"ssim": ("=>", 0.9)})


# --------------------------------------------------------------------------
# Viewer data
# --------------------------------------------------------------------------


def test_hdr_images_embedded_and_decode(report, case):
    data = _data(report["parser"])
    assert (data["width"], data["height"]) == (W, H)
    assert data["exposure"] == pytest.approx(metrics.exposure_scale(case["reference"].image))
    ref = case["reference"].image
    got = _f16(data["reference"], (H, W, 3))
    np.testing.assert_array_equal(got, ref.astype(np.float16).astype(np.float64))
    np.testing.assert_allclose(got, ref, rtol=2**-11, atol=2**-24)
    assert [r["name"] for r in data["renderers"]] == list(OK_NAMES)
    for r in data["renderers"]:
        img = case["images"][r["name"]]
        np.testing.assert_allclose(_f16(r["img"], (H, W, 3)), img, rtol=2**-11, atol=2**-24)
        assert r["spp"] == 64 and r["seed"] == 0
        assert set(r["color"]) and r["color"].startswith("#")


def test_f16_keeps_nan_and_clips_huge_values():
    x = np.array([[[np.nan, 1e6, -1e6], [np.inf, 0.5, 1e-9]]])
    y = _f16(f16_base64(x), x.shape)
    assert np.isnan(y[0, 0, 0]) and y[0, 0, 1] == 65504 and y[0, 0, 2] == -65504
    assert y[0, 1, 0] == np.inf and y[0, 1, 1] == 0.5
    np.testing.assert_array_equal(f16_decode(f16_base64(x), x.shape), y.astype(np.float32))


def test_error_maps_embedded(report, case):
    data = _data(report["parser"])
    ref = case["reference"].image
    exposure = metrics.exposure_scale(ref)
    import flip_evaluator

    for r in data["renderers"]:
        img = case["images"][r["name"]]
        _, de = metrics.delta_e2000(img, ref, exposure=exposure, full=True)
        np.testing.assert_allclose(_f16(r["de"], (H, W)), de, rtol=2**-10, atol=1e-6)
        assert r["stats"]["de"] == pytest.approx(float(np.mean(de)))
        rel = rel_mse_map(img, ref)
        assert float(np.mean(rel)) == pytest.approx(metrics.rel_mse(img, ref), rel=1e-12)
        # embedded as log10: float16 keeps it to ~0.002 decades (0.5 %), far below one colour step
        np.testing.assert_allclose(_f16(r["relmse"], (H, W)), np.log10(np.maximum(rel, 1e-12)), atol=2.5e-3)
        fl, _, _ = flip_evaluator.evaluate(ref, img, "HDR", applyMagma=False)
        got = _f16(r["flip"], (H, W))
        np.testing.assert_allclose(got, fl[..., 0], atol=1e-3)
        assert 0 <= got.min() and got.max() <= 1
    maps = data["maps"]
    assert (maps["de"]["lo"], maps["de"]["hi"]) == DELTA_E_RANGE and maps["flip"]["available"]
    assert maps["relmse"]["log"] and maps["relmse"]["cmap"] == "inferno" and maps["flip"]["cmap"] == "magma"
    for name in ("viridis", "inferno", "magma"):
        lut = bytes.fromhex(data["colormaps"][name])
        assert len(lut) == 768
        np.testing.assert_array_equal(np.frombuffer(lut, np.uint8).reshape(256, 3)[[0, -1]],
                                      apply_colormap([0.0, 1.0], 0.0, 1.0, name))


def test_legends_have_colour_bars_and_ticks(report):
    text, parser = report["text"], report["parser"]
    bars = {a["data-mode"]: a for a in parser.find("img", data_role="colorbar")}
    assert set(bars) == {"de", "relmse", "flip"}
    for mode, a in bars.items():
        im = _decode_png(a["src"]).convert("RGB")
        px = np.asarray(im)
        cmap = report_images.MAP_COLORMAPS[mode]
        np.testing.assert_array_equal(px[0, 0], apply_colormap(0.0, 0, 1, cmap))
        np.testing.assert_array_equal(px[0, -1], apply_colormap(1.0, 0, 1, cmap))

    def ticks(mode):
        block = re.search(rf'id="legend-{mode}">(.*?)</div>\s*<p', text, re.S).group(1)
        return re.findall(r'class="tick[^"]*"[^>]*>([^<]*)<', block)

    assert ticks("de") == ["0", "2", "4", "6", "8", "10+"]
    assert ticks("relmse") == ["10⁻⁶", "10⁻⁵", "10⁻⁴", "0.001", "0.01", "0.1", "1"]
    assert ticks("flip") == ["0", "0.2", "0.4", "0.6", "0.8", "1"]
    assert "JND 2.3" in text
    for mode in ("image", "de", "relmse", "flip"):
        assert f'data-mode="{mode}"' in text  # a mode button each


def test_viewer_controls_present(report):
    parser = report["parser"]
    exposure = parser.find("input", id="exposure")[0]
    assert (exposure["min"], exposure["max"], exposure["value"]) == ("-8", "8", "0")
    assert parser.find("input", id="split") and parser.find("button", id="flip-toggle")
    assert parser.find("button", id="exposure-reset") and parser.find("canvas", id="view")
    assert len(parser.find("canvas", **{"class": "thumb"})) == len(OK_NAMES)
    js = next(t for a, t in parser.scripts if "id" not in a)
    assert "imageSmoothingEnabled = false" in js and "S.fit * 64" in js  # nearest neighbour, ≥ 16× zoom


def test_mismatched_image_is_noted_not_shown(tmp_path, case):
    images = dict(case["images"], **{"gamma-raster": np.zeros((8, 8, 3), np.float32)})
    text = rf.write_case(tmp_path / "r.html", case, images=images).read_text(encoding="utf-8")
    assert "gamma-raster: image shape (8, 8, 3) does not match" in text
    assert [r["name"] for r in _data(_parse(text))["renderers"]] == ["alpha-tracer", "beta-photons"]


# --------------------------------------------------------------------------
# Charts
# --------------------------------------------------------------------------


def test_convergence_plots_one_line_per_renderer_and_guide(report, case):
    text = report["text"]
    for metric, slope in (("rmse", "-0.5"), ("delta_e2000_mean", "-0.5"), ("rel_mse", "-1")):
        for axis in ("spp", "time"):
            svg = _svg(text, f"conv-{axis}-{metric}")
            series = re.findall(r'<path class="series" data-renderer="([^"]+)"', svg)
            assert series == list(OK_NAMES), (metric, axis)
            assert len(re.findall(rf'<path class="guide" data-slope="{slope}"', svg)) == 1
            # 3 seeds: a 95% CI band for each renderer whose seeds differ (the raster is deterministic)
            bands = re.findall(r'<path class="band" data-renderer="([^"]+)"', svg)
            assert bands == ["alpha-tracer", "beta-photons"], (metric, axis)
            assert "samples per pixel" in svg if axis == "spp" else "wall time (s)" in svg
            for name in OK_NAMES:
                assert f">{name}<" in svg  # legend
    assert "slope −½ (∝ 1/√N)" in _svg(text, "conv-spp-rmse")
    # Each series has one vertex per spp level, at the median over seeds.
    svg = _svg(text, "conv-spp-rmse")
    d = re.search(r'<path class="series" data-renderer="alpha-tracer" d="([^"]+)"', svg).group(1)
    assert d.count("L") == 2  # 3 spp levels
    # metric selector buttons
    assert 'data-metric-button="rmse"' in text and 'data-metric-button="delta_e2000_mean"' in text
    assert SINGLE_SPP_NOTE not in text


def test_guide_slope_is_minus_half_in_plot_coordinates(report):
    svg = _svg(report["text"], "conv-spp-rmse")
    d = re.search(r'<path class="guide"[^>]* d="M ([-\d.]+) ([-\d.]+) L ([-\d.]+) ([-\d.]+)"', svg).groups()
    x0, y0, x1, y1 = map(float, d)
    # axes are log-log; recover decades per pixel from two tick positions of each axis
    xt = {t: float(x) for x, t in re.findall(r'<text class="tick x" x="([-\d.]+)"[^>]*>([^<]+)<', svg)}
    yt = {t: float(y) for y, t in re.findall(r'<text class="tick y" x="[-\d.]+" y="([-\d.]+)"[^>]*>([^<]+)<', svg)}
    (ax, bx), (ay, by) = list(xt.items())[:2], list(yt.items())[:2]
    px_per_decade_x = (bx[1] - ax[1]) / (math.log10(float(bx[0])) - math.log10(float(ax[0])))
    px_per_decade_y = -(by[1] - 4 - (ay[1] - 4)) / (math.log10(float(by[0].replace("×", ""))) -
                                                   math.log10(float(ay[0].replace("×", ""))))
    slope = -((y1 - y0) / px_per_decade_y) / ((x1 - x0) / px_per_decade_x)
    assert slope == pytest.approx(-0.5, abs=0.01)


def test_pareto_front_pure_function():
    # time, error: points 0, 1, 4, 3 are non-dominated; 2 is beaten by 1.
    x = [1.0, 2.0, 3.0, 4.0, 2.5]
    y = [5.0, 3.0, 4.0, 1.0, 2.0]
    assert pareto_front(x, y) == [0, 1, 4, 3]
    # ties: an identical pair both stay; equal x with worse y is dominated
    assert pareto_front([1, 1, 1, 2], [2, 2, 3, 1]) == [0, 1, 3]
    # NaN and inf never on the front; empty input
    assert pareto_front([1, np.nan, 0.5, 3], [1, 0.1, np.inf, 0.5]) == [0, 3]
    assert pareto_front([], []) == []
    # a single point is its own front; brute force agrees on random data
    assert pareto_front([3], [4]) == [0]
    rng = np.random.default_rng(3)
    px, py = rng.random(60), rng.random(60)
    brute = [i for i in range(60) if not any(px[j] <= px[i] and py[j] <= py[i] and (px[j], py[j]) != (px[i], py[i])
                                             for j in range(60))]
    assert sorted(pareto_front(px, py)) == brute
    with pytest.raises(ValueError):
        pareto_front([1, 2], [1])


def test_speed_accuracy_chart_marks_the_frontier(report, case):
    svg = _svg(report["text"], "pareto-rmse")
    points = re.findall(r'<circle class="(point(?: on-front)?)" data-renderer="([^"]+)" cx="([-\d.]+)" cy="([-\d.]+)"',
                        svg)
    assert len(points) == len(OK_NAMES) * 3  # every (renderer, spp)
    ok = case["runs"][case["runs"]["status"] == "ok"]
    med = ok.groupby(["renderer", "spp"], sort=False)[["time_s", "rmse"]].median().reset_index()
    expected = {(r, s) for i, (r, s) in enumerate(zip(med["renderer"], med["spp"]))
                if i in pareto_front(med["time_s"], med["rmse"])}
    on_front = [p for p in points if p[0] == "point on-front"]
    assert len(on_front) == len(expected) >= 2
    assert len(re.findall(r'<path class="frontier" d="M [^"]+"', svg)) == 1
    front_d = re.search(r'<path class="frontier" d="M ([^"]+)"', svg).group(1)
    assert front_d.count("L") == len(expected) - 1
    for _, _, cx, cy in on_front:
        assert f"{cx} {cy}" in front_d


def test_bias_variance_bars(report, case):
    svg = _svg(report["text"], "bias-variance")
    bars = re.findall(r'<rect class="bar" data-renderer="([^"]+)" data-kind="([^"]+)"', svg)
    summ = case["summary"].set_index("renderer")
    expected = [(n, k) for n in OK_NAMES for k, col in (("bias²", "bias2"), ("variance", "variance"))
                if summ.loc[n, col] > 0]
    assert bars == expected
    for n in OK_NAMES:
        if summ.loc[n, "bias2_fraction"] == summ.loc[n, "bias2_fraction"]:
            pct = f"{100 * summ.loc[n, 'bias2_fraction']:.0f} %"
            assert f">{pct}<title>" in svg and f"bias {pct}" in svg  # the mark over the bars, its tooltip
    assert ">bias²<" in svg and ">variance<" in svg  # legend


def test_region_bias_variance_table(tmp_path, case):
    """An experiment's summary on a scene with regions (cornell-box's four): a bias²/variance table per (renderer,
    region) in the bias/variance section, with the numbers of convergence.region_bias_variance."""
    from cornell_harness.evaluate.convergence import bias_significant, region_bias_variance
    from cornell_harness.evaluate.regions import region_masks
    from cornell_harness.evaluate.summary import REGION_SPLIT, summary_table

    ref, sc = case["reference"], case["scene"]
    images = {n: [case["raw"][n, s, 64] for s in (0, 1, 2)] for n in OK_NAMES}
    summary = summary_table(case["runs"], images, ref, sc)
    masks = region_masks(sc)
    assert list(masks) == ["walls", "boxes", "floor", "light", "back-edge"]
    text = rf.write_case(tmp_path / "r.html", case, summary=summary).read_text(encoding="utf-8")
    i = text.index('<section id="bias-variance-section">')
    section = text[i:text.index("</section>", i)]
    assert 'id="bias-variance"' in section  # the image-wide bars stay
    rows = re.findall(r'<tr class="record ok">(.*?)</tr>', section[section.index('id="region-bias-variance-table"'):])
    assert len(rows) == len(OK_NAMES) * len(masks)
    expected = [(n, region, values) for n in OK_NAMES
                for region, values in region_bias_variance(images[n], ref.image, ref.variance, masks).items()]
    for row, (name, region, values) in zip(rows, expected):
        assert f'data-sort="{name}"' in row and f'data-sort="{region}"' in row
        for key, v in values.items():
            assert summary.set_index("renderer").loc[name, f"region.{region}.{key}"] == pytest.approx(v, nan_ok=True)
            if key not in REGION_SPLIT:  # the bounds: shown inside the cells, not as columns
                assert f'data-key="{key}"' not in row
                continue
            sort = re.search(rf'data-key="{key}" data-sort="([^"]*)"', row).group(1)
            assert sort == (repr(float(v)) if math.isfinite(v) else "")
        share = re.search(r'data-key="bias2_fraction"[^>]*>([^<]*)</td>', row).group(1)
        # A share whose 95% interval reaches 0 reads "not significant", never a number.
        assert (share == "not significant") == (bias_significant(values["bias2_fraction_low"]) is False), (name, region)
        if share != "not significant" and math.isfinite(values["bias2_fraction_low"]):
            assert "–" in share  # the share with its interval
    # The noise-free raster's variance is 0: all of its error is bias, significant; the unbiased tracer's is not.
    assert summary.set_index("renderer").loc["gamma-raster", "region.walls.bias2_fraction"] == 1.0
    assert bias_significant(summary.set_index("renderer").loc["gamma-raster", "region.walls.bias2_fraction_low"])
    assert not bias_significant(summary.set_index("renderer").loc["alpha-tracer", "bias2_fraction_low"])
    assert "not significant" in section
    # Without region columns (a summary from before them): no table, the bars alone.
    plain = rf.write_case(tmp_path / "p.html", case).read_text(encoding="utf-8")
    assert 'id="region-bias-variance-table"' not in plain and 'id="bias-variance"' in plain


def test_single_spp_compare_omits_convergence_gracefully(tmp_path):
    case = rf.make_case(W, H, names=OK_NAMES, spps=(16,), seeds=(0,), with_summary=False)
    path = rf.write_case(tmp_path / "compare.html", case, thresholds={"mse": ("<", 1.0)})
    text = path.read_text(encoding="utf-8")
    assert SINGLE_SPP_NOTE in text
    assert "line-plot" not in text and 'class="series"' not in text
    svg = _svg(text, "pareto-rmse")  # one point per renderer, still a speed/accuracy picture
    assert len(re.findall(r'<circle class="point', svg)) == len(OK_NAMES)
    assert "No bias/variance figures" in text
    assert "16 spp, seed 0" in text
    for name in OK_NAMES:
        assert _cell(text, name, "spp")["text"] == "16"
        assert "pass" in _cell(text, name, "mse")["cls"]  # a threshold on a column not shown by default
    assert ">other thresholds</th>" in text


def test_only_not_run_renderers(tmp_path, case):
    runs = case["runs"][case["runs"]["status"] != "ok"]
    text = write_report(tmp_path / "r.html", scene=case["scene"], reference=case["reference"], runs=runs,
                        images={}, provenance={}).read_text(encoding="utf-8")
    assert "No renderer images to show." in text and SINGLE_SPP_NOTE in text
    assert "no successful runs" in text
    for name in NOT_RUN:
        assert name in text


def test_approximations_and_settings_listed(report):
    text = report["text"]
    assert "<li>no caustics</li>" in text and "<li>light leaks at corners</li>" in text
    assert "<li>density estimation blurs the lighting</li>" in text
    assert "<dt>max_depth</dt><dd>-1</dd>" in text


def test_report_size_256_five_renderers(tmp_path):
    names = tuple(rf.RENDERERS)
    assert len(names) == 5
    case = rf.make_case(256, 256, names=names, spps=(16, 64), seeds=(0,), not_run=False)
    path = rf.write_case(tmp_path / "big.html", case)
    size = path.stat().st_size
    assert size < 10 * 1024 * 1024, f"report is {size / 2**20:.1f} MiB"
    assert len(_data(_parse(path.read_text(encoding="utf-8")))["renderers"]) == 5


# --------------------------------------------------------------------------
# Small pure pieces
# --------------------------------------------------------------------------


def _luminance(rgb_u8: np.ndarray) -> np.ndarray:
    c = rgb_u8.astype(np.float64) / 255.0
    lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return lin @ np.array([0.2126, 0.7152, 0.0722])


@pytest.mark.parametrize("cmap", ["viridis", "inferno", "magma"])
def test_colormaps_are_perceptual_and_clipped(cmap):
    values = np.linspace(0.0, 10.0, 201)
    rgb = apply_colormap(values, 0.0, 10.0, cmap)
    assert rgb.shape == (201, 3) and rgb.dtype == np.uint8
    y = _luminance(rgb)
    assert np.all(np.diff(y) >= -1e-9) and y[-1] > 5 * y[0] + 0.01  # monotone in luminance
    np.testing.assert_array_equal(apply_colormap(-3.0, 0, 10, cmap), rgb[0])  # clipped below
    np.testing.assert_array_equal(apply_colormap(250.0, 0, 10, cmap), rgb[-1])  # and above
    np.testing.assert_array_equal(apply_colormap(np.nan, 0, 10, cmap), rgb[-1])  # undefined reads as worst


def test_viridis_ends():
    np.testing.assert_array_equal(apply_colormap(0.0), [68, 1, 84])
    np.testing.assert_array_equal(apply_colormap(10.0), [253, 231, 37])
    assert apply_colormap(np.zeros((4, 5))).shape == (4, 5, 3)


def test_format_value():
    assert format_value("psnr", None) == "—"
    assert format_value("psnr", float("inf")) == "∞"
    assert format_value("psnr", float("nan")) == "NaN"
    assert format_value("nan_count", 3) == "3"
    assert format_value("delta_e2000_frac_gt_2_3", 0.5) == "50.0 %"
    assert format_value("mean_radiance_rel_error", 0.0123) == "+1.23 %"
    assert format_value("rel_mse", 1.5e-6) == "1.500e-06"
    assert format_value("slope_rmse_spp", -0.5) == "-0.50"
    assert format_value("time_to_rel_mse_le_0.001", 12.3456) == "12.346"
    assert format_value("bias2_fraction", 0.25) == "25.0 %"


def test_time_to_columns_and_thresholds():
    assert parse_time_to("time_to_delta_e2000_mean_le_1") == ("delta_e2000_mean", "<=", 1.0)
    assert parse_time_to("time_to_rel_mse_le_0.001") == ("rel_mse", "<=", 0.001)
    assert parse_time_to("time_to_ssim_ge_0.95") == ("ssim", ">=", 0.95)
    assert parse_time_to("rmse") is None
    assert column_label("time_to_rel_mse_le_0.001")[0] == "time to relMSE ≤ 0.001"
    assert column_label("noise_foo_bar")[0] == "foo bar (noise)"
    assert check_threshold(3.0, "<=", 3.0) and not check_threshold(3.0, "<", 3.0)
    assert check_threshold(0.95, ">=", 0.9) and not check_threshold(0.85, ">", 0.9)
    assert not check_threshold(float("nan"), "<=", 3.0) and not check_threshold(None, ">=", 0.0)
    with pytest.raises(ValueError):
        check_threshold(1.0, "=<", 2.0)


def test_axis_ticks():
    assert log_ticks(0.0, 3.0) == [1.0, 10.0, 100.0, 1000.0]
    assert log_ticks(0.0, math.log10(64), base2=True) == [1, 2, 4, 8, 16, 32, 64]
    assert len(log_ticks(0.0, math.log10(2**20), base2=True)) <= 9
    assert log_ticks(-0.2, 0.4) == [1.0, 2.0]
    assert format_tick(1e-6) == "10⁻⁶" and format_tick(2e-5) == "2×10⁻⁵" and format_tick(0.01) == "0.01"


# --------------------------------------------------------------------------
# Standalone figures, table order, negative bias², title
# --------------------------------------------------------------------------

SVG_NS = "{http://www.w3.org/2000/svg}"
FIGURE_STEMS = [f"{kind}-{metric}" for kind in ("convergence-spp", "convergence-time", "speed-accuracy")
                for metric in ("rmse", "delta_e2000_mean", "rel_mse")] + ["bias-variance"]


def _figure_root(report, stem: str):
    import xml.etree.ElementTree as ET

    return ET.parse(report["path"].parent / "figures" / f"{stem}.svg").getroot()  # parses as XML on its own


def _viewbox(root) -> tuple[float, float]:
    x0, y0, w, h = map(float, root.get("viewBox").split())
    assert (x0, y0) == (0, 0)
    return w, h


def test_figures_are_written_and_linked(report):
    from cornell_harness.reports.figures import COLUMN_WIDTH_IN, PNG_DPI, _converter

    folder, text = report["path"].parent / "figures", report["text"]
    for stem in FIGURE_STEMS:
        assert (folder / f"{stem}.svg").is_file(), stem
        assert f'<a href="figures/{stem}.svg" download>SVG</a>' in text, stem
    if _converter()[0] is None:
        pytest.skip(f"PDF/PNG figures not checked: {_converter()[1]}")
    for stem in FIGURE_STEMS:
        assert (folder / f"{stem}.pdf").read_bytes().startswith(b"%PDF-"), stem
        w, h = _viewbox(_figure_root(report, stem))
        with Image.open(folder / f"{stem}.png") as im:
            im.load()
            rgb = np.asarray(im.convert("RGB"), dtype=np.float64)
        assert rgb.shape[1] == pytest.approx(COLUMN_WIDTH_IN * PNG_DPI, abs=1), stem  # column width at print dpi
        assert rgb.shape[1] / rgb.shape[0] == pytest.approx(w / h, rel=0.01), stem
        luminance = rgb.mean(axis=2)
        assert np.median(luminance) > 240 and luminance[:4, :4].min() > 250, stem  # white, not transparent/black
        assert (luminance < 80).mean() > 0.002, stem  # dark text and lines drawn on it
        for fmt in ("PDF", "PNG"):
            assert f'<a href="figures/{stem}.{fmt.lower()}" download>{fmt}</a>' in text, (stem, fmt)
    assert 'id="figures-note"' not in text


def test_standalone_svg_styles_itself_for_print(report, case):
    from cornell_harness.reports.figures import COLUMN_WIDTH_IN

    root = _figure_root(report, "convergence-spp-rmse")
    assert root.tag == f"{SVG_NS}svg"
    w, h = _viewbox(root)
    assert root.get("width") == f"{COLUMN_WIDTH_IN:g}in"
    assert float(root.get("height").removesuffix("in")) == pytest.approx(COLUMN_WIDTH_IN * h / w, abs=1e-3)
    style = root.find(f"{SVG_NS}style").text
    for cls in (".plot-bg", ".grid", ".axis", ".guide", "text"):
        assert cls in style, cls
    points = [float(v) * COLUMN_WIDTH_IN * 72 / w for v in re.findall(r"font-size:([\d.]+)px", style)]
    assert points and min(points) >= 7, points  # readable in print at column width
    first = [el for el in root if el.tag != f"{SVG_NS}style"][0]
    assert first.get("class") == "figure-bg" and first.get("fill") == "#fff" and float(first.get("height")) == h
    series = root.findall(f".//{SVG_NS}path[@class='series']")
    assert [s.get("data-renderer") for s in series] == list(OK_NAMES)
    assert len(root.findall(f".//{SVG_NS}path[@class='guide']")) == 1
    labels = root.findall(f".//{SVG_NS}text[@class='legend-label']")
    assert [el.text for el in labels] == [*OK_NAMES, "95% CI over seeds", "slope −½ (∝ 1/√N)"]
    plot_bottom = max(float(r.get("y")) + float(r.get("height")) for r in root.iter(f"{SVG_NS}rect")
                      if r.get("class") == "axis")
    for el in labels:  # below the plot, inside the viewBox, with room for the longest label's estimated width
        x, y = float(el.get("x")), float(el.get("y"))
        assert plot_bottom < y < h and 0 < x and x + 0.62 * 13 * len(el.text) <= w, (el.text, x, y, w, h)


def test_figures_without_converter_are_svg_only_and_say_so_once(tmp_path, case, monkeypatch, capsys):
    from cornell_harness.reports import figures

    monkeypatch.setattr(figures, "_converter", lambda: (None, "cairosvg is not installed (test)"))
    monkeypatch.setattr(figures, "_said", set())
    stale = tmp_path / "a" / "figures" / "speed-accuracy-gone.pdf"
    mine = tmp_path / "a" / "figures" / "notes.txt"
    stale.parent.mkdir(parents=True)
    stale.write_bytes(b"%PDF-")
    mine.write_text("mine")
    paths = [rf.write_case(tmp_path / d / "report.html", case, figures=True) for d in ("a", "b")]
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("cbox: note: ") and "cairosvg is not installed (test)" in err[0]
    written = sorted(p.name for p in (paths[0].parent / "figures").iterdir())
    assert {n.rsplit(".", 1)[1] for n in written} == {"svg", "txt"} and "notes.txt" in written  # stale PDF gone
    text = paths[0].read_text(encoding="utf-8")
    assert "cairosvg is not installed (test)" in text and 'id="figures-note"' in text
    assert 'href="figures/convergence-spp-rmse.svg"' in text and 'href="figures/convergence-spp-rmse.pdf"' not in text


def test_summary_leads_with_the_decisive_columns(report):
    keys = [a["data-key"] for a in report["parser"].find("th") if "data-key" in a]
    decisive = ["slope_rmse_spp", "slope_rmse_time", "time_to_delta_e2000_mean_le_1", "time_to_rel_mse_le_0.001",
                "efficiency", "bias2_fraction"]
    assert keys[:2] == ["renderer", "status"] and keys[2:2 + len(decisive)] == decisive, keys
    assert keys.index("bias2_fraction") < min(keys.index(k) for k in ("spp", "time_s", "rmse", "ssim", "version"))


def test_negative_bias2_reads_approximately_zero(case):
    from cornell_harness.reports.html import render_html

    assert format_value("bias2", -8.6e-06) == "≈ 0" and format_value("region.walls.bias2", -1e-9) == "≈ 0"
    assert format_value("bias2", 8.6e-06) == "8.600e-06" and format_value("variance", -1e-4) == "-1.000e-04"
    assert "−8.6e-06" in value_note("bias2", -8.6e-06) and "noise" in value_note("bias2", -8.6e-06)
    assert value_note("bias2", 8.6e-06) == "" and value_note("bias2", float("nan")) == ""
    summary = case["summary"].copy()
    summary.loc[summary["renderer"] == "alpha-tracer", "bias2"] = -8.6e-06
    kwargs = {k: case[k] for k in ("scene", "reference", "runs", "images", "thresholds", "provenance")}
    text = render_html(**kwargs, summary=summary)
    cell = _cell(text, "alpha-tracer", "bias2")
    assert cell["text"] == "≈ 0" and float(cell["sort"]) == -8.6e-06  # sorts on the raw estimate
    row = re.search(r'data-renderer="alpha-tracer">(.*?)</tr>', text, re.S).group(1)
    assert re.search(r'<td data-key="bias2" [^>]*title="estimate −8.6e-06: below zero by noise', row)
    assert "-8.600e-06" not in row  # the raw estimate is not printed as a value
    assert _cell(text, "beta-photons", "bias2")["text"] != "≈ 0"


def test_title_option_reaches_the_report(tmp_path, capsys, monkeypatch):
    """`--title` of compare, converge and report is the title write_experiment_report gets (which puts it in
    the page: test_title_names_and_json_escaped). In-process; the report writer records instead of writing,
    and converge's experiment is stubbed: only the options' wiring is under test here."""
    import pandas as pd

    import cornell_harness.reports.experiment
    from cornell_harness.cli.app import main
    from cornell_harness.evaluate.summary import ExperimentResults
    from cornell_harness.workflows import converge as converge_workflow

    titles = []

    def record(out, scene, reference, thresholds=None, sections=(), title=None, **_):
        titles.append(title)
        return Path(out) / "report.html"

    def cbox(*args: str) -> None:
        with pytest.raises(SystemExit) as done:
            main(list(args))
        assert done.value.code == 0, capsys.readouterr().err

    monkeypatch.setattr(cornell_harness.reports.experiment, "write_experiment_report", record)
    nothing = pd.DataFrame({"renderer": [], "status": [], "reason": []})
    monkeypatch.setattr(converge_workflow, "run_experiment", lambda *a, **k: nothing)
    monkeypatch.setattr(converge_workflow, "experiment_results",
                        lambda *a, **k: ExperimentResults({}, nothing, {}, pd.DataFrame()))
    out = tmp_path / "cmp"
    cbox("compare", "--scene", "cornell-box", "-r", "tests.user_renderers:FlatGrey", "--spp", "1", "--out", str(out),
         "--title", "Paper <figure> 1")
    cbox("report", str(out), "--title", "Rebuilt")
    cbox("report", str(out))
    cbox("converge", "--scene", "cornell-box", "-r", "tests.user_renderers:FlatGrey", "--spp", "1,2", "--seeds", "1",
         "--out", str(tmp_path / "conv"), "--title", "Converged")
    assert titles == ["Paper <figure> 1", "Rebuilt", None, "Converged"]


# --------------------------------------------------------------------------
# Intervals and timing quality (issue 30)
# --------------------------------------------------------------------------


def _timed(runs: pd.DataFrame, load: float, repeats: bool = True) -> pd.DataFrame:
    """The case's runs with the timing columns of issue 30: loads of ``load`` runnable threads, one thread per
    render, a steady calibration kernel, and (``repeats``) three timings of each row around its time_s."""
    ok = runs["status"] == "ok"
    out = runs.assign(cpu_time_s=runs["time_s"] * 1.5, setup_s=0.1, threads=1.0, calibration_s=0.01,
                      load_before=load, load_after=load)
    if repeats:
        out["time_samples_s"] = [json.dumps([t * 0.95, t, t * 1.1]) if k else None for t, k in zip(runs["time_s"], ok)]
        out["cpu_time_samples_s"] = [json.dumps([t * 1.4, t * 1.5, t * 1.6]) if k else None
                                     for t, k in zip(runs["time_s"], ok)]
    return out


def test_timing_badge_good_contended_unknown(tmp_path, case):
    """The header and the run panel carry the timing-quality badge with timing_quality's figures behind it."""
    unknown = _parse(rf.write_case(tmp_path / "u.html", case).read_text(encoding="utf-8"))
    assert [a["data-timing"] for a in unknown.find("span", data_timing=True)] == ["unknown", "unknown"]
    for load, state in ((1.0, "good"), (9.0, "contended")):
        text = rf.write_case(tmp_path / f"{state}.html", case, runs=_timed(case["runs"], load), cores=4)\
            .read_text(encoding="utf-8")
        badges = _parse(text).find("span", data_timing=True)
        assert [a["data-timing"] for a in badges] == [state, state]
        n = int((case["runs"]["status"] == "ok").sum())
        contended = n if state == "contended" else 0
        assert f"{contended} of {n} timed renders contended; load up to {load:.1f} runnable threads beside " \
               "renders of 1 on 4 cores" in text
        assert ("warning: the machine was busy" in badges[0]["title"]) == (state == "contended")


def test_intervals_in_table_charts_and_summary_file(tmp_path, case):
    """A summary from summary_table: summary.parquet holds every figure's bounds; the table shows them beside the
    figure; the time charts draw 95% CI bands and time whiskers, labelled so; an unbiased renderer's bias share
    reads "not significant"."""
    from cornell_harness.evaluate.convergence import bias_significant, target_column
    from cornell_harness.evaluate.summary import summary_table

    runs = _timed(case["runs"], 1.0)
    images = {n: [case["raw"][n, s, 64] for s in (0, 1, 2)] for n in OK_NAMES}
    summary = summary_table(runs, images, case["reference"], case["scene"])
    summary.to_parquet(tmp_path / "summary.parquet", index=False)
    csv = pd.read_parquet(tmp_path / "summary.parquet").set_index("renderer")
    for fig in ("efficiency", "slope_rmse_time", "time_at_max_spp", target_column("rel_mse", 1e-2), "bias2",
                "variance", "bias2_fraction"):
        for end in ("low", "high"):
            assert f"{fig}_{end}" in csv.columns, (fig, end)
    assert set(csv["interval_basis"]) == {"seeds and timing repeats"}
    tracer = csv.loc["alpha-tracer"]
    assert tracer["efficiency_low"] < tracer["efficiency"] < tracer["efficiency_high"]
    text = rf.write_case(tmp_path / "r.html", case, runs=runs, summary=summary).read_text(encoding="utf-8")
    eff = _cell(text, "alpha-tracer", "efficiency")
    assert re.fullmatch(r"[0-9.e+-]+ \([0-9.e+-]+–[0-9.e+-]+\)", eff["text"]), eff
    assert "95% confidence intervals over seeds and timing repeats; times are wall time (time_s)" in text
    share = _cell(text, "alpha-tracer", "bias2_fraction")["text"]
    assert bias_significant(tracer["bias2_fraction_low"]) is False and share == "not significant"
    assert _cell(text, "gamma-raster", "bias2_fraction")["text"].startswith("100.0 %")  # all bias, significant
    svg = _svg(text, "conv-time-rmse")
    assert ">95% CI over seeds<" in svg and ">95% CI of the time<" in svg and "min–max" not in svg
    assert len(re.findall(r'<path class="whisker" data-renderer="alpha-tracer" data-axis="x"', svg)) == 3
    pareto = _svg(text, "pareto-rmse")
    assert re.search(r'<path class="whisker" data-renderer="beta-photons" data-axis="y"', pareto)
    bars = _svg(text, "bias-variance")
    assert "bias not significant" in bars and re.search(r'<path class="whisker" data-renderer="alpha-tracer"', bars)
    # --time-basis cpu: the figures and the time axes follow the CPU clock
    cpu = summary_table(runs, images, case["reference"], case["scene"], time_column="cpu_time_s")
    assert cpu.set_index("renderer").loc["alpha-tracer", "efficiency"] == pytest.approx(tracer["efficiency"] / 1.5)
    text = rf.write_case(tmp_path / "c.html", case, runs=runs, summary=cpu).read_text(encoding="utf-8")
    assert "CPU time (s)" in _svg(text, "conv-time-rmse") and "times are CPU time (cpu_time_s)" in text
    assert "<h3>against CPU time</h3>" in text and "<h3>against wall time</h3>" not in text
