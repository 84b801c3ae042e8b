"""The results' rgb_convention column: which colours a run rendered (cornell_harness.scenes.spectral_scene.convention_used)."""

from __future__ import annotations

from tests.conftest import CORNELL
from cornell_harness.adapters.registry import resolve
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.loader import load_scene
from cornell_harness.scenes.spectral_scene import SPECTRAL_INFO, convention_used
from cornell_harness.workflows.runner import RunRecord


def test_convention_used():
    assert convention_used("", {SPECTRAL_INFO: "llvm_ad_spectral"}) == ""  # an RGB scene: no convention
    assert convention_used("scene_light", {}) == "scene_light"
    assert convention_used("illuminant_E", {SPECTRAL_INFO: ""}) == "illuminant_E"
    assert convention_used("scene_light", {SPECTRAL_INFO: "hero"}) == "spectral"


def test_a_row_says_the_convention_its_run_used():
    (entry,) = resolve(["pathtracer"])
    measured = RunRecord.new(resolve_scene("cornell-box-measured"), entry, 4, 0)
    assert measured.row()["rgb_convention"] == "scene_light"
    measured.info = {SPECTRAL_INFO: "llvm_ad_spectral"}
    assert measured.row()["rgb_convention"] == "spectral"
    assert RunRecord.new(load_scene(CORNELL), entry, 4, 0).row()["rgb_convention"] == ""
