"""The USD export, read back with ``usd-core`` (``pxr``): every stored scene's meshes, spheres, materials, emitters,
camera and custom data are what the scene says, by USD's own reading of them.

The emitter's radiance is computed as UsdLux defines it (usd-core's ``usdLux/schema.usda``, ``LightAPI``:
intensity · 2^exposure · color, divided by the world-space area when ``normalize`` is on), and the camera by
casting points through ``GfCamera``'s frustum, which reads the focal length, the apertures and the transform as
every USD consumer does: a light left normalised, or apertures in another unit than the focal length, fails here.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import math

import numpy as np
import pytest

pytest.importorskip("pxr")  # the [usd] extra, in [all]: CI installs it

from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade  # noqa: E402

from tests.conftest import cbox_in_process as cbox  # noqa: E402
from cornell_harness import extras  # noqa: E402
from cornell_harness.scenes import export  # noqa: E402
from cornell_harness.scenes.export import usd  # noqa: E402
from cornell_harness.scenes.library import resolve_scene, scene_names  # noqa: E402
from cornell_harness.scenes.materials import Dielectric, Diffuse, Mirror  # noqa: E402
from cornell_harness.scenes.model import Camera  # noqa: E402


def written(scene, tmp_path) -> Usd.Stage:
    """The stage of ``scene``'s export, written by ``export_scene`` and opened from the file."""
    path = export.export_scene(scene, "usd", tmp_path / "d")
    assert path == tmp_path / "d" / "scene.usda"
    return Usd.Stage.Open(str(path))


def prims_by_name(stage: Usd.Stage) -> dict[str, Usd.Prim]:
    """Every prim that names a scene object or material in its custom data, by kind and name."""
    out = {}
    for prim in stage.Traverse():
        name = prim.GetCustomDataByKey("cbox:name")
        if name is not None and prim.GetPath().GetParentPath().name in ("Geometry", "Looks"):
            out[(prim.GetPath().GetParentPath().name, name, prim.GetPath().name)] = prim
    return out


def bound_surface(prim: Usd.Prim) -> UsdShade.Shader:
    material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
    shader = material.ComputeSurfaceSource()[0]
    assert shader.GetIdAttr().Get() == "UsdPreviewSurface"
    return shader


def value(shader: UsdShade.Shader, name: str):
    attr = shader.GetInput(name)
    return None if not attr or not attr.GetAttr().HasAuthoredValue() else attr.Get()


def usdlux_radiance(prim: Usd.Prim) -> np.ndarray:
    """The radiance UsdLux defines for the light on ``prim``: intensity · 2^exposure · color, over the world-space
    area when normalised (a colour temperature, were it on, would tint it: checked off)."""
    light = UsdLux.LightAPI(prim)
    assert not light.GetEnableColorTemperatureAttr().Get()
    le = light.GetIntensityAttr().Get() * 2.0 ** light.GetExposureAttr().Get() * np.array(light.GetColorAttr().Get())
    if light.GetNormalizeAttr().Get():
        p = np.array(UsdGeom.Mesh(prim).GetPointsAttr().Get(), dtype=np.float64)
        tri = np.array(UsdGeom.Mesh(prim).GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
        le /= 0.5 * np.linalg.norm(np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]]), axis=1).sum()
    return le


def usd_pixels(stage: Usd.Stage, points: np.ndarray, width: int, height: int) -> np.ndarray:
    """(col, row) of world ``points`` through the stage's camera as ``GfCamera`` projects them (NDC to pixels,
    row 0 at the top)."""
    gf = UsdGeom.Camera(stage.GetPrimAtPath("/World/Camera")).GetCamera(Usd.TimeCode.Default())
    frustum = gf.frustum
    m = frustum.ComputeViewMatrix() * frustum.ComputeProjectionMatrix()
    ndc = np.array([m.Transform(Gf.Vec3d(*map(float, p))) for p in points])
    return np.stack([(ndc[:, 0] + 1.0) / 2.0 * width, (1.0 - ndc[:, 1]) / 2.0 * height], axis=1)


def visible_points(scene) -> np.ndarray:
    """Points in front of the camera: every mesh's vertices and centroid, and the spheres' centres."""
    pts = [m.vertices for m in scene.meshes] + [m.vertices.mean(axis=0, keepdims=True) for m in scene.meshes]
    pts += [np.array([s.center]) for s in scene.spheres]
    p = np.concatenate(pts)
    _, _, forward = scene.camera.frame()
    return p[(p - np.asarray(scene.camera.position)) @ forward > 1e-3 * scene.extent()]


