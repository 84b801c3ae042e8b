"""OpenUSD: a scene written as a USD stage (``scene.usda``, text), with ``usd-core`` (the ``[usd]`` extra).

For the renderers that read USD (Cycles through Blender's USD importer, Karma, Arnold, RenderMan,
Omniverse). The stage holds the meshes (``UsdGeomMesh``) and spheres (``UsdGeomSphere``), one
``UsdPreviewSurface`` material per scene material, the emitters as mesh lights and the camera; what USD
has no schema for (samples, seed, depth, the AO definition, our exact materials) is custom data under
the key ``cbox``: the root layer's ``customLayerData`` for the scene, each prim's ``customData`` for
itself. :data:`MAPPING` says how each aspect is written and what a consumer must do where USD's
schemas say less than our model (the mirror, the glass, the emitter's side, reflection from behind).

The emitter is its mesh with ``UsdLuxMeshLightAPI`` applied and a bound ``UsdPreviewSurface`` whose
``emissiveColor`` is the radiance. The emissive material is what Blender's USD importer (which ignores
``MeshLightAPI``) and Omniverse build their mesh lights from, and it keeps the emitter's own reflectance;
a ``RectLight`` would drop that and could not express an emitter that is not one rectangle (``furnace``'s
box). The light's ``materialSyncMode`` is ``independent`` and ``normalize`` off, so that
intensity · 2^exposure · color is the radiance by itself (usd-core's ``usdLux/schema.usda``,
``LightAPI``: a light of intensity 1 and exposure 0 seen directly gives pixel value 1; ``normalize``
would divide by the world-space area).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade, Vt

from cornell_harness.scenes.materials import Dielectric, Diffuse, Mirror
from cornell_harness.scenes.model import Camera, Mesh, Scene, Sphere

NAME = "usd"
FEATURES = frozenset({"triangle_mesh", "sphere", "diffuse", "mirror", "dielectric", "area_light",
                      "pinhole_camera", "box_filter"})
#: The quantities the stage carries: an AO scene's definition is custom data (``cbox.ambient_occlusion``).
QUANTITIES = ("radiance", "ambient_occlusion")

#: Samples per pixel and seed the stage's custom data gives (a consumer's own settings override them).
DEFAULT_SPP = 64
DEFAULT_SEED = 0
#: The camera's ``focalLength`` (USD's fallback), in tenths of a scene unit; the apertures, in the same unit,
#: set the field of view: only their ratio to it matters.
FOCAL_LENGTH = 50.0
MAIN_FILE = "scene.usda"

MAPPING = (
    ("units", "scene units", "the same coordinates; `metersPerUnit` 1 (the image does not depend on the unit: "
                             "radiance is per scene unit, and an importer that scales by it, as Blender's does, "
                             "then leaves lengths as they are); `upAxis` Y or Z, whichever the camera's `up` is "
                             "nearer (a hint: nothing is rotated)"),
    ("camera", "pinhole at `position` looking at `look_at`, `up`", "`UsdGeomCamera` (perspective) with "
                                                                   "`xformOp:transform` rows right, up, "
                                                                   "−forward, position: USD cameras look "
                                                                   "along their −Z with +Y up"),
    ("fov axis", "`fov_deg` along `fov_axis` (x, y, smaller, larger)", f"`focalLength` {FOCAL_LENGTH:g} and "
                                                                       "`horizontalAperture` = 2·tan(half-angle "
                                                                       "along x)·focalLength, "
                                                                       "`verticalAperture` likewise along y, "
                                                                       "in the same unit: the image's aspect "
                                                                       "ratio. USD has no resolution: "
                                                                       "`cbox.resolution` (and Blender's "
                                                                       "sensor fit must be horizontal for a "
                                                                       "portrait image)"),
    ("handedness", "right = forward × up; pixel (0, 0) top-left", "the same: the camera's +X is the image's "
                                                                  "right, +Y its top"),
    ("geometry", "triangles, quads split (a, b, c), (a, c, d); spheres", "`UsdGeomMesh` (float32 `points`, "
                                                                         "triangles, `subdivisionScheme` none, "
                                                                         "one normal per face: flat); "
                                                                         "`UsdGeomSphere` (`radius`) with a "
                                                                         "`translate`; all `doubleSided`"),
    ("emitter", "`radiance` on a mesh, linear sRGB", "the mesh with `UsdLuxMeshLightAPI`: `inputs:intensity` "
                                                     "the largest channel, `inputs:exposure` 0, `inputs:color` "
                                                     "the radiance over it, `inputs:normalize` false, "
                                                     "`light:materialSyncMode` independent: intensity · "
                                                     "2^exposure · color = radiance; its material's "
                                                     "`emissiveColor` is the radiance too"),
    ("emitter side", "front side only (counter-clockwise winding)", "the front is the side of the winding's "
                                                                    "normal (`orientation` rightHanded, "
                                                                    "counter-clockwise, as ours); UsdLux does "
                                                                    "not say on which sides a mesh light "
                                                                    "emits, and Cycles emits on both: a "
                                                                    "consumer must not emit from the back "
                                                                    "(`cbox.emits` front)"),
    ("diffuse", "Lambertian, albedo R, front side only", "`diffuseColor` R, `metallic` 0, `ior` 1: the preview "
                                                         "surface's Fresnel F0 = ((1 − ior)/(1 + ior))² = 0, "
                                                         "so no specular reflection at normal incidence (a "
                                                         "Schlick Fresnel still reflects at grazing; an exact "
                                                         "dielectric Fresnel reflects nothing at ior 1), "
                                                         "`roughness` 1; a consumer must render it Lambertian"),
    ("mirror", "constant specular reflectance R, any angle", "`metallic` 1, `roughness` 0, `diffuseColor` R: "
                                                             "the preview surface's metal reflects R at "
                                                             "normal incidence only, rising to 1 at grazing "
                                                             "(Schlick); USD has no constant-reflectance "
                                                             "mirror: a consumer must reflect R at every angle "
                                                             "(`cbox.reflectance`; in Cycles a Glossy BSDF, "
                                                             "roughness 0, colour R)"),
    ("glass", "smooth dielectric, `int_ior` inside, `ext_ior` outside", "`opacity` 0 (clear, still specular), "
                                                                        "`ior` int_ior / ext_ior, `roughness` "
                                                                        "0; Blender's importer makes "
                                                                        "opacity alpha (the sphere vanishes): "
                                                                        "a consumer must build a smooth "
                                                                        "dielectric from `cbox.int_ior`, "
                                                                        "`cbox.ext_ior`"),
    ("two-sidedness", "diffuse and mirror reflect on the front side only (black from behind); dielectric "
                      "both sides", "USD's preview surface has no one-sided form and `doubleSided` false means "
                                    "culled (transparent) from behind: every gprim is `doubleSided`, and a "
                                    "consumer reflecting on both sides differs only where paths meet a back "
                                    "face (the gap behind the Cornell box's light); `cbox.sides`"),
    ("colour", "linear sRGB; a spectral scene's sampled spectra", "`colorSpace:name` lin_rec709_scene on "
                                                                   "/World (linear sRGB); a spectral scene "
                                                                   "is written as its RGB projection "
                                                                   "(USD has no spectra; `cbox.spectral` "
                                                                   "true)"),
    ("filter", "box: each pixel the mean over its own square", "`cbox.pixel_filter` box (USD has no film)"),
    ("depth", "`max_depth` path segments, -1 unbounded", "`cbox.max_depth`, the same number (Mitsuba's "
                                                         "convention: 1 = emitters seen directly)"),
    ("samples", "spp, seed", f"`cbox.spp` {DEFAULT_SPP}, `cbox.seed` {DEFAULT_SEED}"),
    ("quantity", "radiance, or ambient occlusion with its definition", "`cbox.quantity`; for AO "
                                                                       "`cbox.ambient_occlusion`: "
                                                                       "`max_distance` (scene units, inf for "
                                                                       "none), `weighting`, `normal`, "
                                                                       "`miss_value`"),
)


def _vec3f(x) -> Gf.Vec3f:
    return Gf.Vec3f(*(float(c) for c in x))


def _vec3d(x) -> Gf.Vec3d:
    return Gf.Vec3d(*(float(c) for c in x))


def prim_names(names: list[str]) -> list[str]:
    """Valid, distinct USD prim names for ``names`` (in order): characters other than letters, digits and ``_``
    become ``_``, a leading digit gets a ``_``, and a repeat a ``_2``, ``_3``…; the name itself is custom data."""
    out: list[str] = []
    for name in names:
        base = "".join(c if c.isascii() and (c.isalnum() or c == "_") else "_" for c in name) or "_"
        base = "_" + base if base[0].isdigit() else base
        candidate, k = base, 1
        while candidate in out:
            k += 1
            candidate = f"{base}_{k}"
        out.append(candidate)
    return out


def light_terms(radiance) -> tuple[float, float, tuple[float, float, float]]:
    """``(intensity, exposure, color)`` of a light whose intensity · 2^exposure · color is ``radiance``: the largest
    channel, 0, the radiance over it (white, and intensity 0, for a black emitter)."""
    peak = max(float(c) for c in radiance)
    if peak <= 0.0:
        return 0.0, 0.0, (1.0, 1.0, 1.0)
    return peak, 0.0, tuple(float(c) / peak for c in radiance)


def apertures(camera: Camera) -> tuple[float, float]:
    """``(horizontalAperture, verticalAperture)`` that, with :data:`FOCAL_LENGTH`, give the camera's field of view."""
    tx, ty = camera.tan_half_fov()
    return 2.0 * tx * FOCAL_LENGTH, 2.0 * ty * FOCAL_LENGTH


