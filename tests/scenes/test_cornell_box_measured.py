"""cornell-box-measured: the stored file is the script's output, oriented as published (red on the left), with the
light's cut-out, spectral materials and the declared convention's projection.

The colour-science cross-check of the measured reflectances (illuminant E against the data's derived values) is
tests/scenes/test_spectra.py's test_measured_reflectances_under_E_equal_the_derived_values.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest

from tests.conftest import ROOT
from cornell_harness.evaluate.regions import region_masks
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.model import Region
from cornell_harness.scenes.spectra import CORNELL_PCG, SCENE_LIGHT, emission_rgb, reflectance_rgb

FOLDER = ROOT / "src" / "cornell_harness" / "references" / "cornell-box-measured"
DATA = json.loads(CORNELL_PCG.read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def scene():
    return resolve_scene("cornell-box-measured")


def _normals(mesh) -> np.ndarray:
    v = mesh.vertices[mesh.triangles]
    return np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])


def test_the_stored_file_is_the_scripts_output():
    out = subprocess.run([sys.executable, str(ROOT / "scripts" / "make_cornell_box_measured.py")], cwd=ROOT,
                         capture_output=True, text=True, check=True).stdout
    assert out.rstrip() == (FOLDER / "scene.toml").read_text(encoding="utf-8").rstrip()


def test_red_is_on_the_left_seen_from_the_camera(scene):
    """Camera rays (the renderers' pixel convention, cornell_harness.evaluate.regions) see the red wall in the left half of
    the image and the green wall in the right half, as the data's note_handedness says."""
    probe = dataclasses.replace(scene, regions={"red": Region("red", ("red-wall",)),
                                                "green": Region("green", ("green-wall",))})
    masks = region_masks(probe)
    width = scene.camera.width
    red_cols, green_cols = np.nonzero(masks["red"])[1], np.nonzero(masks["green"])[1]
    assert len(red_cols) > 1000 and len(green_cols) > 1000
    assert red_cols.max() < width / 2 < green_cols.min()
    red = next(m for m in scene.meshes if m.name == "red-wall")
    assert red.vertices[:, 0].min() > 0.5  # the red wall is the x ~ 0.55 m one


def test_geometry_is_as_published_in_metres(scene):
    """Published mm times length_scale 0.001; fronts face into the box (out of the blocks); the ceiling and the
    light together tile the published ceiling exactly, the light at the published height."""
    meshes = {m.name: m for m in scene.meshes}
    np.testing.assert_allclose(meshes["floor"].vertices, np.array(DATA["quads"]["floor"]["vertices"]) * 1e-3)
    inside = np.array([0.278, 0.274, 0.28])
    for name in ("floor", "back", "green-wall", "red-wall", "ceiling", "light"):
        m = meshes[name]
        centres = m.vertices[m.triangles].mean(axis=1)
        assert np.all(np.einsum("ij,ij->i", _normals(m), inside - centres) > 0), name
    for name in ("short-block", "tall-block"):
        m = meshes[name]
        centres = m.vertices[m.triangles].mean(axis=1)
        assert np.all(np.einsum("ij,ij->i", _normals(m), centres - m.vertices.mean(axis=0)) > 0), name

    def area(m):
        return 0.5 * np.linalg.norm(_normals(m), axis=1).sum()

    assert area(meshes["light"]) == pytest.approx(0.130 * 0.105, rel=1e-9)
    assert area(meshes["ceiling"]) + area(meshes["light"]) == pytest.approx(0.556 * 0.5592, rel=1e-9)
    assert np.all(meshes["light"].vertices[:, 1] == pytest.approx(0.5488))
    assert scene.camera.position == pytest.approx((0.278, 0.273, -0.8))


def test_materials_and_light_are_the_declared_projection_of_the_measured_spectra(scene):
    sp = scene.spectral
    assert sp.rgb_convention == SCENE_LIGHT and scene.max_depth == -1 and scene.pixel_filter == "box"
    light = sp.spectra["light"]
    assert light.values == tuple(DATA["spectra"]["light_emission"]["values"])
    for name in ("white", "green", "red"):
        assert sp.reflectance(name).values == tuple(DATA["spectra"][f"{name}_reflectance"])
        assert scene.materials[name].reflectance == reflectance_rgb(sp.reflectance(name), SCENE_LIGHT, light)
    emitter = next(m for m in scene.meshes if m.is_emitter)
    assert emitter.radiance == emission_rgb(light)
    np.testing.assert_allclose(emitter.radiance, DATA["derived_reference_values_colour_science_cie1931_2deg"]
                               ["light_emission_to_linear_sRGB"], atol=0.02)
    assert set(scene.regions) == {"walls", "blocks", "floor", "light", "bleed-red", "bleed-green"}


def test_the_rgb_convention_can_be_overridden(scene):
    """--set colour.rgb_convention=illuminant_E: a derived scene on the illuminant-E projection, its own hash."""
    from cornell_harness.scenes.overrides import load_derived_scene
    from cornell_harness.scenes.spectra import ILLUMINANT_E

    e = load_derived_scene(scene.path, [f"colour.rgb_convention={ILLUMINANT_E}"])
    assert e.spectral.rgb_convention == ILLUMINANT_E and e.content_hash() != scene.content_hash()
    white = e.spectral.reflectance("white")
    assert e.materials["white"].reflectance == reflectance_rgb(white, ILLUMINANT_E)
    np.testing.assert_allclose(e.materials["white"].reflectance, DATA["derived_reference_values_colour_science_"
                               "cie1931_2deg"]["illuminant_E_to_linear_sRGB_no_adaptation"]["white"], atol=1e-3)


def test_the_stored_reference_is_spectral_and_shows_red_on_the_left(scene):
    """The stored reference: Mitsuba's spectral variant, this scene's hash; its left wall red, its right wall green;
    its light the emission_rgb of the light spectrum plus the little the light's own surface reflects (< 2%)."""
    from cornell_harness.store.references import load_reference

    ref = load_reference(scene)
    assert ref.provenance["variant"].endswith("_spectral") and ref.provenance["scene_hash"] == scene.content_hash()
    assert ref.provenance["rgb_convention"] == "spectral"
    masks = region_masks(dataclasses.replace(scene, regions={"red": Region("red", ("red-wall",)),
                                                             "green": Region("green", ("green-wall",)),
                                                             "light": Region("light", ("light",))}))
    red, green = ref.image[masks["red"]].mean(axis=0), ref.image[masks["green"]].mean(axis=0)
    assert red[0] > 3 * red[1] and green[1] > 1.5 * green[0]
    assert np.nonzero(masks["red"])[1].mean() < scene.camera.width / 2 < np.nonzero(masks["green"])[1].mean()
    light = ref.image[masks["light"]].mean(axis=0)
    expected = np.array(emission_rgb(scene.spectral.spectra["light"]))
    assert np.all(light >= expected * 0.999) and np.all(light <= expected * 1.02), (light, expected)
