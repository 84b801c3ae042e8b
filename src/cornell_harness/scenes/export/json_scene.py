"""Neutral JSON: the scene as one documented JSON file (``scene.json``), for a renderer in any language.

Every other format is some renderer's own; this one is ours, written so that a program with a few dozen
lines of parsing (``examples/c-renderer/``'s C tokenizer) has the whole scene: the camera with its
orthonormal basis and vertical field of view, the materials, the meshes as inline arrays (vertices and
triangles; no mesh files to read), the analytic spheres, ``max_depth``, the quantity with its parameters
(ambient occlusion's distance, weighting, normal and miss value), for a spectral scene the sampled
spectra and which values use them, and for an animated scene its frames, frame rate, keyed tracks and light
switches. Its JSON Schema ships in the package,
``src/cornell_harness/schemas/json-scene.schema.json`` (draft 2020-12); every field's meaning and unit is
in it, and :data:`MAPPING` says how each aspect of our scene model is written.

Numbers are Python's shortest round-trip text of the scene's float64 values, so a reader that parses
them as doubles has the scene's values exactly; an unbounded AO distance (``inf``, which JSON has no
word for) is ``null``. ``tests/scenes/test_export_json.py`` validates every stored scene's export
against the schema and reads it back into a :class:`~cornell_harness.scenes.model.Scene` with the same
content.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from cornell_harness.scenes.materials import material_fields
from cornell_harness.scenes.model import Scene

NAME = "json"
# Named, not taken from the model's lists: a feature or quantity added there is written here (and to the
# schema) before the format claims it.
FEATURES = frozenset({"triangle_mesh", "sphere", "diffuse", "mirror", "dielectric", "area_light",
                      "pinhole_camera", "box_filter"})
QUANTITIES = ("radiance", "ambient_occlusion")
#: An animated scene is written whole: its still content and ``animation`` (:mod:`cornell_harness.scenes.animation`).
ANIMATION = True
#: The document's ``format`` and ``version``: a reader checks both before reading on.
FORMAT, VERSION = "cornell-harness-scene", 1
#: The schema's name (:func:`cornell_harness.schemas.reader.schema_file` finds ``<name>.schema.json``).
SCHEMA = "json-scene"

MAPPING = (
    ("units", "scene units; angles in degrees", "the same numbers (float64, shortest round-trip text)"),
    ("camera", "pinhole at `position` looking at `look_at`, `up`", "`camera.position`, `look_at`, `up` as "
                                                                   "given, and `camera.basis`: orthonormal "
                                                                   "`right` = forward × up, `up`, `forward`"),
    ("fov axis", "`fov_deg` along `fov_axis` (x, y, smaller, larger)", "`camera.vertical_fov_deg`, the full "
                                                                       "angle across the image's height; the "
                                                                       "horizontal half-angle's tangent is "
                                                                       "the vertical one's × width / height"),
    ("handedness", "right = forward × up; pixel (0, 0) top-left", "the same: image point (col, row), (0, 0) "
                                                                  "the top-left corner, looks along forward "
                                                                  "+ (2·col/width − 1)·tx·right + "
                                                                  "(1 − 2·row/height)·ty·up"),
    ("geometry", "triangles, quads split (a, b, c), (a, c, d); spheres", "`meshes[].vertices` (V × 3) and "
                                                                         "`triangles` (T × 3, 0-based into the "
                                                                         "mesh's own vertices), inline; "
                                                                         "`spheres[]` `center`, `radius`"),
    ("emitter side", "front side only (counter-clockwise winding)", "`meshes[].emitter.radiance`; the front "
                                                                    "is the side of (v1 − v0) × (v2 − v0)"),
    ("two-sidedness", "diffuse and mirror reflect on the front side only; dielectric both sides", "the same, "
                                                                                                  "stated in "
                                                                                                  "the schema"),
    ("materials", "`diffuse`, `mirror` (`reflectance`), `dielectric` (`int_ior`, `ext_ior`)", "`materials`, by "
                                                                                              "name: `type` and "
                                                                                              "the same fields"),
    ("colour", "linear-sRGB RGB values; a spectral scene's sampled spectra", "the RGB values always; a spectral "
                                                                             "scene also has `colour`, `spectra` "
                                                                             "and each value's spectrum "
                                                                             "(`materials.NAME.spectra`, "
                                                                             "`emitter.radiance_spectrum`)"),
    ("filter", "box: each pixel the mean over its own square", "`camera.pixel_filter` `\"box\"`"),
    ("depth", "`max_depth` path segments, -1 unbounded", "`max_depth`, the same number"),
    ("quantity", "`radiance` or `ambient_occlusion`", "`quantity`; for ambient occlusion `ambient_occlusion`: "
                                                      "`max_distance` (scene units, `null` for unbounded), "
                                                      "`weighting` (`cosine` or `uniform`), `normal`, "
                                                      "`miss_value`"),
    ("animation", "`[animation]`: frames, fps, keyed tracks, light switches", "`animation`: `frames`, `fps`, "
                                                                                "`camera` keys (or `null`), "
                                                                                "`objects` keys by name, "
                                                                                "`switches`; absent for a still "
                                                                                "scene"),
    ("samples", "spp, seed", "not in the file: a renderers file passes them on the command line (`{spp}`, "
                             "`{seed}`)"),
    ("image", "float linear image, pixel (0, 0) top-left", "what the renderer writes at `{out}`: OpenEXR, PFM "
                                                           "(rows bottom to top, as its specification says) or "
                                                           "any float image OpenImageIO reads"),
)


def document(scene: Scene) -> dict:
    """The scene as the JSON document the schema describes (plain dicts, lists, numbers and strings)."""
    cam = scene.camera
    right, up, forward = scene.camera.frame()
    doc = {
        "format": FORMAT, "version": VERSION, "name": scene.name, "content_hash": scene.content_hash(),
        "quantity": scene.quantity, "features": sorted(scene.features),
        "camera": {"type": "pinhole", "position": _vec(cam.position), "look_at": _vec(cam.look_at),
                   "up": _vec(cam.up), "basis": {"right": _vec(right), "up": _vec(up), "forward": _vec(forward)},
                   "vertical_fov_deg": math.degrees(2.0 * math.atan(cam.tan_half_fov()[1])),
                   "width": cam.width, "height": cam.height, "pixel_filter": scene.pixel_filter},
        "max_depth": scene.max_depth,
        "ambient_occlusion": _ambient_occlusion(scene),
        "materials": {name: _material(scene, m) for name, m in scene.materials.items()},
        "meshes": [_mesh(scene, m) for m in scene.meshes],
        "spheres": [{"name": s.name, "center": _vec(s.center), "radius": float(s.radius), "material": s.material}
                    for s in scene.spheres],
    }
    if (sp := scene.spectral) is not None:
        doc["colour"] = {"observer": sp.observer, "output": sp.output, "rgb_convention": sp.rgb_convention,
                         "light": sp.light}
        doc["spectra"] = {name: {"wavelengths_nm": list(s.wavelengths_nm), "values": list(s.values),
                                 "extrapolation": s.extrapolation} for name, s in sp.spectra.items()}
    if (anim := scene.animation) is not None:
        doc["animation"] = _animation(anim)
    return doc


def _animation(anim) -> dict:
    """An animation's tracks as keys: the camera's position and look_at, objects' translations, the switches."""
    camera = None if anim.camera_track is None else [
        {"frame": f, "position": _vec(v[:3]), "look_at": _vec(v[3:])}
        for f, v in zip(anim.camera_track.frames, anim.camera_track.values)]
    objects = {name: [{"frame": f, "translate": _vec(v)} for f, v in zip(t.frames, t.values)]
               for name, t in anim.objects.items()}
    switches = [{"object": s.object, "frame": s.frame, "on": s.on} for s in anim.switches]
    return {"frames": anim.frames, "fps": anim.fps, "camera": camera, "objects": objects, "switches": switches}