def camera_matrix(camera: Camera) -> np.ndarray:
    """The camera's local-to-world matrix in USD's row-vector convention: rows right, up, −forward, position."""
    right, up, forward = camera.frame()
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3], m[3, :3] = right, up, -forward, camera.position
    return m


def up_axis(camera: Camera) -> str:
    """``Y`` or ``Z`` (the axes USD allows), whichever the camera's ``up`` is nearer."""
    _, up, _ = camera.frame()
    return "Z" if abs(up[2]) > abs(up[1]) else "Y"


def scene_data(scene: Scene) -> dict:
    """The scene's custom data (``customLayerData["cbox"]``): what USD has no schema for."""
    cam = scene.camera
    data = {"scene": scene.name, "content_hash": scene.content_hash(), "quantity": scene.quantity,
            "spp": DEFAULT_SPP, "seed": DEFAULT_SEED, "max_depth": int(scene.max_depth),
            "pixel_filter": scene.pixel_filter, "resolution": Gf.Vec2i(cam.width, cam.height),
            "spectral": scene.spectral is not None}
    if scene.ambient_occlusion is not None:
        ao = scene.ambient_occlusion
        data["ambient_occlusion"] = {"max_distance": float(ao.max_distance), "weighting": ao.weighting,
                                     "normal": ao.normal, "miss_value": float(ao.miss_value)}
    return data