@pytest.mark.parametrize("name", scene_names())
def test_every_stored_scene_reads_back_as_it_is(tmp_path, name):
    scene = resolve_scene(name).at_frame(0)  # an animated scene's first frame: usd writes still scenes
    stage = written(scene, tmp_path)
    prims = prims_by_name(stage)
    geometry = {n: p for (kind, n, _), p in prims.items() if kind == "Geometry"}
    assert set(geometry) == set(scene.object_names())
    for m in scene.meshes:
        prim = geometry[m.name]
        mesh = UsdGeom.Mesh(prim)
        assert prim.GetTypeName() == "Mesh" and prim.GetCustomDataByKey("cbox:material") == m.material
        np.testing.assert_array_equal(np.array(mesh.GetPointsAttr().Get()), m.vertices.astype(np.float32))
        assert list(mesh.GetFaceVertexCountsAttr().Get()) == [3] * len(m.triangles)
        np.testing.assert_array_equal(np.array(mesh.GetFaceVertexIndicesAttr().Get()), m.triangles.ravel())
        assert mesh.GetSubdivisionSchemeAttr().Get() == "none" and mesh.GetOrientationAttr().Get() == "rightHanded"
        v, t = m.vertices, m.triangles
        ours = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
        normals = np.array(mesh.GetNormalsAttr().Get())
        assert mesh.GetNormalsInterpolation() == "uniform"
        np.testing.assert_allclose(normals, ours / np.linalg.norm(ours, axis=1, keepdims=True), atol=1e-6)
        assert mesh.GetDoubleSidedAttr().Get()
        check_material(bound_surface(prim), scene.materials[m.material], m.radiance)
        if m.is_emitter:
            assert prim.HasAPI(UsdLux.MeshLightAPI) and prim.GetCustomDataByKey("cbox:emits") == "front"
            light = UsdLux.LightAPI(prim)
            assert light.GetNormalizeAttr().Get() is False
            assert light.GetMaterialSyncModeAttr().Get() == "independent"
            np.testing.assert_allclose(usdlux_radiance(prim), m.radiance, rtol=1e-6)
            assert tuple(prim.GetCustomDataByKey("cbox:radiance")) == m.radiance
        else:
            assert not prim.HasAPI(UsdLux.LightAPI)
    for s in scene.spheres:
        prim = geometry[s.name]
        assert prim.GetTypeName() == "Sphere" and UsdGeom.Sphere(prim).GetRadiusAttr().Get() == s.radius
        to_world = UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default())
        assert tuple(to_world.ExtractTranslation()) == s.center and UsdGeom.Sphere(prim).GetDoubleSidedAttr().Get()
        check_material(bound_surface(prim), scene.materials[s.material], None)
    check_camera(stage, scene)
    check_stage_data(stage, scene)


def check_material(shader: UsdShade.Shader, material, emission) -> None:
    data = shader.GetPrim().GetParent().GetCustomDataByKey("cbox")
    assert data["name"] == material.name and data["type"] == material.type
    if isinstance(material, Dielectric):
        assert value(shader, "opacity") == 0.0 and value(shader, "roughness") == 0.0
        assert value(shader, "ior") == np.float32(material.int_ior / material.ext_ior)
        assert (data["int_ior"], data["ext_ior"], data["sides"]) == (material.int_ior, material.ext_ior, "both")
    else:
        np.testing.assert_array_equal(np.array(value(shader, "diffuseColor")),
                                      np.float32(material.reflectance))
        assert tuple(data["reflectance"]) == material.reflectance and data["sides"] == "front"
        assert value(shader, "opacity") is None  # opaque (the fallback, 1)
    if isinstance(material, Mirror):
        assert value(shader, "metallic") == 1.0 and value(shader, "roughness") == 0.0
    if isinstance(material, Diffuse):
        assert value(shader, "metallic") == 0.0 and value(shader, "ior") == 1.0  # Fresnel F0 = 0: no specular
    if emission is None:
        assert value(shader, "emissiveColor") is None
    else:
        np.testing.assert_array_equal(np.array(value(shader, "emissiveColor")), np.float32(emission))


