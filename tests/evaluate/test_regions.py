"""Named image regions: masks from the geometry, metrics inside each region, and their way to the outputs."""

from __future__ import annotations

import base64
import dataclasses
import io
import json
import math
import re
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tests.conftest import CORNELL, ROOT
from cornell_harness.evaluate import metrics
from cornell_harness.evaluate import regions as R
from cornell_harness.scenes.loader import load_scene
from cornell_harness.scenes.model import Camera, Diffuse, Mesh, Region, Scene
from cornell_harness.store.exr import read_exr, write_exr
from cornell_harness.store.references import Reference

CAUSTICS = ROOT / "src" / "cornell_harness" / "references" / "cornell-box-caustics"


def _with_regions(scene: Scene, **regions: Region) -> Scene:
    return dataclasses.replace(scene, regions={n: dataclasses.replace(r, name=n) for n, r in regions.items()})


def _corner_dirs(camera: Camera) -> np.ndarray:
    """(H+1, W+1, 3) directions through the pixel corners, from the Camera's own frame and field of view."""
    right, up, forward = camera.frame()
    tx, ty = camera.tan_half_fov()
    sx = 2.0 * np.arange(camera.width + 1) / camera.width - 1.0
    sy = 1.0 - 2.0 * np.arange(camera.height + 1) / camera.height
    return forward + sx[None, :, None] * tx * right + sy[:, None, None] * ty * up


def _all_corners(inside: np.ndarray) -> np.ndarray:
    return inside[:-1, :-1] & inside[1:, :-1] & inside[:-1, 1:] & inside[1:, 1:]


# --------------------------------------------------------------------------
# Masks
# --------------------------------------------------------------------------


@pytest.mark.parametrize("width,height", [(192, 128), (100, 160)])
def test_light_mask_matches_its_projection(width, height):
    """The light's pixels are exactly those whose four corners project inside its quad (project_to_pixels).

    A non-square image checks rows against columns and the field-of-view axis; the light is convex
    and nothing hides it, so "all 16 rays hit it" is "all 4 corners inside".
    """
    sc = _with_regions(load_scene(CORNELL).with_resolution(width, height), light=Region("", ("light",)))
    mask = R.region_masks(sc)["light"]
    (light,) = [m for m in sc.meshes if m.name == "light"]
    quad = sc.camera.project_to_pixels(light.vertices)  # (col, row), counter-clockwise or not
    ys, xs = np.mgrid[0:height + 1, 0:width + 1].astype(float)
    sign = np.sign(np.cross(np.r_[quad[1] - quad[0], 0], np.r_[quad[2] - quad[1], 0])[2])
    inside = np.ones(xs.shape, dtype=bool)
    for a, b in zip(quad, np.roll(quad, -1, axis=0)):
        inside &= sign * ((b[0] - a[0]) * (ys - a[1]) - (b[1] - a[1]) * (xs - a[0])) > 0
    expected = _all_corners(inside)
    assert expected.sum() > 40
    np.testing.assert_array_equal(mask, expected)
    rows, cols = np.nonzero(mask)  # the light is at the top, centred left-right
    assert rows.max() < height / 2 and abs((cols.min() + cols.max() + 1) / 2 - width / 2) <= 1


def _two_planes(edge_px: float, width: int = 12, height: int = 6) -> Scene:
    """Two quads side by side filling the view of a camera at z = 3, meeting at film x = ``edge_px``."""
    cam = Camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 50.0, "x", width, height)
    tx, _ = cam.tan_half_fov()
    e = (2.0 * edge_px / width - 1.0) * tx * 3.0  # world x at z = 0 that lands on film x = edge_px

    def quad(name, x0, x1):
        v = np.array([[x0, -9, 0], [x1, -9, 0], [x1, 9, 0], [x0, 9, 0]], dtype=np.float64)
        return Mesh(name, v, np.array([[0, 1, 2], [0, 2, 3]]), "white")

    return Scene("two-planes", Path("two-planes.toml"), frozenset({"triangle_mesh", "diffuse", "pinhole_camera"}),
                 cam, {"white": Diffuse("white", (0.5, 0.5, 0.5))}, (quad("left", -9, e), quad("right", e, 9)), -1,
                 "box", regions={"left": Region("left", ("left",)), "right": Region("right", ("right",))})


@pytest.mark.parametrize("fraction", [0.2, 0.5, 0.8])
def test_pixels_straddling_a_boundary_are_left_out(fraction):
    """An edge through column 5 (anywhere inside it) drops that column from both sides, and only it."""
    masks = R.region_masks(_two_planes(5 + fraction))
    cols = np.arange(12)
    np.testing.assert_array_equal(masks["left"], np.broadcast_to(cols < 5, (6, 12)))
    np.testing.assert_array_equal(masks["right"], np.broadcast_to(cols > 5, (6, 12)))


