"""`cbox compare-image`: an image file scores exactly as `cbox compare` scored that render; bad input is one line."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from tests.conftest import CORNELL, run_cbox
from cornell_harness.adapters.registry import resolve
from cornell_harness.evaluate import flip
from cornell_harness.evaluate.ciede2000 import srgb_eotf_inverse
from cornell_harness.evaluate.registry import IMAGE_METRICS
from cornell_harness.evaluate.thresholds import parse_threshold
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.exr import ImageFileError, read_exr, write_exr
from cornell_harness.store.image_files import ImageFile
from cornell_harness.store.references import load_reference
from cornell_harness.workflows import compare_image as ci
from cornell_harness.workflows import runner

SPP, SEED = 2, 0  # the numbers must match, not be good: the cheapest render
REFERENCE = CORNELL.parent / "reference.exr"


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """A Mitsuba image written by `cbox render` (the issue's case: a reference renderer's EXR), and the record
    `cbox compare --json` prints for that render.

    The record is made here as `cbox compare` makes it (``runner.run_one``,
    then ``runner.json_record``), without a second process and its report.
    """
    tmp = tmp_path_factory.mktemp("compare-image")
    exr = tmp / "pt.exr"
    proc = run_cbox("render", "--scene", "cornell-box", "-r", "mitsuba", "--spp", str(SPP), "--seed", str(SEED),
                    "--out", str(exr))
    assert proc.returncode == 0, proc.stderr
    scene = resolve_scene("cornell-box")
    reference = load_reference(scene)
    (entry,) = resolve(["mitsuba"])
    run = runner.run_one(entry, scene, SPP, SEED, reference)
    return {"tmp": tmp, "exr": exr, "run": run, "record": runner.json_record(run), "reference": reference}


def _one_error_line(proc, *words: str) -> str:
    assert proc.returncode == 2, proc.stderr
    (line,) = proc.stderr.strip().splitlines()
    assert line.startswith("cbox: error: "), line
    for w in words:
        assert w in line, line
    return line


def test_a_render_scores_exactly_as_compare_scored_it(rendered):
    """The issue's done-when: `cbox render` + `compare-image --scene` gives `cbox compare`'s numbers.

    Exactly, not to a tolerance: renders are float32 (the render path casts
    them), the EXR stores float32, and the metrics are the same functions on
    the same arrays.
    """
    np.testing.assert_array_equal(read_exr(rendered["exr"]), rendered["run"].image)  # one render
    out = rendered["tmp"] / "scored"
    proc = run_cbox("compare-image", str(rendered["exr"]), "--scene", "cornell-box", "--json", "--report",
                    "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    (line,) = proc.stdout.strip().splitlines()
    rec, compared = json.loads(line), rendered["record"]
    assert rec["spp"] == SPP and rec["scene"] == "cornell-box" and rec["noise_note"] is None  # spp from the header
    ours = {**rec["metrics"], **rec["noise"]}
    assert set(ours) == {k for k in compared if k in IMAGE_METRICS}
    assert "flip_mean" in ours and "noise_delta_e2000_mean" in ours
    for key, value in ours.items():
        assert value == compared[key], key
    # Per region too, but for mean_z: compare takes the renderer's own variance, a file has none (noise model).
    assert set(rec["regions"]) == set(compared["regions"]) == {"walls", "boxes", "floor", "light", "back-edge"}
    for name, values in rec["regions"].items():
        assert {k: v for k, v in values.items() if k != "mean_z"} == \
            {k: v for k, v in compared["regions"][name].items() if k != "mean_z"}, name
    assert rec["flip_parameters"] == pytest.approx(flip.flip_parameters(rendered["reference"].image))
    # The error map: the viewer's ΔE colours, one pixel per pixel; the report shows the image by its label.
    assert rec["error_map"] == str(out / "pt.delta_e.png")
    assert Image.open(rec["error_map"]).size == rendered["reference"].image.shape[1::-1]
    html = (out / "report.html").read_text()
    assert "<title>cbox compare-image — cornell-box</title>" in html and '"renderers":[{"name":"pt"' in html
    assert f'data-key="flip_mean" data-sort="{rec["metrics"]["flip_mean"]!r}"' in html


def test_a_reference_file_gives_yardsticks_only_with_its_stored_variance(rendered, tmp_path):
    """`--reference` of a stored reference.exr finds variance.exr beside it; a bare copy of it has none."""
    bare = tmp_path / "ref.exr"
    write_exr(bare, rendered["reference"].image)
    stored, copied = ci.load_file_target(REFERENCE), ci.load_file_target(bare)
    assert stored.noise_note is None and copied.noise_note.startswith("no reference variance")
    (image,) = ci.load_images([rendered["exr"]], stored)
    assert image.spp == SPP
    scored = ci.score(image, stored)
    assert scored.noise == {k: rendered["record"][k] for k in scored.noise} and scored.noise and not scored.regions
    assert ci.noise_gap(copied, SPP) == copied.noise_note and ci.noise_gap(stored, None).startswith("no spp")


def test_display_referred_input_is_refused_unless_its_transfer_is_given(tmp_path):
    """An 8-bit sRGB PNG: refused, in one line naming it; with the sRGB transfer, linearised correctly."""
    ref = read_exr(REFERENCE)
    ref = np.minimum(ref / np.percentile(ref, 99), 1.0)  # displayable as it is, mostly far from black
    write_exr(tmp_path / "ref.exr", ref)
    png = tmp_path / "shot.png"
    Image.fromarray(np.round(255 * srgb_eotf_inverse(ref)).astype(np.uint8)).save(png)
    _one_error_line(run_cbox("compare-image", str(png), "--reference", str(tmp_path / "ref.exr"), "--out",
                             str(tmp_path / "out")), str(png), "display-referred", "--input-transfer")
    target = ci.load_file_target(tmp_path / "ref.exr")
    (image,) = ci.load_images([png], target, "srgb")
    m = ci.score(image, target).metrics
    # 8-bit sRGB steps are well below a just-noticeable difference; taken as linear, the image is far too bright.
    assert abs(m["mean_radiance_rel_error"]) < 0.01 and m["delta_e2000_mean"] < 0.5
    (as_linear,) = ci.load_images([png], target, "linear")
    assert as_linear.image.mean() > 1.5 * image.image.mean()


def test_images_of_another_size_are_refused(tmp_path):
    small = tmp_path / "small.exr"
    write_exr(small, np.ones((8, 8, 3), np.float32))
    _one_error_line(run_cbox("compare-image", str(small), "--scene", "cornell-box", "--out", str(tmp_path)),
                    str(small), "8x8", "256x256", str(REFERENCE))


def test_reference_or_scene_one_of_them(tmp_path):
    _one_error_line(run_cbox("compare-image", str(REFERENCE), "--out", str(tmp_path)), "--reference", "--scene")


# -- the workflow's checks, without a process ----------------------------------------------------


def _file(pixel_type: str, metadata=None) -> ImageFile:
    return ImageFile(REFERENCE, np.full((2, 2, 3), 0.5, np.float32), pixel_type, "png", metadata or {})


def test_transfers():
    assert ci.linear_pixels(_file("half"), None)[0, 0, 0] == 0.5  # floating point: linear already
    with pytest.raises(ImageFileError, match="uint16 pixels is display-referred"):
        ci.linear_pixels(_file("uint16"), None)
    assert ci.linear_pixels(_file("uint16"), "linear")[0, 0, 0] == 0.5
    assert ci.linear_pixels(_file("uint8"), "srgb")[0, 0, 0] == pytest.approx(0.21404, abs=1e-5)  # IEC 61966-2-1


def test_spp_from_header_or_option():
    assert ci.image_spp(_file("float", {"cbox:spp": "16"}), None) == 16
    assert ci.image_spp(_file("float"), 8) == 8 and ci.image_spp(_file("float"), None) is None
    with pytest.raises(ImageFileError, match="--spp 8, but its header cbox:spp says 16"):
        ci.image_spp(_file("float", {"cbox:spp": "16"}), 8)
    with pytest.raises(ImageFileError, match="not a positive integer"):
        ci.image_spp(_file("float", {"cbox:spp": "many"}), None)


def test_labels_are_unique():
    assert ci.unique_labels(["a/x.exr", "b/x.exr", "y.png", "c/x.exr"]) == ["x", "x-2", "y", "x-3"]


# -- an image of unknown spp, and one the wrong way up --------------------------------------------



@pytest.fixture
def correct(tmp_path):
    """A correct 128-spp render of cornell-box (the stored noise batch's pixels) in a file without a cbox:spp
    header, as any renderer but ours writes it."""
    path = tmp_path / "correct.exr"
    write_exr(path, read_exr(CORNELL.parent / "noise.exr"))
    return path


def _pfm(path, image, upside_down=False) -> None:
    """PFM as a C program writes it: rows bottom to top (``upside_down``: top to bottom, the common mistake)."""
    h, w, _ = image.shape
    rows = np.ascontiguousarray((image if upside_down else image[::-1]).astype("<f4"))
    path.write_bytes(b"PF\n%d %d\n-1.0\n" % (w, h) + rows.tobytes())


def test_without_spp_no_region_z_and_the_score_says_why(correct):
    """No header, no --spp: no yardsticks and no region mean_z (it used to be computed as if the image were
    noise-free: tens of sigma on a correct render); the note in the result names --spp. With --spp, both."""
    target = ci.load_scene_target(resolve_scene("cornell-box"))
    (unknown,) = ci.load_images([correct], target)
    scored = ci.score(unknown, target)
    assert unknown.spp is None and scored.noise is None and "--spp N" in scored.noise_note
    assert scored.regions and all("mean_z" not in values for values in scored.regions.values())
    assert scored.record(target)["noise_note"] == scored.noise_note
    (known,) = ci.load_images([correct], target, spp=128)
    scored = ci.score(known, target)
    assert scored.noise and scored.noise_note is None
    assert all(abs(values["mean_z"]) < 4 for values in scored.regions.values())  # a correct render: within noise


@pytest.mark.parametrize("metric", ["region.walls.mean_z", "noise_rmse"])
def test_a_threshold_that_needs_the_spp_is_refused_without_it(metric, correct):
    with pytest.raises(ci.OptionError, match=f"{metric}: .*correct.exr has no cbox:spp header") as e:
        ci.compare_images([correct], resolve_scene("cornell-box"),
                          checks=ci.Checks([parse_threshold(f"{metric}=3", "fail")]))
    assert e.value.option == "--spp"
    ci.compare_images([correct], resolve_scene("cornell-box"), spp=128,
                      checks=ci.Checks([parse_threshold(f"{metric}=3", "fail")]))


def test_a_pfm_scores_as_its_exr_and_one_upside_down_is_noted(tmp_path, correct):
    """The PFM a C renderer writes scores exactly as the same pixels in EXR, with no note; written top row first,
    it is scored upside down, and its score says so."""
    pixels = read_exr(correct)
    write_exr(tmp_path / "right.exr", pixels)
    _pfm(tmp_path / "right.pfm", pixels)
    _pfm(tmp_path / "wrong.pfm", pixels, upside_down=True)
    run = ci.compare_images([tmp_path / n for n in ("right.exr", "right.pfm", "wrong.pfm")],
                            resolve_scene("cornell-box"), spp=128)
    exr, pfm, wrong = (c.score for c in run.images)
    assert pfm.metrics == exr.metrics and pfm.regions == exr.regions and pfm.noise == exr.noise
    assert exr.orientation_note is None and pfm.orientation_note is None
    assert wrong.orientation_note.startswith("image looks flipped vertically: ")
    assert wrong.record(run.target)["orientation_note"] == wrong.orientation_note
