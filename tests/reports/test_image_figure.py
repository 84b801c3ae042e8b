"""The paper's image grid (cornell_harness.reports.image_figure): cells, crops, colour bars, files; no rendering.

The images are the stored cornell-box-caustics reference box-filtered to 64², a noisy copy and a 10 % bright
copy of it; the regions are the scene's own (caustic, glass-shadow, mirror, glass, walls).
"""

from __future__ import annotations

import base64
import io
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from PIL import Image

from cornell_harness.evaluate import metrics
from cornell_harness.evaluate.regions import region_masks
from cornell_harness.reports import image_figure as fig
from cornell_harness.reports.images import DELTA_E_RANGE, apply_colormap, error_maps, to_uint8
from cornell_harness.reports.regions import region_color
from tests import report_fixtures as rf

N = 64
SVG = "{http://www.w3.org/2000/svg}"
LABELS = {"pt": "PT (independent)"}


@pytest.fixture(scope="module")
def case():
    from cornell_harness.scenes.library import resolve_scene
    from cornell_harness.store.references import load_reference

    full = resolve_scene("cornell-box-caustics")
    big = np.asarray(load_reference(full).image, dtype=np.float64)
    k = big.shape[0] // N
    ref = big.reshape(N, k, N, k, 3).mean(axis=(1, 3)).astype(np.float32)
    rng = np.random.default_rng(1)
    images = {"pt": (ref * rng.uniform(0.5, 1.5, ref.shape)).astype(np.float32),
              "biased": (ref * 1.1).astype(np.float32)}
    return {"scene": full.with_resolution(N, N), "ref": ref, "images": images,
            "exposure": metrics.display_exposure(ref)}


def _write(tmp_path, case, **kw):
    out = fig.write_image_figure(tmp_path, scene=case["scene"], reference_image=case["ref"], images=case["images"],
                                 exposure=case["exposure"], series_labels=kw.pop("series_labels", LABELS), **kw)
    return out, ET.parse(tmp_path / "figures" / "images.svg").getroot()


@pytest.fixture(scope="module")
def written(tmp_path_factory, case):
    tmp = tmp_path_factory.mktemp("grid")
    out, svg = _write(tmp, case)
    return {"dir": tmp, "out": out, "svg": svg}


def _by_class(svg, tag: str, cls: str) -> list:
    return [e for e in svg.iter(SVG + tag) if e.get("class") == cls]


def _png(path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"))


def _uri_pixels(uri: str) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(uri.split(",", 1)[1]))).convert("RGB"))


def test_crops_are_the_small_named_regions(case):
    crops = fig.choose_crops(case["scene"], (N, N))
    names = list(region_masks(case["scene"]))
    assert names == ["caustic", "glass-shadow", "mirror", "glass", "walls"]
    # The walls' box is most of the image: no zoom, left out; the rest in the scene's order and colours.
    assert [c.name for c in crops] == ["caustic", "glass-shadow", "mirror", "glass"]
    masks = region_masks(case["scene"])
    for c in crops:
        assert c.color == region_color(names.index(c.name))
        ys, xs = np.nonzero(masks[c.name])
        assert c.x <= xs.min() and xs.max() < c.x + c.w and c.y <= ys.min() and ys.max() < c.y + c.h
        assert c.x >= 0 and c.y >= 0 and c.x + c.w <= N and c.y + c.h <= N
        assert max(c.w, c.h) <= fig.MAX_ASPECT * min(c.w, c.h) + 1


def test_region_box_padding_clamping_and_thinness():
    mask = np.zeros((40, 50), dtype=bool)
    mask[0, 0] = True  # one pixel in the corner: at least MIN_CROP a side, inside the image
    assert fig.region_box(mask) == (0, 0, fig.MIN_CROP, fig.MIN_CROP)
    mask[:] = False
    mask[20, 5:45] = True  # a line 40 px long: widened to at most 3:1, centred on it
    x, y, w, h = fig.region_box(mask)
    assert x <= 5 and x + w >= 45 and w <= 50 and w <= fig.MAX_ASPECT * h + 1 and y <= 20 < y + h
    assert fig.region_box(np.zeros((4, 4), dtype=bool)) is None