def surface_inputs(material) -> dict[str, tuple[Sdf.ValueTypeName, object]]:
    """The ``UsdPreviewSurface`` inputs of a scene material (:data:`MAPPING` says what each leaves out)."""
    f, c = Sdf.ValueTypeNames.Float, Sdf.ValueTypeNames.Color3f
    if isinstance(material, Diffuse):
        return {"diffuseColor": (c, _vec3f(material.reflectance)), "metallic": (f, 0.0), "ior": (f, 1.0),
                "roughness": (f, 1.0)}
    if isinstance(material, Mirror):
        return {"diffuseColor": (c, _vec3f(material.reflectance)), "metallic": (f, 1.0),
                "roughness": (f, 0.0)}
    if isinstance(material, Dielectric):
        return {"diffuseColor": (c, Gf.Vec3f(1.0, 1.0, 1.0)), "metallic": (f, 0.0), "roughness": (f, 0.0),
                "opacity": (f, 0.0), "ior": (f, float(material.eta))}
    raise ValueError(f"material {material.name!r}: {type(material).__name__} has no USD translation")


def material_data(material) -> dict:
    """A material's exact definition (``customData["cbox"]``), for a consumer that renders it as we do."""
    data = {"name": material.name, "type": material.type,
            "sides": "both" if isinstance(material, Dielectric) else "front"}
    if isinstance(material, Dielectric):
        data.update(int_ior=float(material.int_ior), ext_ior=float(material.ext_ior))
    else:
        data["reflectance"] = _vec3d(material.reflectance)
    return data


def _material(stage: Usd.Stage, path: str, material, emission=None) -> UsdShade.Material:
    mat = UsdShade.Material.Define(stage, path)
    shader = UsdShade.Shader.Define(stage, f"{path}/PreviewSurface")
    shader.CreateIdAttr("UsdPreviewSurface")
    inputs = surface_inputs(material)
    if emission is not None:
        inputs["emissiveColor"] = (Sdf.ValueTypeNames.Color3f, _vec3f(emission))
    for name, (kind, value) in inputs.items():
        shader.CreateInput(name, kind).Set(value)
    mat.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    mat.GetPrim().SetCustomData({"cbox": material_data(material)})
    return mat


def _mesh(stage: Usd.Stage, path: str, mesh: Mesh) -> UsdGeom.Mesh:
    usd = UsdGeom.Mesh.Define(stage, path)
    v = np.ascontiguousarray(mesh.vertices, dtype=np.float32)
    tri = np.ascontiguousarray(mesh.triangles, dtype=np.int32)
    usd.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(v))
    usd.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(tri), 3, dtype=np.int32)))
    usd.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(tri.ravel()))
    usd.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    usd.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    n = np.cross(v[tri[:, 1]] - v[tri[:, 0]], v[tri[:, 2]] - v[tri[:, 0]]).astype(np.float64)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    usd.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(n.astype(np.float32)))
    usd.SetNormalsInterpolation(UsdGeom.Tokens.uniform)
    usd.CreateExtentAttr(Vt.Vec3fArray([_vec3f(v.min(axis=0)), _vec3f(v.max(axis=0))]))
    usd.CreateDoubleSidedAttr(True)
    return usd


