"""The LuxCore SDL export (src/cornell_harness/scenes/export/luxcore.py): what it writes, checked without rendering.

Rendering the export is tests/renderers/test_luxcore.py's.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cornell_harness.scenes.export import export_scene, mapping_table, refusal
from cornell_harness.scenes.export import luxcore
from cornell_harness.scenes.export.ply import read_ply, write_ply
from cornell_harness.scenes.loader import load_scene
from cornell_harness.scenes.model import SceneError, Sphere
from cornell_harness.scenes.transforms import unit_frame
from tests.conftest import CORNELL, ROOT


def _props(path) -> dict[str, str]:
    """An SDL file as {key: value text}."""
    out = {}
    for line in path.read_text().splitlines():
        key, _, value = line.partition(" = ")
        out[key.strip()] = value.strip()
    return out


@pytest.fixture(scope="module")
def cornell_export(tmp_path_factory):
    scene = load_scene(CORNELL)
    return scene, export_scene(scene, "luxcore", tmp_path_factory.mktemp("lux"))


def test_cfg_names_the_scene_and_sets_film_filter_depth(cornell_export):
    scene, cfg = cornell_export
    p = _props(cfg)
    assert cfg.name == "scene.cfg" and (cfg.parent / "scene.scn").is_file()
    assert p["scene.file"] == '"scene.scn"'
    assert (p["film.width"], p["film.height"]) == ("256", "256")
    assert p["film.filter.type"] == '"BOX"' and float(p["film.filter.width"]) == 0.5
    # max_depth = -1 (unbounded): LuxCore's largest total depth, diffuse bounces cut where the light lost is
    # below the bound, and no Russian roulette (a cap of 1: LuxCore 2.11's roulette biases its MIS)
    assert int(p["path.pathdepth.total"]) == int(p["path.pathdepth.specular"]) == luxcore.UNBOUNDED_DEPTH
    assert int(p["path.pathdepth.diffuse"]) == int(p["path.pathdepth.glossy"]) == luxcore.diffuse_depth(scene)
    assert float(p["path.russianroulette.cap"]) == 1.0
    assert p["renderengine.type"] == '"PATHCPU"' and p["path.clamping.variance.maxvalue"] == "0"


def test_depth_is_passed_through(tmp_path):
    scene = load_scene(CORNELL).with_max_depth(3)
    p = _props(export_scene(scene, "luxcore", tmp_path))
    assert all(p[f"path.pathdepth.{k}"] == "3" for k in ("total", "diffuse", "glossy", "specular"))


@pytest.mark.parametrize("scene_name, depth", [("furnace", 52), ("cornell-box", 95), ("furnace-glass", 52)])
def test_unbounded_paths_are_cut_where_the_light_lost_is_below_the_bound(scene_name, depth):
    """n = ⌈ln ε / ln ρ⌉ diffuse bounces, ρ the largest diffuse reflectance in any channel: ρⁿ <= ε < ρⁿ⁻¹
    (furnace 0.8 -> 52; cornell-box's white, 0.885809 in red -> 95; the furnace-glass mirror of
    reflectance 1 is specular and does not count)."""
    scene = load_scene(ROOT / "src" / "cornell_harness" / "references" / scene_name)
    rho = max(max(m.reflectance) for m in scene.materials.values() if type(m).__name__ == "Diffuse")
    n = luxcore.diffuse_depth(scene)
    assert n == depth and rho**n <= luxcore.TRUNCATION < rho ** (n - 1)
    assert luxcore.depths(scene) == {"total": luxcore.UNBOUNDED_DEPTH, "diffuse": n, "glossy": n,
                                     "specular": luxcore.UNBOUNDED_DEPTH}
    # a bounded max_depth within n is kept as it is (exact, with no roulette), a larger one cut at n
    assert luxcore.depths(scene.with_max_depth(6))["diffuse"] == 6
    assert luxcore.depths(scene.with_max_depth(n + 10)) == {"total": n + 10, "diffuse": n, "glossy": n,
                                                           "specular": n + 10}


def test_max_depth_1_is_refused_naming_file_and_field(tmp_path):
    """LuxCore's path depth 1 adds direct light at the first hit: our emission-only max_depth 1 is refused
    before anything is written, depth 2 is not."""
    scene = load_scene(CORNELL)
    why = refusal(scene.with_max_depth(1), "luxcore")
    assert isinstance(why, SceneError) and "render.max_depth" in str(why) and str(scene.path) in str(why)
    with pytest.raises(SceneError, match="render.max_depth"):
        export_scene(scene.with_max_depth(1), "luxcore", tmp_path / "one")
    assert not (tmp_path / "one" / "scene.cfg").exists()
    assert refusal(scene.with_max_depth(2), "luxcore") is None
    assert refusal(scene.with_max_depth(1), "mitsuba") is None


def test_materials_are_one_sided_and_the_emitter_gives_its_rgb(cornell_export):
    scene, cfg = cornell_export
    p = _props(cfg.parent / "scene.scn")
    for name, material in scene.materials.items():
        assert p[f"scene.materials.{name}.type"] == '"twosided"'
        assert p[f"scene.materials.{name}.backmaterial"] == '"__black"'
        front = f"scene.materials.{name}__front"
        assert p[f"{front}.type"] == '"matte"'
        assert [float(x) for x in p[f"{front}.kd"].split()] == list(material.reflectance)
    assert p["scene.materials.__black.kd"] == "0 0 0"
    (emitter,) = [k.rsplit(".", 1)[0] for k in p if k.endswith(".emission")]
    assert emitter.endswith("__front")  # on the wrapper, a camera ray would not see it
    assert [float(x) for x in p[f"{emitter}.emission"].split()] == list(scene.emitters[0].radiance)
    assert p[f"{emitter}.emission.gain"] == "1 1 1"
    assert p[f"{emitter}.emission.power"] == p[f"{emitter}.emission.efficency"] == "0"
    assert p[f"{emitter}.emission.normalizebycolor"] == p[f"{emitter}.emission.gain.normalizebycolor"] == "0"


def test_meshes_are_plys_in_the_unit_frame(cornell_export):
    scene, cfg = cornell_export
    p = _props(cfg.parent / "scene.scn")
    centre, k = unit_frame(scene)
    for i, mesh in enumerate(scene.meshes):
        assert p[f"scene.objects.object{i}.shape"] == f'"shape{i}"'
        v, t = read_ply(cfg.parent / p[f"scene.shapes.shape{i}.ply"].strip('"'))
        np.testing.assert_allclose(v, (mesh.vertices - centre) * k, atol=1e-7)
        assert (t == mesh.triangles).all()
    eye = np.array(p["scene.camera.lookat.orig"].split(), float)
    np.testing.assert_allclose(eye, (np.array(scene.camera.position) - centre) * k)


@pytest.mark.parametrize("axis, size, want", [("smaller", (256, 256), 39.3077), ("x", (200, 100), None),
                                              ("larger", (100, 200), None)])
def test_fov_is_along_the_smaller_side(axis, size, want):
    scene = load_scene(CORNELL).with_resolution(*size)
    scene = type(scene)(**{**scene.__dict__, "camera": type(scene.camera)(**{**scene.camera.__dict__,
                                                                              "fov_axis": axis})})
    tx, ty = scene.camera.tan_half_fov()
    fov = luxcore.camera_fov(scene)
    assert math.tan(math.radians(fov) / 2) == pytest.approx(min(tx, ty))
    if want is not None:
        assert fov == pytest.approx(want)


def test_screenwindow_spans_the_aspect_moved_one_pixel_down():
    x0, x1, y0, y1 = luxcore.screenwindow(200, 100)
    assert (x0, x1) == (-2.0, 2.0) and (y1 - y0) == 2.0 and y0 == pytest.approx(-1.0 - 2.0 / 100)
    x0, x1, y0, y1 = luxcore.screenwindow(100, 200)
    assert (x0, x1) == (-1.0, 1.0) and y1 == pytest.approx(2.0 - 4.0 / 200)


def test_sphere_mesh_faces_out_and_stays_within_its_chord_error():
    s = Sphere("ball", (0.5, -0.2, 1.0), 0.3, "white")
    v, t, n = luxcore.sphere_mesh(s, segments=64)
    np.testing.assert_allclose(np.linalg.norm(v - s.center, axis=1), s.radius)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0)
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    normal = np.cross(b - a, c - a)
    area = np.linalg.norm(normal, axis=1) / 2
    assert (area > 0).all()  # no degenerate triangles at the poles
    out = np.einsum("ij,ij->i", normal, (a + b + c) / 3 - s.center)
    assert (out > 0).all()  # counter-clockwise seen from outside: the front is the outside
    # the mesh encloses the sphere's volume up to the chord error
    centroid_r = np.linalg.norm((a + b + c) / 3 - s.center, axis=1)
    assert centroid_r.min() >= s.radius * (1 - 2 * (1 - math.cos(math.pi / 64)))
    assert len(t) == 64 * 32 * 2 - 2 * 64


def test_ply_with_normals_round_trips(tmp_path):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    n = np.array([[0, 0, 1]] * 3, float)
    write_ply(tmp_path / "t.ply", v, [[0, 1, 2]], normals=n)
    assert b"property float nx" in (tmp_path / "t.ply").read_bytes()
    rv, rt = read_ply(tmp_path / "t.ply")
    np.testing.assert_array_equal(rv, v)
    assert rt.tolist() == [[0, 1, 2]]


def test_spheres_are_written_with_normals(tmp_path):
    scene = load_scene(ROOT / "src" / "cornell_harness" / "references" / "cornell-box-caustics" / "scene.toml")
    cfg = export_scene(scene, "luxcore", tmp_path)
    p = _props(cfg.parent / "scene.scn")
    glass = [k for k, v in p.items() if v == '"glass"' and k.endswith(".type")]
    assert len(glass) == 1 and p[glass[0].replace(".type", ".interiorior")] == "1.5"
    assert any(v == '"mirror"' and k.endswith(".type") for k, v in p.items())
    spheres = sorted(tmp_path.glob("sphere*.ply"))
    assert len(spheres) == 2 and b"property float nx" in spheres[0].read_bytes()[:400]


def test_ambient_occlusion_is_refused():
    scene = load_scene(ROOT / "src" / "cornell_harness" / "references" / "cornell-box-ao" / "scene.toml")
    why = refusal(scene, "luxcore")
    assert isinstance(why, SceneError) and why.field == "quantity"


def test_mapping_table_has_every_aspect():
    table = mapping_table("luxcore")
    for aspect in ("camera", "fov axis", "handedness", "emitter side", "two-sidedness", "filter", "depth", "IOR",
                   "sphere"):
        assert f"| {aspect} |" in table
