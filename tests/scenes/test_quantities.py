"""A scene's quantity and the AO definition it pins (src/cornell_harness/scenes/quantities.py), and the runner's refusal."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.conftest import MINIMAL_SCENE
from cornell_harness.adapters.registry import missing_features
from cornell_harness.evaluate import metrics, regions
from cornell_harness.evaluate.registry import COLOUR_METRICS
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.loader import load_scene
from cornell_harness.scenes.model import SceneError
from cornell_harness.store.references import Reference
from cornell_harness.evaluate.score import score_image

AO_TABLE = """
[ambient_occlusion]
max_distance = 0.5
weighting = "cosine"
normal = "geometric"
miss_value = 0.0
"""
AO_SCENE = MINIMAL_SCENE.replace('format = 1\n', 'format = 1\nquantity = "ambient_occlusion"\n', 1) + AO_TABLE


def _ao(old: str, new: str) -> str:
    assert old in AO_SCENE, old
    return AO_SCENE.replace(old, new, 1)


def test_a_scene_without_quantity_is_radiance(write_scene):
    scene = load_scene(write_scene())
    assert scene.quantity == "radiance" and scene.ambient_occlusion is None


def test_ao_scene_parses_and_its_definition_changes_the_hash(write_scene):
    scene = load_scene(write_scene(AO_SCENE))
    assert scene.quantity == "ambient_occlusion"
    ao = scene.ambient_occlusion
    assert (ao.max_distance, ao.weighting, ao.normal, ao.miss_value) == (0.5, "cosine", "geometric", 0.0)
    radiance = load_scene(write_scene(MINIMAL_SCENE, "radiance.toml")).content_hash()
    assert scene.content_hash() != radiance
    for old, new in [("max_distance = 0.5", "max_distance = 0.25"), ('"cosine"', '"uniform"'),
                     ("miss_value = 0.0", "miss_value = 1.0")]:
        assert load_scene(write_scene(_ao(old, new), "other.toml")).content_hash() != scene.content_hash(), new


def test_relative_and_unbounded_max_distance(write_scene):
    rel = load_scene(write_scene(_ao("max_distance = 0.5", "max_distance_relative = 0.25")))
    # The minimal scene's bounds: the floor quad (2 x 2 at z = 0) and the light above it.
    assert rel.ambient_occlusion.max_distance == pytest.approx(0.25 * rel.extent())
    inf = load_scene(write_scene(_ao("max_distance = 0.5", "max_distance = inf"), "inf.toml"))
    assert math.isinf(inf.ambient_occlusion.max_distance)
    assert inf.content_hash() != rel.content_hash()


BAD_AO = {
    "missing table": (AO_SCENE.replace(AO_TABLE, ""), "ambient_occlusion", "missing required table"),
    "table on a radiance scene": (MINIMAL_SCENE + AO_TABLE, "ambient_occlusion", "only a scene of quantity"),
    "unknown quantity": (_ao('quantity = "ambient_occlusion"', 'quantity = "irradiance"'), "quantity",
                         "unknown quantity 'irradiance'"),
    "both distances": (_ao("max_distance = 0.5", "max_distance = 0.5\nmax_distance_relative = 0.1"),
                       "ambient_occlusion", "exactly one"),
    "no distance": (_ao("max_distance = 0.5\n", ""), "ambient_occlusion", "neither"),
    "zero distance": (_ao("max_distance = 0.5", "max_distance = 0"), "ambient_occlusion.max_distance", "> 0"),
    "nan distance": (_ao("max_distance = 0.5", "max_distance = nan"), "ambient_occlusion.max_distance", "finite"),
    "unknown weighting": (_ao('"cosine"', '"cosine_squared"'), "ambient_occlusion.weighting", "unknown weighting"),
    "unknown normal": (_ao('"geometric"', '"smooth"'), "ambient_occlusion.normal", "unknown normal"),
    "miss value above 1": (_ao("miss_value = 0.0", "miss_value = 2"), "ambient_occlusion.miss_value", "[0, 1]"),
    "misspelt key": (_ao("miss_value", "miss_valeu"), "ambient_occlusion.miss_valeu", "did you mean 'miss_value'"),
}


@pytest.mark.parametrize("case", sorted(BAD_AO))
def test_bad_ao_input_names_file_and_field(case, write_scene):
    text, field, words = BAD_AO[case]
    path = write_scene(text)
    with pytest.raises(SceneError) as exc:
        load_scene(path)
    assert (exc.value.file, exc.value.field) == (str(path), field)
    assert words in exc.value.message, exc.value.message


class _Radiance:
    features = frozenset({"triangle_mesh", "diffuse", "area_light", "pinhole_camera", "box_filter"})


class _AO(_Radiance):
    quantities = ("ambient_occlusion",)


def test_a_renderer_never_runs_on_a_quantity_it_does_not_compute(write_scene):
    ao_scene, radiance_scene = load_scene(write_scene(AO_SCENE)), load_scene(write_scene(MINIMAL_SCENE, "r.toml"))
    assert missing_features(_Radiance(), ao_scene) == ["the quantity ambient_occlusion"]
    assert missing_features(_Radiance(), radiance_scene) == []
    assert missing_features(_AO(), radiance_scene) == ["the quantity radiance"]
    assert missing_features(_AO(), ao_scene) == []


def test_stored_ao_scene():
    scene = resolve_scene("cornell-box-ao")
    cornell = resolve_scene("cornell-box")
    assert scene.quantity == "ambient_occlusion" and scene.ambient_occlusion.max_distance == 0.5
    assert scene.camera == cornell.camera
    assert [m.name for m in scene.meshes] == [m.name for m in cornell.meshes]
    assert not scene.emitters


# -- scoring an AO image: no colour differences, shown at exposure 1 ---------------------------

def _ao_reference(quantity: str) -> Reference:
    rng = np.random.default_rng(3)
    img = np.repeat(rng.uniform(0.2, 1.0, (16, 16, 1)), 3, axis=2).astype(np.float32)
    return Reference(img, np.full_like(img, 1e-4), img.copy(), {"spp": 4096, "noise_spp": 64}, None, quantity)


def test_an_ao_image_is_scored_without_colour_differences():
    ao, radiance = _ao_reference("ambient_occlusion"), _ao_reference("radiance")
    img = ao.image * 0.9
    assert COLOUR_METRICS == {"delta_e2000_mean", "delta_e2000_p95", "delta_e2000_max", "delta_e2000_frac_gt_2_3",
                              "flip_mean", "noise_delta_e2000_mean"}
    ao_row, radiance_row = score_image(img, ao, 64).values, score_image(img, radiance, 64).values
    assert not COLOUR_METRICS & set(ao_row) and COLOUR_METRICS <= set(radiance_row)
    assert ao_row["rmse"] == radiance_row["rmse"] and 0 < ao_row["ssim"] < 1
    # AO is shown as it is: a key-value exposure would rescale a darker AO image to mid-grey.
    assert metrics.display_exposure(ao.image, "ambient_occlusion") == 1.0
    assert metrics.display_exposure(ao.image) == metrics.exposure_scale(ao.image) != 1.0
    mask = {"all": np.ones((16, 16), bool), "none": np.zeros((16, 16), bool)}
    ao_regions, radiance_regions = regions.region_metrics(img, ao, mask), regions.region_metrics(img, radiance, mask)
    for name in mask:
        assert "delta_e2000_mean" not in ao_regions[name] and "delta_e2000_mean" in radiance_regions[name]
    assert ao_regions["all"]["rmse"] == radiance_regions["all"]["rmse"]