def test_every_pixel_in_at_most_one_object_region():
    sc = load_scene(CORNELL).with_resolution(64, 64)
    sc = _with_regions(sc, **{n: Region("", (n,)) for n in sc.object_names()})
    masks = R.region_masks(sc)
    count = sum(m.astype(int) for m in masks.values())
    assert count.max() == 1
    left_out = count == 0
    assert 0.05 < left_out.mean() < 0.3  # the boundaries between walls, boxes, floor and light
    # A left-out pixel borders another object: its neighbours are not all in one region.
    label = sum(i * m for i, m in enumerate(masks.values(), start=1))
    r, c = np.nonzero(left_out[1:-1, 1:-1])
    around = np.stack([label[r, c + 1], label[r + 2, c + 1], label[r + 1, c], label[r + 1, c + 2]])
    assert np.all((around == 0).any(axis=0) | (around != around[0]).any(axis=0))


def test_box_and_objects_combined():
    """objects AND box: the floor split at x = 0; a box alone selects whatever it holds (the back wall)."""
    sc = load_scene(CORNELL).with_resolution(64, 64)
    floor_box = ((-1.1, -1.01, -1.1), (1.1, -0.99, 1.1))
    sc = _with_regions(
        sc,
        floor=Region("", ("floor",)),
        back=Region("", ("back",)),
        left=Region("", ("floor",), ((-1.1, -1.01, -1.1), (0.0, -0.99, 1.1))),
        right=Region("", ("floor",), ((0.0, -1.01, -1.1), (1.1, -0.99, 1.1))),
        floor_slab=Region("", ("floor", "light"), floor_box),
        back_slab=Region("", (), ((-1.1, -1.1, -1.001), (1.1, 1.1, -0.999))),  # no objects: any
        wrong_object=Region("", ("light",), floor_box),
    )
    m = R.region_masks(sc)
    assert m["left"].sum() > 50 and m["right"].sum() > 50
    assert not (m["left"] & m["right"]).any()
    assert not ((m["left"] | m["right"]) & ~m["floor"]).any()
    cols = np.nonzero(m["left"])[1], np.nonzero(m["right"])[1]
    assert cols[0].max() == 31 and cols[1].min() == 32  # x = 0 is the image's middle column boundary
    # x = 0 falls on pixel edges, whose rays both boxes hold (faces count as inside): no floor pixel is lost
    np.testing.assert_array_equal(m["left"] | m["right"], m["floor"])
    np.testing.assert_array_equal(m["floor_slab"], m["floor"])  # the box drops the light, not the floor
    np.testing.assert_array_equal(m["back_slab"], m["back"])
    assert not m["wrong_object"].any()


def test_sphere_masks():
    """The glass sphere's pixels are those whose four corner rays pass within its radius (nothing hides it)."""
    sc = load_scene(CAUSTICS).with_resolution(64, 48)
    (glass,) = [s for s in sc.spheres if s.name == "glass-sphere"]
    sc = _with_regions(sc, glass=Region("", ("glass-sphere",)), mirror=Region("", ("mirror-sphere",)))
    m = R.region_masks(sc)
    d = _corner_dirs(sc.camera)
    to_center = np.subtract(glass.center, sc.camera.position)
    dist = np.linalg.norm(np.cross(d, to_center), axis=-1) / np.linalg.norm(d, axis=-1)
    np.testing.assert_array_equal(m["glass"], _all_corners(dist < glass.radius))
    assert m["mirror"].sum() > 50 and not (m["mirror"] & m["glass"]).any()
    # the mirror sphere is left of the glass sphere in the image
    assert np.nonzero(m["mirror"])[1].mean() < np.nonzero(m["glass"])[1].mean()


def test_masks_are_cached_read_only_and_fast():
    sc = load_scene(CORNELL)
    assert set(sc.regions) == {"walls", "boxes", "floor", "light", "back-edge"}
    R._cached_masks.cache_clear()
    # CPU time of this process, not wall time: other processes on the machine (CI shares it) cannot push it
    # past the bound, while a per-pixel Python loop (minutes) still would.
    t0 = time.process_time()
    first = R.region_masks(sc)
    cpu = time.process_time() - t0
    assert cpu < 5.0, f"256×256 masks took {cpu:.1f} s of CPU"  # ~0.4 s
    again = R.region_masks(load_scene(CORNELL))  # another Scene object of the same content: a cache hit
    assert all(again[k] is first[k] for k in first) and R._cached_masks.cache_info().hits >= 1
    assert first["walls"].shape == (256, 256) and not first["walls"].flags.writeable
    assert R.region_masks(sc.with_resolution(32, 16))["walls"].shape == (16, 32)
    other = _with_regions(sc, walls=Region("", ("back",)))
    assert R.region_masks(other)["walls"].sum() < first["walls"].sum()  # regions are part of the key
    assert R.region_masks(dataclasses.replace(sc, regions={})) == {}


