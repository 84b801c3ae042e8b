"""glTF 2.0: a scene as ``scene.gltf`` (JSON: nodes, meshes, materials, the camera) and ``scene.bin`` (its binary
buffer: float32 positions and normals, uint32 indices), for real-time engines and WebGPU renderers.

Written with ``pygltflib`` (the ``[gltf]`` extra); the JSON is readable, so the materials and the camera can
be checked by eye, and the buffer is a plain file beside it (a ``.glb`` packs the two into one; any glTF tool
converts between them). The file follows the glTF 2.0 specification and its Khronos material extensions:
``KHR_materials_emissive_strength`` (radiance above 1), ``KHR_materials_transmission``, ``KHR_materials_ior``
and ``KHR_materials_volume`` (glass), ``KHR_materials_specular`` (a Lambertian surface without glTF's
dielectric specular layer). A renderer that ignores one of them renders another scene, so each is also listed
in ``extensionsRequired``.

How each aspect of a scene is written, and what glTF cannot say (a black back face, a mirror without Fresnel,
a path depth, spectra), is :data:`MAPPING`. What glTF has no place for (spp, seed, ``max_depth``, the pixel
filter, the resolution, the scene's name and hash, each material's own fields) is in ``extras``. An emitter
whose material is a dielectric is refused (:func:`refusal`): glTF's emission follows the surface's sides,
and glass is two-sided.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from cornell_harness.scenes.export.luxcore import SPHERE_SEGMENTS, sphere_mesh
from cornell_harness.scenes.materials import Dielectric, Diffuse, Mirror, material_fields
from cornell_harness.scenes.model import Scene, SceneError, one_line

NAME = "gltf"
FEATURES = frozenset({"triangle_mesh", "sphere", "diffuse", "mirror", "dielectric", "area_light",
                      "pinhole_camera", "box_filter"})

#: The samples per pixel and seed the file's extras give (glTF has no render settings).
DEFAULT_SPP = 64
DEFAULT_SEED = 0
#: The camera's ``znear`` as a fraction of the scene's size (bounding-box diagonal): glTF requires one; path
#: tracers ignore it, rasterisers clip nearer geometry. ``zfar`` is left out: an infinite projection.
ZNEAR_FRACTION = 1e-4
#: The extensions a file may use; those its materials use are listed as used and as required (module docstring).
EXTENSIONS = ("KHR_materials_emissive_strength", "KHR_materials_ior", "KHR_materials_specular",
              "KHR_materials_transmission", "KHR_materials_volume")
#: glTF's component types and buffer-view targets (specification, "Accessor Data Types", "bufferView.target").
FLOAT, UNSIGNED_INT = 5126, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963


def schlick(f0: float, cos_theta: float) -> float:
    """glTF's Fresnel term (specification, Appendix B): f0 + (1 − f0)(1 − cos θ)⁵, for metals and dielectrics."""
    return f0 + (1.0 - f0) * (1.0 - cos_theta) ** 5


def fresnel(eta: float, cos_theta: float) -> float:
    """The exact unpolarised Fresnel reflectance of a smooth dielectric of relative index ``eta``, seen from
    outside at incidence cos θ: ours (:class:`~cornell_harness.scenes.materials.Dielectric`)."""
    cos_t = math.sqrt(1.0 - (1.0 - cos_theta**2) / eta**2)
    r_parl = (eta * cos_theta - cos_t) / (eta * cos_theta + cos_t)
    r_perp = (cos_theta - eta * cos_t) / (cos_theta + eta * cos_t)
    return (r_parl**2 + r_perp**2) / 2.0


def _at(f, angles=(45, 75, 85)) -> str:
    return ", ".join(f"{f(math.cos(math.radians(a))):.3f} at {a}°" for a in angles)