def _sphere(stage: Usd.Stage, path: str, sphere: Sphere) -> UsdGeom.Sphere:
    usd = UsdGeom.Sphere.Define(stage, path)
    r = float(sphere.radius)
    usd.CreateRadiusAttr(r)
    usd.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-r, -r, -r), Gf.Vec3f(r, r, r)]))
    usd.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(_vec3d(sphere.center))
    usd.CreateDoubleSidedAttr(True)
    return usd


def _emitter(prim: Usd.Prim, mesh: Mesh) -> None:
    UsdLux.MeshLightAPI.Apply(prim)
    light = UsdLux.LightAPI(prim)
    intensity, exposure, color = light_terms(mesh.radiance)
    light.CreateIntensityAttr(intensity)
    light.CreateExposureAttr(exposure)
    light.CreateColorAttr(_vec3f(color))
    light.CreateNormalizeAttr(False)
    light.CreateEnableColorTemperatureAttr(False)
    light.CreateMaterialSyncModeAttr(UsdLux.Tokens.independent)


def _camera(stage: Usd.Stage, path: str, scene: Scene) -> UsdGeom.Camera:
    cam = scene.camera
    usd = UsdGeom.Camera.Define(stage, path)
    usd.CreateProjectionAttr(UsdGeom.Tokens.perspective)
    usd.CreateFocalLengthAttr(FOCAL_LENGTH)
    h, v = apertures(cam)
    usd.CreateHorizontalApertureAttr(h)
    usd.CreateVerticalApertureAttr(v)
    lo, hi = scene.bounds()
    reach = float(np.linalg.norm(np.asarray(cam.position) - (lo + hi) / 2.0)) + scene.extent()
    usd.CreateClippingRangeAttr(Gf.Vec2f(1e-5 * scene.extent(), 10.0 * reach))
    usd.AddTransformOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Matrix4d(camera_matrix(cam).tolist()))
    usd.GetPrim().SetCustomData({"cbox": {"position": _vec3d(cam.position), "look_at": _vec3d(cam.look_at),
                                          "up": _vec3d(cam.up), "fov_deg": float(cam.fov_deg),
                                          "fov_axis": cam.fov_axis, "resolution": Gf.Vec2i(cam.width, cam.height)}})
    return usd


def build_stage(scene: Scene, stage: Usd.Stage) -> None:
    """Write ``scene`` into the empty ``stage``: /World with Looks, Geometry and Camera."""
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.SetStageUpAxis(stage, up_axis(scene.camera))
    world = UsdGeom.Xform.Define(stage, "/World").GetPrim()
    stage.SetDefaultPrim(world)
    Usd.ColorSpaceAPI.Apply(world).CreateColorSpaceNameAttr(Gf.ColorSpaceNames.LinearRec709)
    layer = stage.GetRootLayer()
    layer.customLayerData = {"cbox": scene_data(scene)}
    UsdGeom.Scope.Define(stage, "/World/Looks")
    UsdGeom.Scope.Define(stage, "/World/Geometry")
    looks = dict(zip(scene.materials, prim_names(list(scene.materials))))
    bound = {name: _material(stage, f"/World/Looks/{looks[name]}", m) for name, m in scene.materials.items()}
    objects = list(scene.meshes) + list(scene.spheres)
    taken = list(looks.values())
    for obj, ident in zip(objects, prim_names([o.name for o in objects])):
        path = f"/World/Geometry/{ident}"
        data = {"name": obj.name, "material": obj.material}
        prim = (_sphere if isinstance(obj, Sphere) else _mesh)(stage, path, obj).GetPrim()
        material = bound[obj.material]
        if isinstance(obj, Mesh) and obj.is_emitter:
            look = prim_names(taken + [f"{looks[obj.material]}_emitting_{ident}"])[-1]
            taken.append(look)
            material = _material(stage, f"/World/Looks/{look}", scene.materials[obj.material], obj.radiance)
            _emitter(prim, obj)
            data.update(radiance=_vec3d(obj.radiance), emits="front")
        UsdShade.MaterialBindingAPI.Apply(prim).Bind(material)
        prim.SetCustomData({"cbox": data})
    _camera(stage, "/World/Camera", scene)


def write(scene: Scene, folder: Path) -> Path:
    """Write ``scene.usda`` into ``folder``; return its path."""
    path = Path(folder) / MAIN_FILE
    stage = Usd.Stage.CreateNew(str(path))
    build_stage(scene, stage)
    stage.GetRootLayer().Save()
    return path
