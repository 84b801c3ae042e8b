"""The HTML report: self-contained, complete, escaped, and with a sound colour map."""

from __future__ import annotations

import base64
import io
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from harness.runner import RunRecord
from harness.scene import load_scene
from reports.html import DELTA_E_RANGE, apply_colormap, format_value, write_report

ROOT = Path(__file__).resolve().parent.parent
W = H = 16
EVIL = '<script>alert("x")</script> & more'


class _Collector(HTMLParser):
    """Collects every <img>, every src/href value and each <tr class="record">."""

    def __init__(self):
        super().__init__()
        self.imgs: list[dict] = []
        self.links: list[str] = []
        self.record_rows = 0
        self.scripts = 0

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img":
            self.imgs.append(a)
        if tag == "script":
            self.scripts += 1
        if tag == "tr" and "record" in (a.get("class") or "").split():
            self.record_rows += 1
        for key in ("src", "href"):
            if a.get(key):
                self.links.append(a[key])


@pytest.fixture(scope="module")
def scene():
    return load_scene(ROOT / "references" / "cornell-box").with_resolution(W, H)


@pytest.fixture(scope="module")
def reference():
    rng = np.random.default_rng(0)
    ref = rng.uniform(0.05, 1.0, (H, W, 3)).astype(np.float32)
    ref[:2, 6:10] = 20.0  # a bright "light"
    return ref


def _ok(scene, name, image, approximations=()):
    return RunRecord(
        scene.name, name, "ok", 16, 7, version="1.2.3", time_s=0.25, approximations=tuple(approximations),
        metrics={"rmse": 0.01, "rel_mse": 2e-4, "psnr": 35.1, "ssim": 0.93, "delta_e2000_mean": 1.2,
                 "delta_e2000_p95": 3.4, "delta_e2000_max": 12.0, "delta_e2000_frac_gt_2_3": 0.125,
                 "nan_count": 0, "inf_count": 0, "negative_count": 0, "mean_radiance_rel_error": -0.012,
                 "noise_rmse": 0.02, "noise_delta_e2000_mean": 1.5, "noise_mean_radiance_z": 0.4},
        image=np.asarray(image, dtype=np.float32),
    )


@pytest.fixture(scope="module")
def report(tmp_path_factory, scene, reference):
    rng = np.random.default_rng(1)
    noisy = reference * rng.uniform(0.8, 1.2, reference.shape).astype(np.float32)
    broken = reference.copy()
    broken[3, 3] = np.nan
    records = [
        _ok(scene, "alpha-tracer", noisy, ["no caustics", "light leaks at corners"]),
        _ok(scene, "beta-raster", reference * 1.1),
        _ok(scene, "gamma-nan", broken),
        RunRecord(scene.name, "delta-skip", "skipped", 16, 7, reason="does not model area_light"),
        RunRecord(scene.name, "epsilon-missing", "unavailable", 16, 7, reason="epsilon is not installed; pip install eps"),
        RunRecord(scene.name, "zeta-crash", "failed", 16, 7, reason=f"RuntimeError: {EVIL}",
                  info={"traceback": "Traceback ...\nRuntimeError: boom"}),
    ]
    prov = {"renderer": "mitsuba", "renderer_version": "3.9.1 (llvm_ad_rgb)", "variant": "llvm_ad_rgb",
            "spp": 4096, "batches": 64, "batch_spp": 64, "date": "2025-01-02T03:04:05+00:00",
            "scene_hash": scene.content_hash()}
    path = write_report(tmp_path_factory.mktemp("rep") / "sub" / "dir" / "report.html", scene=scene,
                        reference_image=reference, reference_provenance=prov, records=records,
                        command="cbox compare --spp 16 --seed 7")
    text = path.read_text(encoding="utf-8")
    parser = _Collector()
    parser.feed(text)
    return {"path": path, "text": text, "parser": parser, "records": records, "scene": scene}


def _decode(uri: str) -> Image.Image:
    prefix = "data:image/png;base64,"
    assert uri.startswith(prefix), uri[:40]
    im = Image.open(io.BytesIO(base64.b64decode(uri[len(prefix):], validate=True)))
    im.load()
    assert im.format == "PNG"
    return im