def test_one_image_per_cell_and_crop(written, case):
    svg = written["svg"]
    crops = fig.choose_crops(case["scene"], (N, N))
    cells = 1 + 3 * len(case["images"])  # the reference's image; each renderer's image, ΔE and FLIP maps
    assert len(_by_class(svg, "image", "cell")) == cells
    assert len(_by_class(svg, "image", "inset")) == cells * len(crops)
    headers = [t.text for t in _by_class(svg, "text", "column-header")]
    assert headers == ["image", "ΔE₀₀ (CIEDE2000)", "FLIP"]
    rows = {g.get("data-row"): " ".join(t.text for t in g.iter(SVG + "text")) for g in _by_class(svg, "g", "row-label")}
    assert rows == {"reference": "reference", "pt": "PT (independent)", "biased": "biased"}


def test_one_colour_bar_per_map_with_ticks(written):
    bars = _by_class(written["svg"], "g", "colorbar")
    assert sorted(b.get("data-map") for b in bars) == ["de", "flip"]
    for bar in bars:
        assert len(list(bar.iter(SVG + "image"))) == 1
        ticks = [t.text for t in bar.iter(SVG + "text") if t.get("class") == "tick"][1:]  # after the title
        assert ticks == (["0", "2", "4", "6", "8", "10+"] if bar.get("data-map") == "de"
                         else ["0", "0.2", "0.4", "0.6", "0.8", "1"])


def test_crop_frames_have_the_region_colours(written, case):
    crops = fig.choose_crops(case["scene"], (N, N))
    colors = [c.color for c in crops]
    cells = 1 + 3 * len(case["images"])
    for cls in ("crop-frame", "inset-frame"):
        strokes = [r.get("stroke") for r in _by_class(written["svg"], "rect", cls)]
        assert strokes == colors * cells, cls
    # A frame in the full image sits on the crop's pixels (one cell is 240 units for 64 px).
    first = _by_class(written["svg"], "rect", "crop-frame")[0]
    cell = _by_class(written["svg"], "image", "cell")[0]
    s = float(cell.get("width")) / N
    c = crops[0]
    assert float(first.get("x")) == pytest.approx(float(cell.get("x")) + c.x * s, abs=0.01)
    assert float(first.get("y")) == pytest.approx(float(cell.get("y")) + c.y * s, abs=0.01)
    assert float(first.get("width")) == pytest.approx(c.w * s, abs=0.01)


def test_pngs_are_the_exact_pixels(written, case):
    folder = written["dir"] / "images"
    img, ref = case["images"]["pt"], case["ref"]
    tone = to_uint8(metrics.display_encode(img, case["exposure"]))
    assert np.array_equal(_png(folder / "pt.png"), tone)
    assert np.array_equal(_png(folder / "reference.png"), to_uint8(metrics.display_encode(ref, case["exposure"])))
    de = error_maps(img, ref, case["exposure"])["de"]
    assert np.array_equal(_png(folder / "pt.delta_e2000.png"), apply_colormap(de, *DELTA_E_RANGE, "viridis"))
    for c in fig.choose_crops(case["scene"], (N, N)):
        crop = _png(folder / f"pt.crop-{c.name}.png")
        assert crop.shape == (c.h, c.w, 3) and np.array_equal(crop, tone[c.y:c.y + c.h, c.x:c.x + c.w])
    # The insets embedded in the SVG are those pixels too (the pt row's first inset is its caustic).
    insets = _by_class(written["svg"], "image", "inset")
    n_crops = len(fig.choose_crops(case["scene"], (N, N)))
    assert np.array_equal(_uri_pixels(insets[n_crops].get("href")), _png(folder / "pt.crop-caustic.png"))
    names = {p.name for p in folder.iterdir()}
    assert {"pt.flip.png", "biased.flip.crop-glass.png", "reference.crop-caustic.png"} <= names
    assert not any(n.startswith("reference.delta_e2000") for n in names)
    assert sorted(written["out"]["pngs"]) == sorted(f"images/{n}" for n in names)


def test_pdf_and_png_written(written):
    out = written["out"]
    assert out["figure"] == [("SVG", "figures/images.svg"), ("PDF", "figures/images.pdf"),
                             ("PNG", "figures/images.png")]
    assert (written["dir"] / "figures" / "images.pdf").read_bytes().startswith(b"%PDF")
    png = Image.open(written["dir"] / "figures" / "images.png")
    assert png.width == round(fig.WIDTH_IN * 300)