def check_camera(stage: Usd.Stage, scene) -> None:
    cam = scene.camera
    pts = visible_points(scene)
    assert len(pts) >= 4
    np.testing.assert_allclose(usd_pixels(stage, pts, cam.width, cam.height), cam.project_to_pixels(pts),
                               atol=1e-3 * max(cam.width, cam.height))
    centre = usd_pixels(stage, np.array([cam.look_at]), cam.width, cam.height)
    np.testing.assert_allclose(centre, [[cam.width / 2.0, cam.height / 2.0]], atol=1e-6 * cam.width)
    gf = UsdGeom.Camera(stage.GetPrimAtPath("/World/Camera")).GetCamera(Usd.TimeCode.Default())
    tx, ty = cam.tan_half_fov()
    assert math.radians(gf.GetFieldOfView(Gf.Camera.FOVHorizontal)) == pytest.approx(2 * math.atan(tx), rel=1e-6)
    assert gf.aspectRatio == pytest.approx(cam.width / cam.height, rel=1e-6)
    near, far = gf.clippingRange.min, gf.clippingRange.max
    d = np.linalg.norm(np.concatenate([m.vertices for m in scene.meshes]) - np.asarray(cam.position), axis=1)
    assert near < d[d > 0].min() and far > d.max()  # nothing of the scene is clipped
    data = stage.GetPrimAtPath("/World/Camera").GetCustomDataByKey("cbox")
    assert (tuple(data["position"]), tuple(data["look_at"]), tuple(data["up"])) == (cam.position, cam.look_at, cam.up)
    assert (data["fov_deg"], data["fov_axis"], tuple(data["resolution"])) == (cam.fov_deg, cam.fov_axis,
                                                                               (cam.width, cam.height))


def check_stage_data(stage: Usd.Stage, scene) -> None:
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0 and stage.GetDefaultPrim().GetPath() == "/World"
    _, up, _ = scene.camera.frame()
    assert UsdGeom.GetStageUpAxis(stage) == ("Z" if abs(up[2]) > abs(up[1]) else "Y")
    assert Usd.ColorSpaceAPI(stage.GetDefaultPrim()).GetColorSpaceNameAttr().Get() == "lin_rec709_scene"
    data = stage.GetRootLayer().customLayerData["cbox"]
    assert (data["scene"], data["content_hash"], data["quantity"]) == (scene.name, scene.content_hash(),
                                                                      scene.quantity)
    assert (data["spp"], data["seed"], data["max_depth"]) == (usd.DEFAULT_SPP, usd.DEFAULT_SEED, scene.max_depth)
    assert data["pixel_filter"] == "box" and tuple(data["resolution"]) == (scene.camera.width, scene.camera.height)
    assert data["spectral"] == (scene.spectral is not None)
    ao = scene.ambient_occlusion
    if ao is None:
        assert "ambient_occlusion" not in data
    else:
        assert data["ambient_occlusion"] == {"max_distance": ao.max_distance, "weighting": ao.weighting,
                                             "normal": ao.normal, "miss_value": ao.miss_value}


def test_the_stored_scenes_cover_what_the_checks_check():
    """Meshes, spheres, each material type, an emitter of many triangles, a Z-up camera, AO and spectra."""
    scenes = [resolve_scene(n) for n in scene_names()]
    assert {type(m) for s in scenes for m in s.materials.values()} == {Diffuse, Mirror, Dielectric}
    assert any(s.spheres for s in scenes) and any(len(e.triangles) > 2 for s in scenes for e in s.emitters)
    assert {usd.up_axis(s.camera) for s in scenes} == {"Y", "Z"}
    assert {s.quantity for s in scenes} == set(usd.QUANTITIES) and any(s.spectral for s in scenes)


@pytest.mark.parametrize("axis", ["x", "y", "smaller", "larger"])
@pytest.mark.parametrize("size", [(48, 32), (32, 48)])
def test_the_camera_projects_as_ours_for_every_fov_axis_and_aspect(tmp_path, axis, size):
    base = resolve_scene("cornell-box")
    cam = Camera(position=(0.7, 0.4, 3.2), look_at=(-0.1, -0.2, 0.0), up=(0.1, 1.0, 0.2), fov_deg=47.0,
                 fov_axis=axis, width=size[0], height=size[1])
    scene = dataclasses.replace(base, camera=cam)
    check_camera(written(scene, tmp_path), scene)


