"""Scene parsing and validation: the good file, and each kind of bad input."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import CORNELL, MINIMAL_SCENE, run_cbox
from cornell_harness.scenes.model import IMAGE_BUFFERS, MAX_IMAGE_BYTES, SceneError, image_memory_bytes, triangle_arrays
from cornell_harness.scenes.loader import load_scene


def test_minimal_scene_parses(write_scene):
    s = load_scene(write_scene())
    assert s.name == "minimal"
    assert (s.camera.width, s.camera.height) == (8, 6)
    assert [m.name for m in s.meshes] == ["floor", "light"]
    assert s.meshes[0].triangles.tolist() == [[0, 1, 2], [0, 2, 3]]  # quad split (a,b,c),(a,c,d)
    assert s.meshes[1].radiance == (10.0, 10.0, 10.0)
    assert s.emitters == (s.meshes[1],)
    assert s.max_depth == -1 and s.pixel_filter == "box"


def test_cornell_box_scene():
    s = load_scene(CORNELL)
    assert s.features == {"triangle_mesh", "diffuse", "area_light", "pinhole_camera", "box_filter"}
    assert len(s.emitters) == 1 and s.emitters[0].name == "light"
    tri = triangle_arrays(s)
    assert tri["triangles"].shape == (5 * 2 + 2 * 12 + 2, 3)  # walls, boxes, light
    # Every wall faces into the box: its normal points toward the centre.
    for m in s.meshes:
        a, b, c = (m.vertices[m.triangles[:, k]] for k in range(3))
        n = np.cross(b - a, c - a)
        centroid = (a + b + c) / 3
        inward = np.einsum("ij,ij->i", n, -centroid)
        if m.name in ("floor", "ceiling", "back", "green-wall", "red-wall", "light"):
            assert np.all(inward > 0), m.name
        else:  # boxes: normals point away from the box's own centre
            outward = np.einsum("ij,ij->i", n, centroid - m.vertices.mean(0))
            assert np.all(outward > 0), m.name


def test_content_hash_ignores_formatting_but_not_content(write_scene):
    h = load_scene(write_scene()).content_hash()
    assert load_scene(write_scene("# comment\n" + MINIMAL_SCENE.replace(" = ", "="), "b.toml")).content_hash() == h
    assert load_scene(write_scene(MINIMAL_SCENE.replace("0.8, 0.8, 0.8", "0.8, 0.8, 0.7"), "c.toml")).content_hash() != h


def test_obj_mesh(write_scene, tmp_path):
    (tmp_path / "quad.obj").write_text("v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nf 1 2 3 4\n")
    text = MINIMAL_SCENE.replace(
        'vertices = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]\nfaces = [[0, 1, 2, 3]]', 'obj = "quad.obj"')
    obj = load_scene(write_scene(text))
    inline = load_scene(write_scene(MINIMAL_SCENE, "inline.toml"))
    assert obj.content_hash() == inline.content_hash()


def _replace(old: str, new: str) -> str:
    assert old in MINIMAL_SCENE, old
    return MINIMAL_SCENE.replace(old, new, 1)


BAD_INPUTS = {
    "missing field": (_replace("fov_deg = 40\n", ""), "camera.fov_deg", "missing"),
    "wrong type": (_replace("fov_deg = 40", 'fov_deg = "wide"'), "camera.fov_deg", "expected a number"),
    "wrong type in list": (_replace("position = [0, 0, 3]", 'position = [0, "a", 3]'), "camera.position[1]", "expected a number"),
    "unknown material": (_replace('name = "light"\nmaterial = "white"', 'name = "light"\nmaterial = "chalk"'),
                         "meshes[1] (light).material", "unknown material 'chalk'"),
    "degenerate triangle": (_replace("[-1, 1, 0]]", "[3, 3, 0]]"), "meshes[0] (floor)", "degenerate"),
    "non-finite number": (_replace("position = [0, 0, 3]", "position = [0, nan, 3]"), "camera.position[1]", "finite"),
    "infinite radiance": (_replace("radiance = [10, 10, 10]", "radiance = [10, inf, 10]"),
                          "meshes[1] (light).emitter.radiance[1]", "finite"),
    "reflectance above 1": (_replace("reflectance = [0.8, 0.8, 0.8]", "reflectance = [0.8, 1.2, 0.8]"),
                            "materials.white.reflectance[1]", "[0, 1]"),
    "reflectance below 0": (_replace("reflectance = [0.8, 0.8, 0.8]", "reflectance = [-0.1, 0.8, 0.8]"),
                            "materials.white.reflectance[0]", "[0, 1]"),
    "zero-size resolution": (_replace("resolution = [8, 6]", "resolution = [0, 6]"), "camera.resolution[0]",
                             "must be >= 1, got 0"),
    "missing OBJ": (_replace('vertices = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]\nfaces = [[0, 1, 2, 3]]',
                             'obj = "nowhere.obj"'), "meshes[0] (floor).obj", "does not exist"),
    "face index out of range": (_replace("faces = [[0, 1, 2, 3]]", "faces = [[0, 1, 2, 9]]"),
                                "meshes[0] (floor).faces[0]", "out of range"),
    "undeclared feature": (_replace('"area_light", ', ""), "features", "uses area_light but does not declare"),
    "unknown feature": (_replace('"box_filter"]', '"box_filter", "caustics"]'), "features[5]", "unknown feature"),
    "bad max_depth": (_replace("max_depth = -1", "max_depth = 0"), "render.max_depth", "-1"),
    "unknown filter": (_replace('pixel_filter = "box"', 'pixel_filter = "gaussian"'), "render.pixel_filter", "unknown"),
    "boolean as number": (_replace("fov_deg = 40", "fov_deg = true"), "camera.fov_deg", "boolean"),
    "TOML syntax": (_replace("[camera]", "[camera"), "(syntax)", "invalid TOML"),
    # Unknown keys, at every level, with a did-you-mean where one is close.
    "unknown top-level key": (_replace("format = 1", "format = 1\nfeature = []"), "feature",
                              "unknown key (did you mean 'features'?)"),
    "unknown camera key": (_replace("fov_deg = 40", "fov_deg = 40\nfov = 40"), "camera.fov",
                           "unknown key (did you mean 'fov_deg'?)"),
    "unknown render key": (_replace("max_depth = -1", "max_depht = -1"), "render.max_depht",
                           "unknown key (did you mean 'max_depth'?)"),
    "unknown material key": (_replace('type = "diffuse"\n', 'type = "diffuse"\nroughness = 0.1\n'),
                             "materials.white.roughness", "unknown key (known: type, reflectance)"),
    "unknown mesh key": (_replace('name = "light"\n', 'name = "light"\ntwo_sided = true\n'),
                         "meshes[1] (light).two_sided", "unknown key"),
    "misspelt mesh name key": (_replace('name = "floor"', 'nmae = "floor"'), "meshes[0].nmae",
                               "unknown key (did you mean 'name'?)"),
    "unknown emitter key": (_replace("radiance = [10, 10, 10] }", "radiance = [10, 10, 10], power = 1 }"),
                            "meshes[1] (light).emitter.power", "unknown key"),
    "odd key quoted, one line": (_replace("[materials.white]", '[materials."wh\\nite"]\nx = 1\n[materials.white]'),
                                 'materials."wh\\nite".x', "unknown key"),
    # Values whose products overflow float64, and integers beyond it.
    "radiance 1e308": (_replace("radiance = [10, 10, 10]", "radiance = [1e308, 10, 10]"),
                       "meshes[1] (light).emitter.radiance[0]", "out of range"),
    "radiance above 1e30": (_replace("radiance = [10, 10, 10]", "radiance = [10, 2e30, 10]"),
                            "meshes[1] (light).emitter.radiance[1]", "must be in [0, 1e+30]"),
    "vertex 1e308 (not 'degenerate')": (_replace("[1, -1, 0], [1, 1, 0]", "[1e308, -1, 0], [1, 1, 0]"),
                                        "meshes[0] (floor).vertices[1][0]", "out of range"),
    "camera position 1e31": (_replace("position = [0, 0, 3]", "position = [0, 0, 1e31]"), "camera.position[2]",
                             "out of range"),
    "integer beyond float64": (_replace("fov_deg = 40", "fov_deg = 1" + "0" * 400), "camera.fov_deg", "out of range"),
    "integer vertex beyond float64": (_replace("[1, 1, 0]", "[1" + "0" * 400 + ", 1, 0]"),
                                      "meshes[0] (floor).vertices[2][0]", "out of range"),
    "max_depth beyond int32": (_replace("max_depth = -1", f"max_depth = {2**40}"), "render.max_depth",
                               "out of range: must be -1 (unbounded) or in [1, 2147483647]"),
    # Resolutions whose image buffers cannot fit: refused by the memory estimate, before any renderer.
    "resolution 2^70": (_replace("resolution = [8, 6]", f"resolution = [{2**70}, 6]"), "camera.resolution",
                        "estimated"),
    "resolution 200000^2": (_replace("resolution = [8, 6]", "resolution = [200000, 200000]"), "camera.resolution",
                            "6.98 TiB"),
    "100,000 nested arrays": (_replace('name = "minimal"\n', 'name = "minimal"\ndescription = ' + "[" * 100_000
                                       + "]" * 100_000 + "\n"), "(syntax)", "nested too deeply"),
}


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_bad_input_names_file_and_field(case, write_scene):
    text, field, words = BAD_INPUTS[case]
    path = write_scene(text)
    with pytest.raises(SceneError) as exc:
        load_scene(path)
    assert exc.value.file == str(path)
    assert exc.value.field == field
    assert words in exc.value.message
    assert "\n" not in str(exc.value)


@pytest.mark.parametrize("data, words", [
    (b"format = 1\nname = \"\xff\"\n", "not UTF-8 text: byte 0xff at offset 19"),
    (np.random.default_rng(9).bytes(1 << 20), "not UTF-8 text"),
], ids=["non-UTF-8", "random bytes"])
def test_undecodable_scene_file(data, words, tmp_path):
    path = tmp_path / "scene.toml"
    path.write_bytes(data)
    with pytest.raises(SceneError) as exc:
        load_scene(path)
    assert exc.value.field == "(file)" and words in exc.value.message


@pytest.mark.parametrize("obj, field, words", [
    (np.random.default_rng(9).bytes(4096), "meshes[0] (floor).obj", "not UTF-8"),
    (b"v -1 -1 0\nv 1e308 -1 0\nv 1 1 0\nf 1 2 3\n", "line 2", "out of range"),
    (b"v -1 -1 0\nv 1 -1 0\nv 1 1 0\nf 1 2 x\n", "line 4", "invalid literal"),
], ids=["garbage bytes", "1e308 vertex", "bad face"])
def test_bad_obj_file(obj, field, words, write_scene, tmp_path):
    (tmp_path / "bad.obj").write_bytes(obj)
    path = write_scene(_replace('vertices = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]\nfaces = [[0, 1, 2, 3]]',
                                'obj = "bad.obj"'))
    with pytest.raises(SceneError) as exc:
        load_scene(path)
    assert exc.value.field == field and words in exc.value.message


def test_memory_estimate_bounds_resolution(write_scene):
    """The estimate is width x height x 3 x 8 bytes x IMAGE_BUFFERS; 9000^2 fits in 16 GiB, 9500^2 does not."""
    assert image_memory_bytes(2048, 2048) == 2048 * 2048 * 3 * 8 * IMAGE_BUFFERS
    assert image_memory_bytes(9000, 9000) <= MAX_IMAGE_BYTES < image_memory_bytes(9500, 9500)
    assert load_scene(write_scene(_replace("resolution = [8, 6]", "resolution = [9000, 9000]"))).camera.width == 9000
    with pytest.raises(SceneError, match="camera.resolution"):
        load_scene(write_scene(_replace("resolution = [8, 6]", "resolution = [9500, 9500]"), "big.toml"))


def test_tiny_scene_is_not_degenerate(write_scene):
    """The degenerate-triangle test is relative to the scene's size: a box 1e-150 across still loads."""
    import re

    tiny = re.sub(r"(vertices = .*|position = .*)", lambda m: re.sub(r"(-?\d+(?:\.\d+)?)", r"\1e-150", m.group(0)),
                  MINIMAL_SCENE)
    s = load_scene(write_scene(tiny))
    assert np.abs(s.meshes[0].vertices).max() == pytest.approx(1e-150)