MAPPING = (
    ("units", "scene units", "the same numbers (glTF reads them as metres; a radiance image does not depend on "
                             "the unit), `extras.units` says so"),
    ("files", "scene, meshes", "`scene.gltf` (JSON) and `scene.bin` (its one buffer: float32 positions and "
                               "normals, uint32 indices), not a `.glb`: the JSON can be read and diffed"),
    ("camera", "pinhole at `position` looking at `look_at`, `up`",
     "a node with `translation` = position and `rotation` (a quaternion) whose local +X is our right, +Y our "
     "up and −Z our forward (glTF cameras look down −Z), holding a `perspective` camera"),
    ("fov axis", "`fov_deg` along `fov_axis` (x, y, smaller, larger)",
     "`yfov` (radians) = 2·atan(tan(half-angle) along y), `aspectRatio` = width / height; `znear` "
     f"{ZNEAR_FRACTION:g} × the scene's size, no `zfar` (infinite)"),
    ("handedness", "right = forward × up; pixel (0, 0) top-left",
     "the same: glTF is right-handed, and (−Z) × (+Y) = +X; positions are written unchanged (glTF's +Y up is "
     "a convention for viewers, not for the camera, which its node carries)"),
    ("geometry", "triangles, quads split (a, b, c), (a, c, d)",
     "a mesh per our mesh, one `TRIANGLES` primitive (float32 `POSITION` with min/max, uint32 indices), no "
     "`NORMAL`: glTF then shades flat, as ours; counter-clockwise triangles are front faces in both"),
    ("sphere", "analytic sphere", f"glTF has no sphere: a UV sphere of {SPHERE_SEGMENTS} × {SPHERE_SEGMENTS // 2} "
                                  "quads (luxcore's), with the analytic normals as `NORMAL`"),
    ("diffuse", "Lambertian ρ/π, reflectance ρ",
     "`pbrMetallicRoughness` `baseColorFactor` [ρ, 1], `metallicFactor` 0, `roughnessFactor` 1, and "
     "`KHR_materials_specular` `specularFactor` 0, which removes glTF's dielectric specular layer (without "
     "it, a GGX lobe of Fresnel f0 0.04 at ior 1.5 sits on top and the diffuse is weighted by 1 − F)"),
    ("emitted radiance", "`radiance` Le, linear sRGB, per channel",
     "`emissiveFactor` Le / max(Le) (each channel at most 1, as glTF requires) × "
     "`KHR_materials_emissive_strength` `emissiveStrength` max(Le): glTF adds emissive × strength to the "
     "outgoing radiance, the same linear sRGB (no π: it is radiance, not exitance)"),
    ("emitter side", "front side only (counter-clockwise winding); the back is black and opaque",
     "`doubleSided` false: glTF culls the back face, so the front emits and nothing is seen from behind, but "
     "the back is not there at all rather than black (a renderer that culls it for every ray lets light "
     "through it); an emitter on a dielectric (a two-sided volume boundary) is refused"),
    ("two-sidedness", "diffuse and mirror reflect on the front side only; dielectric both sides",
     "`doubleSided` false (the back face culled, not black: the image differs only where light paths meet a "
     "back face, in the Cornell box the gap between the light's back and the ceiling); a dielectric's surface "
     "is a `KHR_materials_volume` boundary, two-sided whatever `doubleSided` says (that extension's rule), "
     "and `doubleSided` false, as the Khronos validator asks of a volume"),
    ("mirror", "constant specular reflectance R, any angle",
     "`metallicFactor` 1, `roughnessFactor` 0, `baseColorFactor` [R, 1]: glTF's metal is Schlick's Fresnel "
     "with f0 = R, R at normal incidence only: for R = 0.95, "
     f"{_at(lambda c: schlick(0.95, c))}, 1 at grazing. glTF has no constant-reflectance mirror; "
     "`extras.type` mirror says which one is meant"),
    ("glass", "smooth dielectric, exact Fresnel, refraction, total internal reflection",
     "`KHR_materials_transmission` `transmissionFactor` 1, `baseColorFactor` white, `metallicFactor` 0, "
     "`roughnessFactor` 0; `KHR_materials_volume` (a solid, not a thin wall: `thicknessFactor` the object's "
     "smallest bounding-box side, 0 (a thin wall) for a flat one; no attenuation). glTF's Fresnel is Schlick's: "
     "at ior 1.5 "
     f"{_at(lambda c: schlick(0.04, c))} against the exact {_at(lambda c: fresnel(1.5, c))}"),
    ("IOR", "`int_ior` inside, `ext_ior` outside, absolute",
     "`KHR_materials_ior` `ior` int_ior / ext_ior (glTF takes the outside as ior 1; Fresnel and Snell depend on "
     "the ratio only); both values in `extras`"),
    ("colour", "linear-sRGB RGB; a spectral scene's spectra", "linear sRGB factors (glTF's own colour space); "
                                                              "spectra cannot be written: their RGB projection "
                                                              "is, and `extras.spectral` says so"),
    ("filter", "box: each pixel the mean over its own square", "no place in glTF: `extras.pixel_filter` box"),
    ("depth", "`max_depth` path segments, -1 unbounded", "no place in glTF: `extras.max_depth` (our count, -1 "
                                                         "unbounded; `extras.max_depth_counts` says how)"),
    ("samples", "spp, seed", f"no place in glTF: `extras.spp` {DEFAULT_SPP}, `extras.seed` {DEFAULT_SEED}"),
    ("resolution", "`camera.resolution`", "no place in glTF (only the aspect ratio): the camera's "
                                          "`extras.resolution` [width, height]"),
)


