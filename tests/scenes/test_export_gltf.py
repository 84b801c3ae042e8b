"""The glTF 2.0 export, read back with pygltflib (the ``[gltf]`` extra, installed by the suite's set-up).

Every stored scene glTF can express is written and read back: its vertices, triangles, materials, emitted
radiance and camera must be ours. The camera is checked by projecting points through glTF's own camera model
(the node's TRS as a matrix, the specification's infinite perspective projection, NDC y up), independently
of the module's code, against our camera's :meth:`~cornell_harness.scenes.model.Camera.project_to_pixels`.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tests.conftest import cbox_in_process
from cornell_harness import extras
from cornell_harness.scenes.export import export_scene, gltf, mapping_table, refusal
from cornell_harness.scenes.library import resolve_scene, scene_names
from cornell_harness.scenes.materials import Dielectric, Diffuse, Mirror
from cornell_harness.scenes.model import SceneError

pygltflib = pytest.importorskip("pygltflib")  # the [gltf] extra: CI's set-up installs [all], so this runs there

DTYPES = {gltf.FLOAT: "<f4", gltf.UNSIGNED_INT: "<u4"}
WIDTH = {"SCALAR": 1, "VEC3": 3}


def read_back(path):
    """(the pygltflib document, a function giving accessor ``i``'s data as a NumPy array)."""
    doc = pygltflib.GLTF2.load(str(path))
    (buffer,) = doc.buffers
    blob = (path.parent / buffer.uri).read_bytes()
    assert len(blob) == buffer.byteLength

    def accessor(i: int) -> np.ndarray:
        a = doc.accessors[i]
        view = doc.bufferViews[a.bufferView]
        data = np.frombuffer(blob, dtype=DTYPES[a.componentType], count=a.count * WIDTH[a.type],
                             offset=view.byteOffset + (a.byteOffset or 0))
        return data.reshape(a.count, WIDTH[a.type]) if a.type == "VEC3" else data

    return doc, accessor


def exported(scene, tmp_path):
    path = export_scene(scene, "gltf", tmp_path / "out")
    assert path == tmp_path / "out" / "scene.gltf"
    return read_back(path)


def rotation_matrix(q) -> np.ndarray:
    """The rotation of glTF's unit quaternion ``q`` = [x, y, z, w]."""
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def gltf_projection(doc, points: np.ndarray, width: int, height: int) -> np.ndarray:
    """(col, row) of world ``points`` through the document's camera node, by the glTF specification alone:
    the node's matrix from translation and rotation (quaternion x, y, z, w), the view its inverse, the
    infinite perspective projection of "Projection Matrices", NDC x right and y up."""
    (node,) = [n for n in doc.nodes if n.camera is not None]
    r = rotation_matrix(node.rotation)
    model = np.eye(4)
    model[:3, :3], model[:3, 3] = r, node.translation
    p = doc.cameras[node.camera].perspective
    t = math.tan(p.yfov / 2)
    proj = np.array([[1 / (p.aspectRatio * t), 0, 0, 0], [0, 1 / t, 0, 0],
                     [0, 0, -1, -2 * p.znear], [0, 0, -1, 0]])
    clip = (proj @ np.linalg.inv(model) @ np.c_[points, np.ones(len(points))].T).T
    ndc = clip[:, :3] / clip[:, 3:]
    assert (clip[:, 3] > 0).all()  # in front of the camera
    return np.stack([(ndc[:, 0] + 1) / 2 * width, (1 - ndc[:, 1]) / 2 * height], axis=1)


# --- every stored scene --------------------------------------------------------------------------------------

def test_only_the_ambient_occlusion_and_animated_scenes_are_refused():
    refused = {name: refusal(resolve_scene(name), "gltf") for name in scene_names()}
    refused = {name: why.field for name, why in refused.items() if why is not None}
    assert refused == {"cornell-box-ao": "quantity", "cornell-box-moving-light": "animation",
                       "cornell-box-orbit": "animation"}


EXPRESSIBLE = [n for n in scene_names() if resolve_scene(n).quantity == "radiance" and not resolve_scene(n).animation]


@pytest.mark.parametrize("name", EXPRESSIBLE)
def test_a_stored_scene_reads_back_as_ours(tmp_path, name):
    scene = resolve_scene(name)
    doc, accessor = exported(scene, tmp_path)
    meshes = {m.name: m for m in doc.meshes}
    assert sorted(meshes) == sorted(scene.object_names())
    nodes = [n for n in doc.nodes if n.mesh is not None]
    assert all(n.matrix is None and n.translation is None and n.rotation is None for n in nodes)  # identity
    assert sorted(doc.meshes[n.mesh].name for n in nodes) == sorted(meshes)
    assert sorted(doc.scenes[doc.scene].nodes) == list(range(len(doc.nodes)))
    for m in scene.meshes:
        (prim,) = meshes[m.name].primitives
        assert prim.mode == 4 and prim.attributes.NORMAL is None  # triangles, shaded flat as ours
        assert np.array_equal(accessor(prim.attributes.POSITION), m.vertices.astype(np.float32))
        tris = accessor(prim.indices).reshape(-1, 3)
        assert len(tris) == len(m.triangles) and np.array_equal(tris, m.triangles)  # same winding: same front
        a = doc.accessors[prim.attributes.POSITION]
        assert a.min == m.vertices.astype(np.float32).min(axis=0).tolist()
        check_material(doc.materials[prim.material], scene.materials[m.material], m.radiance)
    for s in scene.spheres:
        (prim,) = meshes[s.name].primitives
        v, n = accessor(prim.attributes.POSITION), accessor(prim.attributes.NORMAL)
        assert np.allclose(np.linalg.norm(v - np.float32(s.center), axis=1), s.radius, rtol=1e-6)
        assert np.allclose(v, np.float32(s.center) + s.radius * n, atol=1e-6 * (1 + abs(np.array(s.center)).max()))
        tris = accessor(prim.indices).reshape(-1, 3)
        a, b, c = (v[tris[:, k]].astype(np.float64) for k in range(3))
        centroid = (a + b + c) / 3 - s.center
        assert (np.einsum("ij,ij->i", np.cross(b - a, c - a), centroid) > 0).all()  # front faces out
        check_material(doc.materials[prim.material], scene.materials[s.material], None)
    assert set(doc.extensionsUsed) == set(doc.extensionsRequired) <= set(gltf.EXTENSIONS)
    assert set(doc.extensionsUsed) == {k for mat in doc.materials for k in mat.extensions}
    extras_ = doc.scenes[doc.scene].extras
    assert extras_["scene"] == scene.name and extras_["content_hash"] == scene.content_hash()
    assert (extras_["max_depth"], extras_["pixel_filter"]) == (scene.max_depth, scene.pixel_filter)
    assert (extras_["spp"], extras_["seed"]) == (gltf.DEFAULT_SPP, gltf.DEFAULT_SEED)
    assert ("spectral" in extras_) == (scene.spectral is not None)


def check_material(mat, ours, radiance):
    """A glTF material is our material (and emits our radiance, or nothing)."""
    pbr, ext = mat.pbrMetallicRoughness, mat.extensions
    assert mat.doubleSided is False and mat.alphaMode == "OPAQUE"
    if isinstance(ours, Diffuse):
        assert pbr.baseColorFactor == [*ours.reflectance, 1.0]
        assert (pbr.metallicFactor, pbr.roughnessFactor) == (0.0, 1.0)
        assert ext["KHR_materials_specular"] == {"specularFactor": 0.0}  # Lambertian: no specular layer
    elif isinstance(ours, Mirror):
        assert pbr.baseColorFactor == [*ours.reflectance, 1.0]
        assert (pbr.metallicFactor, pbr.roughnessFactor) == (1.0, 0.0)
    else:
        assert isinstance(ours, Dielectric)
        assert pbr.baseColorFactor == [1.0, 1.0, 1.0, 1.0] and (pbr.metallicFactor, pbr.roughnessFactor) == (0.0, 0.0)
        assert ext["KHR_materials_transmission"] == {"transmissionFactor": 1.0}
        assert ext["KHR_materials_ior"]["ior"] == pytest.approx(ours.int_ior / ours.ext_ior, rel=1e-15)
        assert ext["KHR_materials_volume"]["thicknessFactor"] > 0  # a solid, not a thin wall
    assert mat.extras["type"] == ours.type
    if radiance is None:
        assert mat.emissiveFactor in (None, [0.0, 0.0, 0.0]) and "KHR_materials_emissive_strength" not in ext
    else:
        factor, strength = np.array(mat.emissiveFactor), ext["KHR_materials_emissive_strength"]["emissiveStrength"]
        assert factor.max() == 1.0 and factor.min() >= 0.0  # glTF bounds each channel by 1
        assert np.allclose(factor * strength, radiance, rtol=1e-15, atol=0)  # emitted radiance = ours, no π


def test_a_spectral_scene_is_written_as_its_rgb_projection(tmp_path):
    scene = resolve_scene("cornell-box-measured")
    doc, _ = exported(scene, tmp_path)
    assert "RGB projection" in doc.scenes[0].extras["spectral"]
    white = next(m for m in doc.materials if m.name == "white")
    assert white.pbrMetallicRoughness.baseColorFactor[:3] == list(scene.materials["white"].reflectance)


# --- the camera ----------------------------------------------------------------------------------------------

CAMERAS = [  # (fov_axis, width, height, position, look_at, up)
    ("smaller", 256, 256, None, None, None),
    ("x", 24, 16, None, None, None),
    ("y", 24, 16, None, None, None),
    ("larger", 16, 24, None, None, None),
    ("smaller", 16, 24, (0.7, -0.4, 3.0), (-0.2, 0.1, -0.5), (0.3, 1.0, 0.1)),  # tilted: up not ⟂ forward
    ("x", 30, 20, (0.0, 3.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0)),  # looking straight down
    ("y", 20, 30, (0.0, 0.0, -3.0), (0.0, 0.0, 1.0), (-1.0, 0.0, 0.0)),  # a half turn about (1, -1, 0)
]


@pytest.mark.parametrize("axis, width, height, position, look_at, up", CAMERAS)
def test_the_gltf_camera_projects_points_where_ours_does(tmp_path, axis, width, height, position, look_at, up):
    scene = resolve_scene("cornell-box")
    cam = dataclasses.replace(scene.camera, fov_axis=axis, width=width, height=height,
                              position=position or scene.camera.position, look_at=look_at or scene.camera.look_at,
                              up=up or scene.camera.up)
    scene = dataclasses.replace(scene, camera=cam)
    doc, _ = exported(scene, tmp_path)
    p = doc.cameras[0].perspective
    assert p.aspectRatio == pytest.approx(width / height, rel=1e-15) and 0 < p.znear < 1e-3 * scene.extent()
    assert p.zfar is None
    assert doc.cameras[0].extras["resolution"] == [width, height]
    rng = np.random.default_rng(7)
    points = np.array(cam.look_at) + rng.uniform(-0.8, 0.8, (200, 3))
    points = points[(points - cam.position) @ cam.frame()[2] > 0.1]
    assert np.allclose(gltf_projection(doc, points, width, height), cam.project_to_pixels(points), atol=1e-9 * width)


def test_the_red_wall_is_on_the_left_of_the_gltf_image(tmp_path):
    """An anchor that does not go through our camera code: the Cornell box's red wall (x = -1) on the left."""
    scene = resolve_scene("cornell-box")
    doc, _ = exported(scene, tmp_path)
    red = next(m for m in scene.meshes if m.name == "red-wall").vertices.mean(axis=0)
    green = next(m for m in scene.meshes if m.name == "green-wall").vertices.mean(axis=0)
    light = next(m for m in scene.meshes if m.is_emitter).vertices.mean(axis=0)
    (red_col, _), (green_col, _), (_, light_row) = gltf_projection(doc, np.array([red, green, light]), 256, 256)
    assert red_col < 128 < green_col and light_row < 128  # red left, green right, the light at the top


def test_quaternions_give_back_their_rotation_half_turns_included():
    from scipy.spatial.transform import Rotation

    rotations = list(Rotation.random(500, random_state=3).as_matrix()) + [np.eye(3)]
    for axis in [(1, -1, 0), (1, 1, 0), (0, 1, -1), (1, 0, -1), (1, 1, 1), (1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        a = np.array(axis, dtype=float) / np.linalg.norm(axis)
        rotations.append(2 * np.outer(a, a) - np.eye(3))  # a half turn: w = 0, the signs from the off-diagonal
    for r in rotations:
        q = gltf.quaternion(r)
        assert np.allclose(rotation_matrix(q), r, atol=1e-14) and q[3] >= 0


def test_the_camera_rotation_is_a_rotation_whose_minus_z_is_forward():
    scene = resolve_scene("cornell-box")
    r = gltf.camera_rotation(scene)
    assert np.allclose(r.T @ r, np.eye(3)) and np.linalg.det(r) == pytest.approx(1.0)
    assert np.allclose(-r[:, 2], scene.camera.frame()[2])


# --- refusals, the extra, the CLI ----------------------------------------------------------------------------

def test_an_ambient_occlusion_scene_is_refused_naming_file_and_field(tmp_path):
    with pytest.raises(SceneError) as e:
        export_scene(resolve_scene("cornell-box-ao"), "gltf", tmp_path / "out")
    assert e.value.field == "quantity" and e.value.file.endswith("cornell-box-ao/scene.toml")
    assert not (tmp_path / "out").exists()


def test_an_emitting_dielectric_is_refused_naming_file_and_field(tmp_path):
    scene = resolve_scene("cornell-box-caustics")
    meshes = tuple(dataclasses.replace(m, material="glass") if m.is_emitter else m for m in scene.meshes)
    scene = dataclasses.replace(scene, meshes=meshes)
    with pytest.raises(SceneError) as e:
        export_scene(scene, "gltf", tmp_path / "out")
    assert e.value.field == "meshes[5] (light).emitter" and e.value.file == str(scene.path)
    assert "two-sided" in e.value.message and not (tmp_path / "out").exists()


def test_without_pygltflib_the_export_is_one_line_with_the_pip_line(monkeypatch, capsys, tmp_path):
    real = extras.importlib.util.find_spec
    monkeypatch.setattr(extras.importlib.util, "find_spec", lambda n, *a: None if n == "pygltflib" else real(n, *a))
    code, out, err = cbox_in_process(capsys, "export", "-s", "cornell-box", "-f", "gltf", "-o", str(tmp_path / "d"))
    assert code == 2 and out == ""
    assert err.splitlines() == ["cbox: error: the gltf export format needs the [gltf] extra (pygltflib not "
                                "installed): pip install 'cornell-harness[gltf]'"]


def test_cbox_export_writes_the_gltf_and_its_buffer(capsys, tmp_path):
    code, out, err = cbox_in_process(capsys, "export", "--scene", "cornell-box", "--format", "gltf",
                                     "--out", str(tmp_path / "d"), "--set", "camera.resolution=24,16")
    assert code == 0, err
    assert out.strip() == str(tmp_path / "d" / "scene.gltf")
    assert sorted(p.name for p in (tmp_path / "d").iterdir()) == ["scene.bin", "scene.gltf"]
    doc, _ = read_back(tmp_path / "d" / "scene.gltf")
    assert doc.cameras[0].perspective.aspectRatio == 1.5 and doc.asset.version == "2.0"


# --- the numbers the mapping table states --------------------------------------------------------------------

def test_emission_splits_radiance_into_a_factor_at_most_1_and_a_strength():
    assert gltf.emission((18.387, 13.9873, 6.75357)) == ([1.0, 13.9873 / 18.387, 6.75357 / 18.387], 18.387)
    assert gltf.emission((0.5, 0.25, 0.0)) == ([1.0, 0.5, 0.0], 0.5)
    assert gltf.emission((0.0, 0.0, 0.0)) == ([0.0, 0.0, 0.0], 1.0)


def test_schlick_and_fresnel_agree_at_normal_incidence_and_part_near_grazing():
    f0 = ((1.5 - 1) / (1.5 + 1)) ** 2
    assert gltf.fresnel(1.5, 1.0) == pytest.approx(f0) and gltf.schlick(f0, 1.0) == pytest.approx(f0)
    assert gltf.fresnel(1.5, 1e-9) == pytest.approx(1.0, abs=1e-6) and gltf.schlick(f0, 0.0) == 1.0
    assert gltf.fresnel(1.5, math.cos(math.radians(60))) == pytest.approx(0.0892, abs=1e-4)  # Rs 0.177, Rp 0.002
    assert abs(gltf.schlick(f0, math.cos(math.radians(85))) - gltf.fresnel(1.5, math.cos(math.radians(85)))) > 0.01


def test_the_mapping_table_names_what_gltf_cannot_say():
    table = mapping_table("gltf")
    for aspect in ("camera", "handedness", "emitted radiance", "emitter side", "two-sidedness", "mirror", "glass",
                   "IOR", "colour", "depth", "samples", "sphere"):
        assert f"| {aspect} |" in table
    assert "no constant-reflectance mirror" in table and "Schlick" in table and "RGB projection" in table