def test_banded_tracing_gives_the_same_masks(monkeypatch):
    """Masks traced a few pixel rows at a time (bounded memory) equal masks traced in one go."""
    sc = load_scene(CAUSTICS).with_resolution(40, 30)
    whole = R.region_masks(sc)
    R._cached_masks.cache_clear()
    monkeypatch.setattr(R, "BAND_RAYS", 1000)  # 2-3 pixel rows per band
    banded = R.region_masks(sc)
    for name in whole:
        np.testing.assert_array_equal(banded[name], whole[name])


def test_regions_do_not_change_the_content_hash():
    """The stored scenes gained regions; their hashes, and so their references, are unchanged."""
    sc = load_scene(CORNELL)
    prov = json.loads((CORNELL.parent / "provenance.json").read_text())
    assert sc.regions and prov["scene_hash"] == sc.content_hash()
    assert dataclasses.replace(sc, regions={}).content_hash() == sc.content_hash()
    caustics = load_scene(CAUSTICS)
    assert set(caustics.regions) == {"caustic", "glass-shadow", "mirror", "glass", "walls"}
    assert dataclasses.replace(caustics, regions={}).content_hash() == caustics.content_hash()
    assert json.loads((CAUSTICS / "provenance.json").read_text())["scene_hash"] == caustics.content_hash()


def _caustics_image() -> tuple[np.ndarray, str]:
    """The caustics scene's stored reference."""
    return np.asarray(read_exr(CAUSTICS / "reference.exr"), np.float64), "reference"


def test_caustic_is_bright_and_glass_shadow_dark():
    img, what = _caustics_image()
    sc = load_scene(CAUSTICS).with_resolution(img.shape[1], img.shape[0])
    sc = _with_regions(sc, **sc.regions, floor=Region("", ("floor",)))
    m = R.region_masks(sc)
    y = metrics.luminance(img)
    caustic, shadow, floor = (float(y[m[k]].mean()) for k in ("caustic", "glass-shadow", "floor"))
    outside = float(y[m["floor"] & ~m["glass-shadow"]].mean())
    assert m["caustic"].sum() >= 20 and m["glass-shadow"].sum() >= 40
    assert not (m["caustic"] & m["glass-shadow"]).any()
    assert caustic > 4 * floor, (what, caustic, floor)  # ~8× in the previews
    assert shadow < 0.5 * outside, (what, shadow, outside)  # ~0.3× in the previews


# --------------------------------------------------------------------------
# Metrics
# --------------------------------------------------------------------------


def _reference(shape=(8, 10), value=0.5, var=1e-4, spp=1024) -> Reference:
    img = np.full((*shape, 3), value)
    img[..., 0] *= 2.0  # not grey, so per-channel means matter
    return Reference(img, np.full_like(img, var), img.copy(), {"spp": spp, "noise_spp": 64}, Path("."))


def test_region_metrics_see_only_their_region():
    ref = _reference()
    a = np.zeros((8, 10), bool)
    a[2:5, 1:4] = True
    b = np.zeros_like(a)
    b[6:, 5:] = True
    image = ref.image.copy()
    image[a] *= 1.1  # +10 % inside a
    image[0, 9] = 50.0  # a firefly outside both
    out = R.region_metrics(image, ref, {"a": a, "b": b, "none": np.zeros_like(a)})
    assert out["a"]["pixels"] == 9 and out["b"]["pixels"] == 10
    assert out["a"]["mean_radiance_rel_error"] == pytest.approx(0.1)
    assert out["a"]["rmse"] == pytest.approx(0.1 * np.sqrt(np.mean(ref.image[a] ** 2)))
    assert out["a"]["rel_mse"] == pytest.approx(np.mean((0.1 * ref.image[a]) ** 2 / (ref.image[a] ** 2 + 1e-2)))
    assert out["a"]["delta_e2000_mean"] > 0.5
    for k in ("mean_radiance_rel_error", "rmse", "rel_mse", "delta_e2000_mean", "mean_z"):
        assert out["b"][k] == 0.0, k
    assert out["none"]["pixels"] == 0 and math.isnan(out["none"]["rmse"])
    # over the whole image, the region metrics are the image-wide ones
    whole = R.region_metrics(image, ref, {"all": np.ones_like(a)})["all"]
    wide = metrics.image_metrics(image, ref.image)
    for k in ("mean_radiance_rel_error", "rmse", "rel_mse", "delta_e2000_mean"):
        assert whole[k] == pytest.approx(wide[k]), k