def refusal(scene: Scene) -> SceneError | None:
    """An emitter whose material is a dielectric: glTF's emission is on the sides its surface has, and glass (a
    ``KHR_materials_volume`` boundary) has both; ours emits from the front only."""
    for i, m in enumerate(scene.meshes):
        if m.is_emitter and isinstance(scene.materials[m.material], Dielectric):
            return SceneError(scene.path, f"meshes[{i}] ({one_line(m.name, 60)}).emitter",
                              f"cannot be exported to {NAME}: dielectric {m.material!r} is a two-sided volume "
                              "boundary in glTF, so its emission would be on both sides; ours is on the front only")
    return None


def emission(radiance) -> tuple[list[float], float]:
    """(``emissiveFactor``, ``emissiveStrength``) whose product is ``radiance``: the factor's largest channel 1
    (glTF bounds each by 1), the strength the largest radiance (1 for black)."""
    strength = max(float(x) for x in radiance) or 1.0
    return [float(x) / strength for x in radiance], strength


def camera_rotation(scene: Scene) -> np.ndarray:
    """The camera node's rotation (3 × 3, columns its local axes in the world): +X right, +Y up, +Z backward."""
    right, up, forward = scene.camera.frame()
    return np.stack([right, up, -forward], axis=1)


def quaternion(r: np.ndarray) -> list[float]:
    """The unit quaternion [x, y, z, w] (glTF's order) of the rotation matrix ``r``, w >= 0.

    Shepperd's method: the largest of 4w², 4x², 4y², 4z² (from the diagonal) is taken by its square root and
    the others from the off-diagonal sums and differences, so that no component is found by a square root
    alone (its sign would be lost, as in a half turn about a diagonal axis).
    """
    t = np.array([1 + r[0, 0] + r[1, 1] + r[2, 2], 1 + r[0, 0] - r[1, 1] - r[2, 2],
                  1 - r[0, 0] + r[1, 1] - r[2, 2], 1 - r[0, 0] - r[1, 1] + r[2, 2]])  # 4w², 4x², 4y², 4z²
    k = int(np.argmax(t))
    s = 2.0 * math.sqrt(t[k])  # 4 × that component
    sums = {(0, 1): r[2, 1] - r[1, 2], (0, 2): r[0, 2] - r[2, 0], (0, 3): r[1, 0] - r[0, 1],
            (1, 2): r[0, 1] + r[1, 0], (1, 3): r[0, 2] + r[2, 0], (2, 3): r[1, 2] + r[2, 1]}  # 4·(w, x, y, z) pairs
    wxyz = np.array([s / 4.0 if j == k else sums[min(j, k), max(j, k)] / s for j in range(4)])
    wxyz *= 1.0 if wxyz[0] >= 0 else -1.0
    return (np.r_[wxyz[1:], wxyz[0]] / np.linalg.norm(wxyz)).tolist()