@pytest.mark.parametrize("scene", ["cornell-box", "cornell-box-caustics", "furnace", "light-panel"])
def test_stored_scenes_have_no_unknown_keys(scene):
    load_scene(CORNELL.parent.parent / scene / "scene.toml")


def test_missing_scene_file(tmp_path):
    with pytest.raises(SceneError, match="no such file"):
        load_scene(tmp_path / "absent.toml")


@pytest.mark.parametrize("case", ["unknown material", "degenerate triangle", "zero-size resolution"])
def test_cli_bad_scene_one_line_exit_2(case, write_scene, tmp_path):
    path = write_scene(BAD_INPUTS[case][0])
    proc = run_cbox("render", "--scene", str(path), "--renderer", "mitsuba", "--out", str(tmp_path / "x.exr"))
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"cbox: error: {path}: {BAD_INPUTS[case][1]}: "), proc.stderr
    assert "Traceback" not in proc.stderr


# --- Specular materials, spheres and regions ------------------------------------------

#: MINIMAL_SCENE with a mirror sphere and a glass sphere: every field the new tables have (ext_ior by default).
SPECULAR_SCENE = MINIMAL_SCENE.replace(
    '"box_filter"]', '"box_filter", "sphere", "mirror", "dielectric"]', 1) + """
[materials.chrome]
type = "mirror"
reflectance = [0.9, 0.8, 0.7]

[materials.glass]
type = "dielectric"
int_ior = 1.5

[[spheres]]
name = "ball"
material = "chrome"
center = [0.3, 0.2, 0.5]
radius = 0.25

[[spheres]]
name = "marble"
material = "glass"
center = [-0.3, -0.2, 0.4]
radius = 0.2
"""
_MARBLE = '[[spheres]]\nname = "marble"\nmaterial = "glass"\ncenter = [-0.3, -0.2, 0.4]\nradius = 0.2\n'