def test_region_mean_z_uses_the_noise_it_is_given():
    """z = Δmean / sd(mean of the difference): the reference's variance plus the image's (given or modelled)."""
    ref = _reference(var=1e-4, spp=1024)
    mask = np.zeros((8, 10), bool)
    mask[:4] = True
    n, delta = 40, 0.01
    image = ref.image + delta
    mean_ref_diff = delta  # every channel moves by delta
    sd = lambda v: np.sqrt(v / n)  # noqa: E731  (per-pixel variance v on all channels, correlated bound)
    z = R.region_metrics(image, ref, {"r": mask})["r"]["mean_z"]  # neither: the image is noise-free
    assert z == pytest.approx(mean_ref_diff / sd(1e-4))
    z = R.region_metrics(image, ref, {"r": mask}, variance=np.full_like(image, 3e-4))["r"]["mean_z"]
    assert z == pytest.approx(mean_ref_diff / sd(4e-4))
    z = R.region_metrics(image, ref, {"r": mask}, spp=256)["r"]["mean_z"]  # model: 1e-4 · 1024/256
    assert z == pytest.approx(mean_ref_diff / sd(5e-4))
    # the image-wide z is the same function over all pixels
    from cornell_harness.evaluate import noise

    whole = R.region_metrics(image, ref, {"all": np.ones_like(mask)}, spp=256)["all"]["mean_z"]
    assert whole == pytest.approx(noise.mean_radiance_z(image, ref.image, ref.variance, 1024, 256))


def test_region_metrics_refuse_a_wrong_mask():
    ref = _reference()
    with pytest.raises(ValueError, match="mask shape"):
        R.region_metrics(ref.image, ref, {"x": np.ones((3, 3), bool)})


# --------------------------------------------------------------------------
# Runner, CLI, report
# --------------------------------------------------------------------------


def _small_scene_dir(tmp_path: Path, size: int = 64) -> Path:
    """The Cornell box (with its regions) at size², with the stored reference box-filtered to it."""
    folder = tmp_path / "box"
    folder.mkdir()
    text = CORNELL.read_text()
    assert "resolution = [256, 256]" in text
    (folder / "scene.toml").write_text(text.replace("resolution = [256, 256]", f"resolution = [{size}, {size}]"))
    f = 256 // size

    def down(name, scale=1.0):
        img = np.asarray(read_exr(CORNELL.parent / name), np.float64)
        return (img.reshape(size, f, size, f, 3).mean(axis=(1, 3)) * scale).astype(np.float32)

    write_exr(folder / "reference.exr", down("reference.exr"))
    write_exr(folder / "variance.exr", down("variance.exr", 1.0 / f**2))  # variance of a mean of f² pixels
    write_exr(folder / "noise.exr", down("noise.exr"))
    prov = json.loads((CORNELL.parent / "provenance.json").read_text())
    prov["scene_hash"] = load_scene(folder).content_hash()
    (folder / "provenance.json").write_text(json.dumps(prov))
    return folder


def test_runner_records_regions_and_flattens_them(tmp_path):
    from cornell_harness.adapters.registry import resolve
    from cornell_harness.store.references import load_reference
    from cornell_harness.workflows import runner

    sc = load_scene(_small_scene_dir(tmp_path))
    ref = load_reference(sc)
    (entry,) = resolve(["tests.user_renderers:FlatGrey"])
    rec = runner.run_one(entry, sc, 1, 0, ref)
    assert rec.status == "ok" and list(rec.regions) == ["walls", "boxes", "floor", "light", "back-edge"]
    masks = R.region_masks(sc)
    assert rec.regions == R.region_metrics(rec.image, ref, masks, spp=1)
    assert rec.regions["light"]["mean_radiance_rel_error"] < -0.9  # grey 0.25 against the light's ~14
    row = rec.row()
    for name, ms in rec.regions.items():
        assert set(ms) == set(R.REGION_METRICS)
        for k, v in ms.items():
            assert row[f"region.{name}.{k}"] == v
    assert "rmse" in row and "regions" not in row
    assert R.nested_regions(row) == rec.regions
    # checkpoints are scored per region too, and an unscored run has none
    recs = runner.run_checkpoints(entry, sc, [1, 2], 0, ref)
    assert [bool(r.regions) for r in recs] == [True, True]
    assert runner.run_one(entry, sc, 1, 0, None).regions == {}