def test_given_crops_replace_the_regions(tmp_path, case):
    out, svg = _write(tmp_path, case, crops=[(2, 3, 10, 20), (60, 60, 10, 10)])
    assert [r.get("stroke") for r in _by_class(svg, "rect", "crop-frame")][:2] == [region_color(0), region_color(1)]
    names = {p.name for p in (tmp_path / "images").iterdir()}
    assert "pt.crop-1.png" in names and "pt.crop-2.png" in names and not any("caustic" in n for n in names)
    tone = to_uint8(metrics.display_encode(case["images"]["pt"], case["exposure"]))
    assert np.array_equal(_png(tmp_path / "images" / "pt.crop-1.png"), tone[3:23, 2:12])
    assert np.array_equal(_png(tmp_path / "images" / "pt.crop-2.png"), tone[60:64, 60:64])  # clamped
    for bad in ([(70, 0, 5, 5)], [(0, 0, 0, 5)], [(1, 2, 3)]):
        with pytest.raises(ValueError, match="crop"):
            fig.checked_crops(bad, N, N)


def test_precomputed_maps_are_reused(tmp_path, case):
    maps = {name: error_maps(img, case["ref"], case["exposure"]) for name, img in case["images"].items()}
    maps["pt"] = {**maps["pt"], "de": np.zeros((N, N))}
    _write(tmp_path, case, maps=maps)
    assert np.array_equal(_png(tmp_path / "images" / "pt.delta_e2000.png"),
                          apply_colormap(np.zeros((N, N)), *DELTA_E_RANGE, "viridis"))


def test_long_labels_wrap_without_truncation(tmp_path, case):
    long = 'pathtracer[sampler="independent", max_depth=12, rr_depth=5, light_sampling="power"]'
    _, svg = _write(tmp_path, case, series_labels={"pt": long})
    label = next(g for g in _by_class(svg, "g", "row-label") if g.get("data-row") == "pt")
    lines = [t.text for t in label.iter(SVG + "text")]
    assert len(lines) > 1 and re.sub(r"\s", "", "".join(lines)) == re.sub(r"\s", "", long)


def test_write_report_writes_the_image_figure(tmp_path):
    case = rf.make_case(32, 32, names=("alpha-tracer", "beta-photons"), spps=(4, 16), seeds=(0,),
                        not_run=False, with_summary=False)
    rf.write_case(tmp_path / "report.html", case, figures=True, series_labels={"alpha-tracer": "Alpha"})
    assert (tmp_path / "figures" / "images.pdf").read_bytes().startswith(b"%PDF")
    names = {p.name for p in (tmp_path / "images").glob("*.png")}
    assert {"reference.png", "alpha-tracer.png", "beta-photons.delta_e2000.png"} <= names
    svg = (tmp_path / "figures" / "images.svg").read_text(encoding="utf-8")
    assert ">Alpha<" in svg and ">beta-photons<" in svg


def test_row_labels_say_the_spp_seed_and_time_of_each_image(tmp_path):
    """The image shown is the first seed's at its highest spp: its label says so, with that run's time."""
    case = rf.make_case(32, 32, names=("alpha-tracer", "beta-photons"), spps=(4, 16), seeds=(1, 2),
                        not_run=False, with_summary=False)
    case["images"] = {n: case["raw"][n, 1, 16] for n in ("alpha-tracer", "beta-photons")}
    rf.write_case(tmp_path / "report.html", case, figures=True)
    svg = ET.parse(tmp_path / "figures" / "images.svg").getroot()
    rows = {g.get("data-row"): [(t.text, t.get("class")) for t in g.iter(SVG + "text")]
            for g in _by_class(svg, "g", "row-label")}
    # time = cost per spp × spp × (1 + 0.05 × seed) (tests/report_fixtures.py): 0.010 × 16 × 1.05, 0.004 × 16 × 1.05
    assert rows["alpha-tracer"] == [("alpha-tracer", None), ("16 spp, seed 1, 0.168 s wall", "tick")]
    assert rows["beta-photons"] == [("beta-photons", None), ("16 spp, seed 1, 0.0672 s wall", "tick")]
    assert rows["reference"] == [("reference", None), (f"{case['reference'].spp} spp", "tick")]


def test_crop_legend_names_each_crop_in_its_colour(written, case, tmp_path):
    crops = fig.choose_crops(case["scene"], (N, N))
    legend = _by_class(written["svg"], "g", "crop-legend")
    assert len(legend) == 1
    swatches = [r.get("fill") for r in legend[0].iter(SVG + "rect")]
    texts = [t.text for t in legend[0].iter(SVG + "text")][1:]
    assert swatches == [c.color for c in crops]
    assert [t.split(" (")[0] for t in texts] == [c.name for c in crops]
    _, svg = _write(tmp_path, case, crops=[(2, 3, 10, 20)])
    assert [t.text for t in _by_class(svg, "g", "crop-legend")[0].iter(SVG + "text")][1:] == ["crop 2,3 10×20 px"]