def _sreplace(old: str, new: str, text: str = SPECULAR_SCENE) -> str:
    assert text.count(old) == 1, old
    return text.replace(old, new, 1)


def test_specular_scene_parses(write_scene):
    from cornell_harness.scenes.materials import Dielectric, Mirror
    from cornell_harness.scenes.model import Sphere

    s = load_scene(write_scene(SPECULAR_SCENE))
    assert s.materials["chrome"] == Mirror("chrome", (0.9, 0.8, 0.7))
    assert s.materials["glass"] == Dielectric("glass", 1.5, 1.0)  # ext_ior defaults to 1 (air)
    assert s.materials["glass"].eta == 1.5
    assert s.spheres == (Sphere("ball", (0.3, 0.2, 0.5), 0.25, "chrome"),
                         Sphere("marble", (-0.3, -0.2, 0.4), 0.2, "glass"))
    assert {"sphere", "mirror", "dielectric"} <= s.features
    assert s.object_names() == ("floor", "light", "ball", "marble")
    assert s.regions == {}
    lo, hi = s.bounds()  # spheres count in the bounds: the ball reaches z = 0.75, the mesh corners x = ±1
    assert lo.tolist() == [-1.0, -1.0, 0.0] and hi.tolist() == [1.0, 1.0, 1.0]
    with_ext = load_scene(write_scene(_sreplace("int_ior = 1.5\n", "int_ior = 1.5\next_ior = 1.33\n"), "w.toml"))
    assert with_ext.materials["glass"].ext_ior == 1.33 and with_ext.materials["glass"].eta == pytest.approx(1.5 / 1.33)