def test_json_record_nests_regions_as_strict_json():
    from cornell_harness.workflows.runner import RunRecord, json_record

    rec = RunRecord("s", "r", "ok", 1, 0, metrics={"psnr": math.inf},
                    regions={"a.b": {"pixels": 3, "rel_mse": math.nan, "rmse": 0.5}})
    out = json_record(rec)
    assert out["regions"] == {"a.b": {"pixels": 3, "rel_mse": None, "rmse": 0.5}} and out["psnr"] is None
    assert not any(k.startswith("region.") for k in out)
    json.dumps(out, allow_nan=False)


def test_compare_json_report_and_tables_carry_regions(tmp_path, capsys):
    """cbox compare --json: nested regions per record; results.parquet/CSV get the columns; the report its table.

    In this process (``_run_compare`` is the command's body) to stay fast; test_cli runs the real CLI.
    """
    import pandas as pd
    from cornell_harness.cli.run import _run_compare

    folder, out = _small_scene_dir(tmp_path), tmp_path / "out"
    assert _run_compare(str(folder), ["tests.user_renderers:FlatGrey"], 2, 0, out, True)[0] == 0
    (line,) = capsys.readouterr().out.strip().splitlines()
    rec = json.loads(line)
    assert list(rec["regions"]) == ["walls", "boxes", "floor", "light", "back-edge"]
    assert set(rec["regions"]["floor"]) == set(R.REGION_METRICS) and rec["regions"]["floor"]["pixels"] > 20
    for table in (pd.read_parquet(out / "results.parquet"), pd.read_csv(out / "metrics.csv")):
        assert table["region.floor.rmse"].iloc[0] == pytest.approx(rec["regions"]["floor"]["rmse"])
    from cornell_harness.store.experiments import load_results

    _, runs = load_results(out)
    assert "region.light.mean_z" in runs.columns

    html = (out / "report.html").read_text()
    i = html.index('<section id="regions">')
    section = html[i:html.index("</section>", i)]
    table = section[section.index('id="region-table"'):]
    rows = re.findall(r'<tr class="record ok">(.*?)</tr>', table)
    assert len(rows) == 5 and all("flat-grey" in r for r in rows)
    for name, r in zip(("walls", "boxes", "floor", "light", "back-edge"), rows):
        assert f'data-sort="{name}"' in r
        pixels = re.search(r'data-key="pixels"[^>]*>(\d+)<', r).group(1)
        assert int(pixels) == rec["regions"][name]["pixels"]
    assert 'class="num fail"' in rows[3]  # the light's |z| is huge
    png = re.search(r'src="data:image/png;base64,([^"]+)"', section).group(1)
    overlay = np.asarray(Image.open(io.BytesIO(base64.b64decode(png))))
    assert overlay.shape == (64, 64, 3)
    for name in ("walls", "boxes", "floor", "light"):
        assert f"<strong>{name}</strong>" in section


def test_report_without_region_runs_still_shows_masks(tmp_path):
    """A scene with regions but runs without region columns: masks and legend, and a note instead of a table."""
    from tests import report_fixtures as rf
    from cornell_harness.reports.html import write_report

    case = rf.make_case(names=("alpha-tracer",), spps=(4,), seeds=(0,), not_run=False, with_summary=False)
    path = write_report(tmp_path / "r.html", scene=case["scene"], reference=case["reference"], runs=case["runs"],
                        images=case["images"], provenance={})
    html = path.read_text()
    assert '<section id="regions">' in html and "No region metrics in these runs." in html
    assert 'id="region-table"' not in html and '<a href="#regions">Regions</a>' in html


def test_region_noise_reports_each_regions_relative_error():
    """A region of value 2 and per-pixel variance 0.04 (std 0.2, 10%): pixel rel. SE 0.1, mean's 0.1/√(3n)."""
    img = np.full((4, 5, 3), 2.0)
    var = np.full_like(img, 0.04)
    a = np.zeros((4, 5), bool)
    a[:2, :] = True  # 10 pixels, 30 values
    out = R.region_noise(img, var, {"a": a, "empty": np.zeros_like(a)})
    assert out["a"]["pixels"] == 10 and out["a"]["mean"] == 2.0
    assert out["a"]["pixel_rel_se_median"] == pytest.approx(0.1)
    assert out["a"]["mean_rel_se"] == pytest.approx(0.1 / np.sqrt(30), rel=1e-3)
    assert out["empty"] == {"pixels": 0}