def perspective(scene: Scene) -> dict:
    """glTF's ``camera.perspective``: the vertical field of view, the aspect ratio, the near plane."""
    cam = scene.camera
    _, ty = cam.tan_half_fov()
    return {"yfov": 2.0 * math.atan(ty), "aspectRatio": cam.width / cam.height,
            "znear": ZNEAR_FRACTION * scene.extent()}


def _our_fields(name: str, material) -> dict:
    """The material as our scene file gives it, for ``extras``: its name, type and every field."""
    fields = {f.name: getattr(material, f.name) for f in material_fields(type(material))}
    return {"material": name, "type": material.type} | {k: list(v) if isinstance(v, tuple) else v
                                                         for k, v in fields.items()}


def material_dict(name: str, material, radiance=None, thickness: float = 0.0) -> dict:
    """The glTF material (JSON) of our material ``name``, emitting ``radiance`` if given (then named after both);
    ``thickness`` is a dielectric's ``KHR_materials_volume`` thickness."""
    ext: dict = {}
    if isinstance(material, Diffuse):
        pbr = {"baseColorFactor": [*map(float, material.reflectance), 1.0], "metallicFactor": 0.0,
               "roughnessFactor": 1.0}
        ext["KHR_materials_specular"] = {"specularFactor": 0.0}
    elif isinstance(material, Mirror):
        pbr = {"baseColorFactor": [*map(float, material.reflectance), 1.0], "metallicFactor": 1.0,
               "roughnessFactor": 0.0}
    elif isinstance(material, Dielectric):
        pbr = {"baseColorFactor": [1.0, 1.0, 1.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.0}
        ext["KHR_materials_transmission"] = {"transmissionFactor": 1.0}
        ext["KHR_materials_ior"] = {"ior": float(material.eta)}
        ext["KHR_materials_volume"] = {"thicknessFactor": float(thickness)}
    else:
        raise ValueError(f"material {name!r}: {type(material).__name__} has no glTF translation")
    label = name if radiance is None else f"{name} emitting {', '.join(f'{x:g}' for x in radiance)}"
    d = {"name": label, "pbrMetallicRoughness": pbr, "doubleSided": False,
         "extras": _our_fields(name, material)}
    if radiance is not None:
        d["emissiveFactor"], strength = emission(radiance)
        ext["KHR_materials_emissive_strength"] = {"emissiveStrength": strength}
        d["extras"]["radiance"] = [float(x) for x in radiance]
    return d | {"extensions": ext}


def scene_extras(scene: Scene) -> dict:
    """What glTF has no place for, on the glTF scene: render settings, the scene's name and hash, units, spectra."""
    sp = scene.spectral
    extras = {
        "generator": "cornell-harness", "scene": scene.name, "content_hash": scene.content_hash(),
        "description": scene.description, "spp": DEFAULT_SPP, "seed": DEFAULT_SEED, "max_depth": scene.max_depth,
        "max_depth_counts": "path segments from the camera: 1 emitters seen directly, 2 direct light; -1 unbounded",
        "pixel_filter": scene.pixel_filter, "resolution": [scene.camera.width, scene.camera.height],
        "units": "scene units, written unchanged; radiance in linear sRGB (BT.709, D65) per channel",
    }
    if sp is not None:
        extras["spectral"] = f"the scene has spectra; glTF holds their RGB projection ({sp.rgb_convention} convention)"
    return extras


class _Buffer:
    """The one binary buffer: its bytes, its buffer views and accessors, appended to as meshes are written."""

    def __init__(self):
        self.chunks: list[bytes] = []
        self.size = 0
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def add(self, array: np.ndarray, component: int, kind: str, target: int, bounds: bool = False) -> int:
        data = np.ascontiguousarray(array, dtype="<f4" if component == FLOAT else "<u4")
        self.views.append({"buffer": 0, "byteOffset": self.size, "byteLength": data.nbytes, "target": target})
        acc = {"bufferView": len(self.views) - 1, "componentType": component, "count": int(data.size // (3 if
               kind == "VEC3" else 1)), "type": kind}
        if bounds:  # POSITION needs min and max, of the float32 values written
            acc["min"], acc["max"] = data.min(axis=0).tolist(), data.max(axis=0).tolist()
        self.accessors.append(acc)
        self.chunks.append(data.tobytes())
        self.size += data.nbytes  # float32 and uint32: every view stays 4-byte aligned
        return len(self.accessors) - 1

    def primitive(self, vertices, triangles, material: int, normals=None) -> dict:
        attributes = {"POSITION": self.add(vertices, FLOAT, "VEC3", ARRAY_BUFFER, bounds=True)}
        if normals is not None:
            attributes["NORMAL"] = self.add(normals, FLOAT, "VEC3", ARRAY_BUFFER)
        indices = self.add(np.ravel(triangles), UNSIGNED_INT, "SCALAR", ELEMENT_ARRAY_BUFFER)
        return {"attributes": attributes, "indices": indices, "material": material, "mode": 4}