def test_caustics_scene_loads():
    s = load_scene(CORNELL.parent.parent / "cornell-box-caustics" / "scene.toml")
    assert s.features == {"triangle_mesh", "sphere", "diffuse", "mirror", "dielectric", "area_light",
                          "pinhole_camera", "box_filter"}
    assert [(x.name, x.material) for x in s.spheres] == [("mirror-sphere", "mirror"), ("glass-sphere", "glass")]
    assert s.materials["glass"].int_ior == 1.5 and s.materials["glass"].ext_ior == 1.0


SPECULAR_BAD_INPUTS = {
    "misspelt material type": (_sreplace('type = "mirror"', 'type = "mirorr"'), "materials.chrome.type",
                               "unknown material type 'mirorr'; did you mean 'mirror'?"),
    "unknown material type": (_sreplace('type = "mirror"', 'type = "plastic"'), "materials.chrome.type",
                              "known: diffuse, mirror, dielectric"),
    "int_ior missing": (_sreplace("int_ior = 1.5\n", ""), "materials.glass.int_ior", "missing required field"),
    "int_ior zero": (_sreplace("int_ior = 1.5", "int_ior = 0"), "materials.glass.int_ior", "must be in (0, 10]"),
    "int_ior negative": (_sreplace("int_ior = 1.5", "int_ior = -1.5"), "materials.glass.int_ior", "got -1.5"),
    "int_ior too large": (_sreplace("int_ior = 1.5", "int_ior = 11"), "materials.glass.int_ior", "must be in (0, 10]"),
    "ext_ior out of range": (_sreplace("int_ior = 1.5", "int_ior = 1.5\next_ior = 0.0"), "materials.glass.ext_ior",
                             "must be in (0, 10]"),
    "int_ior not a number": (_sreplace("int_ior = 1.5", 'int_ior = "glass"'), "materials.glass.int_ior",
                             "expected a number"),
    "int_ior infinite": (_sreplace("int_ior = 1.5", "int_ior = inf"), "materials.glass.int_ior", "finite"),
    "mirror reflectance above 1": (_sreplace("[0.9, 0.8, 0.7]", "[0.9, 1.2, 0.7]"),
                                   "materials.chrome.reflectance[1]", "must be in [0, 1]"),
    "mirror reflectance below 0": (_sreplace("[0.9, 0.8, 0.7]", "[-0.1, 0.8, 0.7]"),
                                   "materials.chrome.reflectance[0]", "must be in [0, 1]"),
    "mirror reflectance missing": (_sreplace("reflectance = [0.9, 0.8, 0.7]\n", ""),
                                   "materials.chrome.reflectance", "missing required field"),
    "reflectance on a dielectric": (_sreplace("int_ior = 1.5", "int_ior = 1.5\nreflectance = [1, 1, 1]"),
                                    "materials.glass.reflectance", "unknown key (known: type, int_ior, ext_ior)"),
    "misspelt ior key": (_sreplace("int_ior = 1.5", "int_ior = 1.5\next_iro = 1.0"), "materials.glass.ext_iro",
                         "unknown key (did you mean 'ext_ior'?)"),
    "ior on a mirror": (_sreplace('type = "mirror"', 'type = "mirror"\nint_ior = 1.5'), "materials.chrome.int_ior",
                        "unknown key"),
    "sphere radius zero": (_sreplace("radius = 0.25", "radius = 0"), "spheres[0] (ball).radius", "must be in (0, "),
    "sphere radius negative": (_sreplace("radius = 0.25", "radius = -0.25"), "spheres[0] (ball).radius", "got -0.25"),
    "sphere radius missing": (_sreplace("radius = 0.25\n", ""), "spheres[0] (ball).radius", "missing required field"),
    "sphere center missing": (_sreplace("center = [0.3, 0.2, 0.5]\n", ""), "spheres[0] (ball).center",
                              "missing required field"),
    "sphere center of 2": (_sreplace("center = [0.3, 0.2, 0.5]", "center = [0.3, 0.2]"), "spheres[0] (ball).center",
                           "expected a list of 3 numbers"),
    "sphere center 1e31": (_sreplace("center = [0.3, 0.2, 0.5]", "center = [0.3, 1e31, 0.5]"),
                           "spheres[0] (ball).center[1]", "out of range"),
    "sphere unknown material": (_sreplace('material = "chrome"', 'material = "chalk"'), "spheres[0] (ball).material",
                                "unknown material 'chalk'; defined: chrome, glass, white"),
    "sphere unknown key": (_sreplace("radius = 0.25", "radius = 0.25\ncentre = [0, 0, 0]"), "spheres[0] (ball).centre",
                           "unknown key (did you mean 'center'?)"),
    "sphere not a table": (_sreplace('"dielectric"]', '"dielectric"]\nspheres = [1]', MINIMAL_SCENE.replace(
        '"box_filter"]', '"box_filter", "dielectric"]')), "spheres[0]", "expected a table"),
    "sphere named like a mesh": (_sreplace('name = "ball"', 'name = "floor"'), "meshes",
                                 "object name 'floor' is used more than once"),
    "two spheres of one name": (_sreplace('name = "marble"', 'name = "ball"'), "spheres",
                                "object name 'ball' is used more than once"),
    # Features: declared exactly what the content uses.
    "mirror used, not declared": (_sreplace('"sphere", "mirror", ', '"sphere", '), "features",
                                  "uses mirror but does not declare it"),
    "sphere used, not declared": (_sreplace('"sphere", "mirror", ', '"mirror", '), "features",
                                  "uses sphere but does not declare it"),
    "dielectric declared, not used": (_sreplace(_MARBLE, "").replace("[materials.glass]\ntype = \"dielectric\"\n"
                                                                     "int_ior = 1.5\n", ""), "features",
                                      "declares dielectric but does not use it"),
    "dielectric material defined but unused": (_sreplace(_MARBLE, ""), "features",
                                               "declares dielectric but does not use it"),
    # Regions.
    "region names an unknown object": (SPECULAR_SCENE + '[regions.shiny]\nobjects = ["bal"]\n',
                                       "regions.shiny.objects[0]", "no object named 'bal'; did you mean 'ball'?"),
    "region box min not below max": (SPECULAR_SCENE + "[regions.top]\nbox = { min = [0, 0, 0], max = [1, 0, 1] }\n",
                                     "regions.top.box", "min must be below max on every axis"),
    "region with neither objects nor box": (SPECULAR_SCENE + '[regions.empty]\ndescription = "nothing"\n',
                                            "regions.empty", "a region needs objects, a box, or both"),
    "region unknown key": (SPECULAR_SCENE + '[regions.shiny]\nobject = ["ball"]\n', "regions.shiny.object",
                           "unknown key (did you mean 'objects'?)"),
    "region object not a string": (SPECULAR_SCENE + '[regions.shiny]\nobjects = [1]\n', "regions.shiny.objects[0]",
                                   "expected a string"),
}