def _vec(values) -> list[float]:
    return [float(x) for x in values]


def _ambient_occlusion(scene: Scene) -> dict | None:
    ao = scene.ambient_occlusion
    if ao is None:
        return None
    d = ao.max_distance
    return {"max_distance": d if math.isfinite(d) else None, "weighting": ao.weighting, "normal": ao.normal,
            "miss_value": ao.miss_value}


def _material(scene: Scene, material) -> dict:
    out = {"type": material.type}
    for f in material_fields(type(material)):
        value = getattr(material, f.name)
        out[f.name] = _vec(value) if isinstance(value, tuple) else float(value)
    if scene.spectral is not None and (bound := scene.spectral.materials.get(material.name)):
        out["spectra"] = dict(bound)
    return out


def _mesh(scene: Scene, mesh) -> dict:
    emitter = None
    if mesh.is_emitter:
        emitter = {"radiance": _vec(mesh.radiance)}
        if scene.spectral is not None and mesh.name in scene.spectral.emitters:
            emitter["radiance_spectrum"] = scene.spectral.emitters[mesh.name]
    return {"name": mesh.name, "material": mesh.material, "emitter": emitter,
            "vertices": [_vec(v) for v in mesh.vertices], "triangles": [[int(i) for i in t] for t in mesh.triangles]}


def dumps(value, indent: str = "") -> str:
    """JSON text with each flat array (a vertex, a triangle, a colour, the features) on one line, the rest indented."""
    inner = indent + "  "
    if isinstance(value, dict) and value:
        items = [f"{inner}{json.dumps(k)}: {dumps(v, inner)}" for k, v in value.items()]
        return "{\n" + ",\n".join(items) + "\n" + indent + "}"
    if isinstance(value, list) and value and any(isinstance(v, (dict, list)) for v in value):
        return "[\n" + ",\n".join(inner + dumps(v, inner) for v in value) + "\n" + indent + "]"
    return json.dumps(value, allow_nan=False)


def write(scene: Scene, folder: Path) -> Path:
    """Write ``scene.json`` into ``folder``; return its path."""
    path = Path(folder) / "scene.json"
    path.write_text(dumps(document(scene)) + "\n", encoding="utf-8")
    return path