def test_file_written_atomically_into_new_folders(report):
    path = report["path"]
    assert isinstance(path, Path) and path.is_file() and path.name == "report.html"
    assert [p.name for p in path.parent.iterdir()] == ["report.html"]  # no temp file left behind
    assert report["text"].lstrip().lower().startswith("<!doctype html>")


def test_self_contained(report):
    text, parser = report["text"], report["parser"]
    assert not re.search(r"""(src|href)\s*=\s*["']?\s*(https?:)?//""", text, re.I)
    assert not re.search(r"url\(\s*['\"]?(https?:)?//", text, re.I)
    assert "@import" not in text
    for link in parser.links:
        assert link.startswith("data:") or link.startswith("#"), link
    assert parser.scripts == 0


def test_header(report):
    text, scene = report["text"], report["scene"]
    assert scene.name in text
    assert scene.content_hash() in text
    assert "3.9.1 (llvm_ad_rgb)" in text and "4096" in text and "2025-01-02T03:04:05+00:00" in text
    assert "cbox compare --spp 16 --seed 7" in text
    assert "16 spp, seed 7" in text
    assert "exposure" in text.lower()


def test_every_renderer_named(report):
    for rec in report["records"]:
        assert rec.renderer in report["text"]


def test_images_inlined_and_decodable(report):
    imgs = report["parser"].imgs
    for img in imgs:
        _decode(img["src"])  # every image decodes
    by_role = {}
    for img in imgs:
        by_role.setdefault(img.get("data-role"), []).append(img)
    assert len(by_role["reference"]) == 1 and _decode(by_role["reference"][0]["src"]).size == (W, H)
    assert len(by_role["colorbar"]) == 1
    ok = [r for r in report["records"] if r.status == "ok"]
    for role in ("render", "heatmap"):
        assert sorted(i["data-renderer"] for i in by_role[role]) == sorted(r.renderer for r in ok)
        for img in by_role[role]:
            im = _decode(img["src"])
            assert im.size == (W, H) and im.mode == "RGB"
    assert len(imgs) == 1 + 2 * len(ok) + 1
    # no images for records that did not run
    for rec in report["records"]:
        if rec.status != "ok":
            assert not any(i.get("data-renderer") == rec.renderer for i in imgs)


def test_rendered_images_use_the_shared_display_encoding(report, reference):
    from harness import metrics

    exposure = metrics.exposure_scale(reference)
    imgs = report["parser"].imgs
    ref_png = np.asarray(_decode(next(i for i in imgs if i.get("data-role") == "reference")["src"]))
    expected = np.round(metrics.display_encode(reference, exposure) * 255).astype(np.uint8)
    np.testing.assert_array_equal(ref_png, expected)
    beta = next(i for i in imgs if i.get("data-role") == "render" and i["data-renderer"] == "beta-raster")
    beta_png = np.asarray(_decode(beta["src"]))
    expected = np.round(metrics.display_encode(reference * 1.1, exposure) * 255).astype(np.uint8)
    assert np.abs(beta_png.astype(int) - expected).max() <= 1  # float32 rounding only


def test_heatmap_colours_are_delta_e(report, reference):
    from harness import metrics

    exposure = metrics.exposure_scale(reference)
    imgs = report["parser"].imgs
    beta = next(i for i in imgs if i.get("data-role") == "heatmap" and i["data-renderer"] == "beta-raster")
    _, de = metrics.delta_e2000(reference * 1.1, reference, exposure=exposure, full=True)
    np.testing.assert_array_equal(np.asarray(_decode(beta["src"])), apply_colormap(de))


def test_not_run_records_show_reason(report):
    text = report["text"]
    assert "does not model area_light" in text
    assert "epsilon is not installed; pip install eps" in text
    assert "RuntimeError: " in text
    for status in ("skipped", "unavailable", "failed"):
        assert status in text