@pytest.mark.parametrize("case", sorted(SPECULAR_BAD_INPUTS))
def test_bad_specular_input_names_file_and_field(case, write_scene):
    text, field, words = SPECULAR_BAD_INPUTS[case]
    path = write_scene(text)
    with pytest.raises(SceneError) as exc:
        load_scene(path)
    assert exc.value.file == str(path)
    assert exc.value.field == field, exc.value
    assert words in exc.value.message, exc.value
    assert "\n" not in str(exc.value)


def test_regions_parse_and_do_not_change_the_hash(write_scene):
    text = SPECULAR_SCENE + """
[regions.shiny]
objects = ["ball", "marble"]
description = "the spheres"

[regions.floor-left]
objects = ["floor"]
box = { min = [-1, -1, -0.1], max = [0, 1, 0.1] }

[regions.anything-high]
box = { min = [-2, -2, 0.5], max = [2, 2, 2] }
"""
    from cornell_harness.scenes.model import Region

    s = load_scene(write_scene(text))
    assert s.regions == {
        "shiny": Region("shiny", ("ball", "marble"), None, "the spheres"),
        "floor-left": Region("floor-left", ("floor",), ((-1.0, -1.0, -0.1), (0.0, 1.0, 0.1)), ""),
        "anything-high": Region("anything-high", (), ((-2.0, -2.0, 0.5), (2.0, 2.0, 2.0)), ""),
    }
    assert s.content_hash() == load_scene(write_scene(SPECULAR_SCENE, "plain.toml")).content_hash()