def _smallest_side(vertices: np.ndarray) -> float:
    sides = vertices.max(axis=0) - vertices.min(axis=0)
    return float(sides[sides > 0].min()) if (sides > 0).any() else 0.0


def gltf_dict(scene: Scene) -> tuple[dict, bytes]:
    """The glTF JSON (as a dict) and its binary buffer's bytes."""
    buf, materials, index = _Buffer(), [], {}
    thickness: dict[str, float] = {}
    for obj, size in [(m, _smallest_side(m.vertices)) for m in scene.meshes] + [(s, 2.0 * s.radius)
                                                                               for s in scene.spheres]:
        thickness[obj.material] = min(thickness.get(obj.material, math.inf), size)

    def material(name: str, radiance=None) -> int:
        key = (name, None if radiance is None else tuple(radiance))
        if key not in index:
            index[key] = len(materials)
            materials.append(material_dict(name, scene.materials[name], radiance, thickness[name]))
        return index[key]

    meshes = [{"name": m.name, "primitives": [buf.primitive(m.vertices, m.triangles, material(m.material, m.radiance))]}
              for m in scene.meshes]
    for s in scene.spheres:
        vertices, triangles, normals = sphere_mesh(s)
        meshes.append({"name": s.name, "primitives": [buf.primitive(vertices, triangles, material(s.material),
                                                                    normals)],
                       "extras": {"sphere": {"center": list(s.center), "radius": s.radius}}})
    cam = scene.camera
    nodes = [{"name": mesh["name"], "mesh": i} for i, mesh in enumerate(meshes)]
    nodes.append({"name": "camera", "camera": 0, "translation": [float(x) for x in cam.position],
                  "rotation": quaternion(camera_rotation(scene))})
    blob = b"".join(buf.chunks)
    used = sorted({name for m in materials for name in m["extensions"]})
    d = {
        "asset": {"version": "2.0", "generator": "cornell-harness"},
        "extensionsUsed": used, "extensionsRequired": used,
        "scene": 0, "scenes": [{"name": scene.name, "nodes": list(range(len(nodes))), "extras": scene_extras(scene)}],
        "nodes": nodes, "meshes": meshes, "materials": materials,
        "cameras": [{"name": "camera", "type": "perspective", "perspective": perspective(scene),
                     "extras": {"resolution": [cam.width, cam.height], "fov_deg": cam.fov_deg,
                                "fov_axis": cam.fov_axis}}],
        "accessors": buf.accessors, "bufferViews": buf.views,
        "buffers": [{"uri": "scene.bin", "byteLength": len(blob)}],
    }
    return d, blob


def write(scene: Scene, folder: Path) -> Path:
    """Write ``scene.gltf`` and ``scene.bin`` into ``folder``; return the ``.gltf``'s path. The JSON goes through
    pygltflib's own model, so what is written is what a pygltflib reader gets."""
    import pygltflib  # its extra was checked by export_scene (cornell_harness.extras.EXPORT_FORMATS)

    d, blob = gltf_dict(scene)
    folder = Path(folder)
    (folder / "scene.bin").write_bytes(blob)
    path = folder / "scene.gltf"
    path.write_text(pygltflib.GLTF2.from_dict(d).to_json(indent=1) + "\n", encoding="utf-8")
    return path
