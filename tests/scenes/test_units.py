"""A scene file's length_scale (cornell_harness.scenes.units): file lengths to scene units, and its errors."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import MINIMAL_SCENE, ROOT
from cornell_harness.scenes.loader import load_scene
from cornell_harness.scenes.model import SceneError


def _in_mm(text: str) -> str:
    """MINIMAL_SCENE with every length in thousandths, declared by length_scale = 0.001."""
    for old, new in (("[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]",
                      "[-1000, -1000, 0], [1000, -1000, 0], [1000, 1000, 0], [-1000, 1000, 0]"),
                     ("[-0.1, -0.1, 1], [-0.1, 0.1, 1], [0.1, 0.1, 1], [0.1, -0.1, 1]",
                      "[-100, -100, 1000], [-100, 100, 1000], [100, 100, 1000], [100, -100, 1000]"),
                     ("position = [0, 0, 3]", "position = [0, 0, 3000]")):
        assert old in text, old
        text = text.replace(old, new)
    return "length_scale = 0.001\n" + text


def test_length_scale_gives_scene_units(write_scene):
    """A file in mm with length_scale = 0.001 is the same scene as the file in units: same geometry, same hash."""
    units = load_scene(write_scene(MINIMAL_SCENE, "units.toml"))
    mm = load_scene(write_scene(_in_mm(MINIMAL_SCENE), "mm.toml"))
    np.testing.assert_allclose(mm.meshes[0].vertices, units.meshes[0].vertices, rtol=1e-15)
    assert mm.camera.position == units.camera.position and mm.name == units.name
    assert mm.content_hash() == units.content_hash()
    ao = ROOT / "src" / "cornell_harness" / "references" / "cornell-box-ao" / "scene.toml"
    text = ao.read_text()
    assert "max_distance" in text
    scaled = load_scene(write_scene("length_scale = 0.5\n" + text, "ao.toml"))
    plain = load_scene(ao)
    assert scaled.ambient_occlusion.max_distance == pytest.approx(0.5 * plain.ambient_occlusion.max_distance)
    np.testing.assert_allclose(scaled.meshes[0].vertices, 0.5 * plain.meshes[0].vertices)


@pytest.mark.parametrize("value, message", [("0", "must be in [1e-09, 1e+09]"), ('"mm"', "expected a number"),
                                            ("1e9", "beyond the 1e+30 limit")])
def test_length_scale_errors_name_the_field(write_scene, value, message):
    text = MINIMAL_SCENE.replace("position = [0, 0, 3]", "position = [0, 0, 1e25]")
    with pytest.raises(SceneError) as e:
        load_scene(write_scene(f"length_scale = {value}\n" + text))
    assert e.value.field == "length_scale" and message in e.value.message, str(e.value)