def test_cornell_box_hash_is_its_stored_references():
    """Adding spheres and material types to the format left a Lambertian scene's content hash unchanged."""
    import json

    stored = json.loads((CORNELL.parent / "provenance.json").read_text())["scene_hash"]
    assert load_scene(CORNELL).content_hash() == stored


@pytest.mark.parametrize("old, new", [
    ("center = [0.3, 0.2, 0.5]", "center = [0.3, 0.2, 0.51]"),  # a sphere moved
    ("radius = 0.25", "radius = 0.26"),
    ("int_ior = 1.5", "int_ior = 1.52"),  # an IOR changed
    ("int_ior = 1.5", "int_ior = 1.5\next_ior = 1.33"),
    ("int_ior = 1.5", "int_ior = 1.5\next_ior = 1.0"),  # the default spelt out: the same content
    ("[0.9, 0.8, 0.7]", "[0.9, 0.8, 0.6]"),  # a mirror's reflectance
])
def test_specular_content_changes_the_hash(write_scene, old, new):
    h = load_scene(write_scene(SPECULAR_SCENE)).content_hash()
    changed = load_scene(write_scene(_sreplace(old, new), "changed.toml")).content_hash()
    if "ext_ior = 1.0" in new:
        assert changed == h
    else:
        assert changed != h


def test_mirror_and_diffuse_of_equal_reflectance_hash_differently(write_scene):
    """The material type is part of a non-diffuse material's hash: a mirror is not a white wall."""
    text = _sreplace('type = "mirror"', 'type = "diffuse"').replace('"mirror", ', "")
    diffuse = load_scene(write_scene(text, "d.toml"))
    mirror = load_scene(write_scene(SPECULAR_SCENE, "m.toml"))
    assert diffuse.materials["chrome"].reflectance == mirror.materials["chrome"].reflectance
    assert diffuse.content_hash() != mirror.content_hash()