def test_reason_is_escaped(report):
    text = report["text"]
    assert "<script>" not in text
    assert "&lt;script&gt;alert(&#34;x&#34;)&lt;/script&gt; &amp; more" in text
    assert report["parser"].scripts == 0


def test_metrics_table(report):
    text = report["text"]
    assert report["parser"].record_rows == len(report["records"])
    for key in ("rmse", "rel_mse", "psnr", "ssim", "delta_e2000_mean", "delta_e2000_p95", "delta_e2000_max",
                "delta_e2000_frac_gt_2_3", "nan_count", "inf_count", "negative_count", "mean_radiance_rel_error",
                "time_s", "spp", "version", "noise_rmse", "noise_delta_e2000_mean", "noise_mean_radiance_z"):
        assert f'data-key="{key}"' in text, key
    assert "35.10" in text and "0.9300" in text and "12.5 %" in text and "-1.20 %" in text


def test_approximations_listed(report):
    text = report["text"]
    assert "no caustics" in text and "light leaks at corners" in text


def test_colorbar_labelled(report):
    text = report["text"]
    assert 'id="colorbar"' in text
    lo, hi = DELTA_E_RANGE
    assert (lo, hi) == (0.0, 10.0)
    bar = next(i for i in report["parser"].imgs if i.get("data-role") == "colorbar")
    pixels = np.asarray(_decode(bar["src"]).convert("RGB"))
    np.testing.assert_array_equal(pixels[0, 0], apply_colormap(0.0))
    np.testing.assert_array_equal(pixels[0, -1], apply_colormap(10.0))
    for tick in ("0", "2", "4", "6", "8", "10"):
        assert re.search(rf'class="tick"[^>]*>{tick}\+?<', text), tick
    assert "2.3" in text


def _luminance(rgb_u8: np.ndarray) -> np.ndarray:
    c = rgb_u8.astype(np.float64) / 255.0
    lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return lin @ np.array([0.2126, 0.7152, 0.0722])


def test_colormap_is_perceptual_and_clipped():
    values = np.linspace(0.0, 10.0, 201)
    rgb = apply_colormap(values)
    assert rgb.shape == (201, 3) and rgb.dtype == np.uint8
    np.testing.assert_array_equal(apply_colormap(0.0), [68, 1, 84])  # viridis' first colour
    np.testing.assert_array_equal(apply_colormap(10.0), [253, 231, 37])  # and its last
    assert not np.array_equal(rgb[0], rgb[-1])
    y = _luminance(rgb)
    assert np.all(np.diff(y) >= 0) and y[-1] > 5 * y[0]  # monotone in luminance
    np.testing.assert_array_equal(apply_colormap(-3.0), rgb[0])  # clipped below
    np.testing.assert_array_equal(apply_colormap(250.0), rgb[-1])  # and above
    np.testing.assert_array_equal(apply_colormap(np.nan), rgb[-1])  # undefined reads as worst
    assert apply_colormap(np.zeros((4, 5))).shape == (4, 5, 3)


def test_format_value():
    assert format_value("psnr", None) == "—"
    assert format_value("psnr", float("inf")) == "∞"
    assert format_value("psnr", float("nan")) == "NaN"
    assert format_value("nan_count", 3) == "3"
    assert format_value("delta_e2000_frac_gt_2_3", 0.5) == "50.0 %"
    assert format_value("mean_radiance_rel_error", 0.0123) == "+1.23 %"
    assert format_value("rel_mse", 1.5e-6) == "1.500e-06"


def test_title_and_no_ok_records(tmp_path, scene, reference):
    records = [RunRecord(scene.name, "only-skipped", "skipped", 4, 0, reason="nothing to do")]
    path = write_report(tmp_path / "r.html", scene=scene, reference_image=reference, reference_provenance={},
                        records=records, title="My <b>title</b>")
    text = path.read_text(encoding="utf-8")
    assert "My &lt;b&gt;title&lt;/b&gt;" in text and "nothing to do" in text
    parser = _Collector()
    parser.feed(text)
    assert parser.record_rows == 1
    assert {i.get("data-role") for i in parser.imgs} == {"reference", "colorbar"}