def test_the_light_terms_give_the_radiance_and_a_black_emitter_is_white_at_intensity_zero():
    intensity, exposure, color = usd.light_terms((18.387, 13.9873, 6.75357))
    assert (intensity, exposure) == (18.387, 0.0) and max(color) == 1.0
    np.testing.assert_allclose(np.multiply(color, intensity * 2.0**exposure), (18.387, 13.9873, 6.75357), rtol=1e-15)
    assert usd.light_terms((0.0, 0.0, 0.0)) == (0.0, 0.0, (1.0, 1.0, 1.0))


def test_prim_names_are_valid_and_distinct():
    names = usd.prim_names(["mirror-sphere", "mirror_sphere", "1st", "", "lumière", "mirror-sphere"])
    assert all(Sdf.Path.IsValidIdentifier(n) for n in names) and len(set(names)) == len(names)
    assert names[:3] == ["mirror_sphere", "mirror_sphere_2", "_1st"]


def test_every_scene_is_expressible_and_the_format_carries_ambient_occlusion():
    assert usd.FEATURES == set(export.format_module("mitsuba").FEATURES)
    assert "ambient_occlusion" in usd.QUANTITIES
    for name in scene_names():
        scene = resolve_scene(name)
        assert export.refusal(scene.at_frame(0), "usd") is None, name
        assert (export.refusal(scene, "usd") is None) == (scene.animation is None), name


def test_cbox_export_writes_the_stage_and_prints_it(capsys, tmp_path):
    out = tmp_path / "d"
    code, stdout, err = cbox(capsys, "export", "--scene", "cornell-box-caustics", "--format", "usd", "--out", str(out),
                             "--set", "camera.resolution=24,16")
    assert code == 0, err
    assert stdout.strip() == str(out / "scene.usda") and sorted(p.name for p in out.iterdir()) == ["scene.usda"]
    stage = Usd.Stage.Open(stdout.strip())
    assert tuple(stage.GetRootLayer().customLayerData["cbox"]["resolution"]) == (24, 16)
    gf = UsdGeom.Camera(stage.GetPrimAtPath("/World/Camera")).GetCamera(Usd.TimeCode.Default())
    assert gf.aspectRatio == pytest.approx(1.5)


def test_without_usd_core_the_export_is_one_line_naming_the_extra(monkeypatch, capsys, tmp_path):
    real = importlib.util.find_spec
    monkeypatch.setattr(extras.importlib.util, "find_spec", lambda name, *a: None if name == "pxr" else real(name, *a))
    code, stdout, err = cbox(capsys, "export", "-s", "cornell-box", "-f", "usd", "-o", str(tmp_path / "d"))
    assert code == 2 and stdout == "" and not (tmp_path / "d").exists()
    assert err.splitlines() == ["cbox: error: the usd export format needs the [usd] extra (pxr not installed): "
                                "pip install 'cornell-harness[usd]'"]
    with pytest.raises(ImportError, match=r"pip install 'cornell-harness\[usd\]'$"):
        export.format_module("usd")  # a command renderer of scene_format usd is then unavailable, with this line
    assert export.format_module("pbrt-v4").NAME == "pbrt-v4"  # the formats that need no extra are unaffected


@pytest.mark.parametrize("name", ["cornell-box-caustics", "furnace-glass"])
def test_the_stage_passes_usd_cores_own_validators(tmp_path, name):
    from pxr import UsdValidation

    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    assert len(validators) >= 20  # usdGeom's, usdShade's, usdLux's, ... (30 in usd-core 26.11)
    errors = UsdValidation.ValidationContext(validators).Validate(written(resolve_scene(name), tmp_path))
    assert [f"{e.GetName()}: {e.GetMessage()}" for e in errors] == []


def test_an_unbounded_ao_distance_is_written_as_inf(tmp_path):
    scene = resolve_scene("cornell-box-ao")
    scene = dataclasses.replace(scene, ambient_occlusion=dataclasses.replace(scene.ambient_occlusion,
                                                                             max_distance=math.inf))
    stage = written(scene, tmp_path)
    assert stage.GetRootLayer().customLayerData["cbox"]["ambient_occlusion"]["max_distance"] == math.inf
    check_stage_data(stage, scene)
