"""Reading scene files: TOML in, a validated :class:`~cornell_harness.scenes.model.Scene` out.

The format is ``src/cornell_harness/schemas/scene.schema.json`` (every field: type, unit, range, default,
meaning), checked by the strict reader :mod:`cornell_harness.schemas.reader`; what is left here is what the
schema cannot say (names that refer to each other, the features a scene uses, degenerate triangles, the
camera's frame, the image's memory) and building the model. Every error is a
:class:`~cornell_harness.scenes.model.SceneError` that names the file and the field, on one line; no other
exception escapes :func:`load_scene`, whatever the bytes of the file (``tests/scenes/test_fuzz.py`` keeps it so).
Units and conventions are documented in :mod:`cornell_harness.scenes.model`.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from pathlib import Path
from typing import Callable

import numpy as np

from cornell_harness.schemas.reader import FormatProblem, check, key_text, read_text, read_toml, schema
from cornell_harness.scenes.animation import parse_animation
from cornell_harness.scenes.materials import MATERIAL_TYPES, material_fields
from cornell_harness.scenes.model import (DEGENERATE_REL_AREA, IMAGE_BUFFERS, MAX_COORDINATE, MAX_IMAGE_BYTES,
                                          MAX_OBJ_FILE_BYTES, MAX_RADIANCE, MAX_SCENE_FILE_BYTES, Camera, Mesh, Region, Scene,
                                          SceneError, Sphere, extent, image_memory_bytes, object_bounds, one_line)
from cornell_harness.scenes.quantities import DEFAULT_QUANTITY, AmbientOcclusion, parse_ambient_occlusion
from cornell_harness.scenes.spectral_scene import SpectralReader
from cornell_harness.scenes.units import apply_length_scale
from cornell_harness.suggest import closest

#: A field's error: ``err(field, message)`` is the SceneError of the file being read.
Err = Callable[[str, str], SceneError]


def keys_of(table: str) -> tuple[str, ...]:
    """The keys of one of the scene format's tables (``camera``, ``render``, ``colour``, ...), from its schema."""
    return tuple(schema("scene")["$defs"][table]["properties"])


def _error(file: Path | str, field: str, message: str) -> SceneError:
    return SceneError(one_line(str(file), 1000), one_line(field), one_line(message))


def _floats(values) -> tuple[float, ...]:
    return tuple(float(x) for x in values)


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene file; raise :class:`SceneError` on bad input, and nothing else."""
    return parse_scene(*read_scene_document(path))


def read_scene_document(path: str | Path) -> tuple[dict, Path]:
    """The parsed TOML of a scene file (not yet validated) and the file's path (``scene.toml`` for a folder)."""
    path = Path(path)
    try:
        if path.is_dir():
            path = path / "scene.toml"
        return read_toml(path, MAX_SCENE_FILE_BYTES), path
    except FormatProblem as e:
        raise _error(path, e.field, e.message) from None
    except OSError as e:  # a folder that cannot be looked into
        raise _error(path, "(file)", e.strerror or str(e)) from None


def parse_scene(doc: dict, path: Path) -> Scene:
    """Validate a parsed scene document (see :func:`load_scene`)."""
    err: Err = functools.partial(_error, path)
    try:
        check(doc, "scene", label="name")
    except FormatProblem as e:
        raise err(e.field, e.message) from None
    camera = _parse_camera(err, doc["camera"])
    spectral = SpectralReader(err, doc, key_text)  # [colour] and [spectra]: before the values that name a spectrum
    materials = _parse_materials(doc["materials"], spectral)
    meshes = tuple(_parse_mesh(err, m, i, materials, path.parent, spectral) for i, m in enumerate(doc["meshes"]))
    spheres = tuple(_parse_sphere(err, t, i, materials) for i, t in enumerate(doc.get("spheres", [])))
    names = [m.name for m in meshes] + [s.name for s in spheres]
    for n in names:
        if names.count(n) > 1:
            raise err("meshes" if n in [m.name for m in meshes] else "spheres",
                      f"object name {n!r} is used more than once")
    _check_degenerate(err, meshes)
    regions = _parse_regions(err, doc.get("regions", {}), names)
    quantity, ao = _parse_quantity(err, doc, meshes, spheres)
    pixel_filter = doc["render"]["pixel_filter"]
    declared = doc["features"]
    used = _features_used(meshes, spheres, materials, pixel_filter)
    if missing := sorted(used - set(declared)):
        raise err("features", f"the scene uses {', '.join(missing)} but does not declare it")
    if unused := sorted(set(declared) - used):
        raise err("features", f"declares {', '.join(unused)} but does not use it")

    scene = apply_length_scale(err, doc, Scene(
        name=doc["name"],
        path=path,
        features=frozenset(declared),
        camera=camera,
        materials=materials,
        meshes=meshes,
        max_depth=doc["render"]["max_depth"],
        pixel_filter=pixel_filter,
        description=doc.get("description", ""),
        spheres=spheres,
        regions=regions,
        quantity=quantity,
        ambient_occlusion=ao,
        spectral=spectral.finish(),
    ), _check_degenerate)
    if "animation" in doc:
        animation = parse_animation(err, doc["animation"], scene, float(doc.get("length_scale", 1.0)))
        scene = dataclasses.replace(scene, animation=animation)
    return scene


def _parse_quantity(err: Err, doc: dict, meshes, spheres) -> tuple[str, AmbientOcclusion | None]:
    """The scene's quantity and, for ambient occlusion, the definition it pins (:mod:`.quantities`)."""
    quantity = doc.get("quantity", DEFAULT_QUANTITY)
    table = doc.get("ambient_occlusion")
    if quantity != "ambient_occlusion":
        if table is not None:
            raise err("ambient_occlusion", f"only a scene of quantity = \"ambient_occlusion\" has this table; "
                                           f"this one's quantity is {quantity!r}")
        return quantity, None
    if table is None:
        raise err("ambient_occlusion", "missing required table: an ambient-occlusion scene pins max_distance "
                                       "(or max_distance_relative), weighting, normal and miss_value")
    return quantity, parse_ambient_occlusion(err, table, extent(*object_bounds(meshes, spheres)))


def _features_used(meshes: tuple[Mesh, ...], spheres: tuple[Sphere, ...], materials: dict,
                   pixel_filter: str) -> set[str]:
    used = {"triangle_mesh", "pinhole_camera"}
    used |= {materials[o.material].feature for o in meshes + spheres}
    if spheres:
        used.add("sphere")
    if any(m.is_emitter for m in meshes):
        used.add("area_light")
    if pixel_filter == "box":
        used.add("box_filter")
    return used


def _parse_camera(err: Err, t: dict) -> Camera:
    position, look_at, up = _floats(t["position"]), _floats(t["look_at"]), _floats(t["up"])
    width, height = t["resolution"]
    if (need := image_memory_bytes(width, height)) > MAX_IMAGE_BYTES:
        raise err("camera.resolution",
                  f"{_count(width)}x{_count(height)} is too large: its image buffers need an estimated "
                  f"{_bytes(need)} (width x height x 3 channels x float64 x {IMAGE_BUFFERS} buffers), "
                  f"over the {_bytes(MAX_IMAGE_BYTES)} limit")
    forward = np.subtract(look_at, position)
    if np.linalg.norm(forward) == 0.0:
        raise err("camera.look_at", "equals camera.position")
    if np.linalg.norm(np.cross(forward, up)) <= 1e-9 * np.linalg.norm(forward) * np.linalg.norm(up):
        raise err("camera.up", "is zero or parallel to the viewing direction")
    return Camera(position, look_at, up, float(t["fov_deg"]), t["fov_axis"], width, height)


def _parse_materials(t: dict, spectral: SpectralReader) -> dict:
    """Each ``[materials.NAME]`` as its type's class (:mod:`cornell_harness.scenes.materials`)."""
    out = {}
    for name, m in t.items():
        cls = MATERIAL_TYPES[m["type"]]
        values = {}
        for f in material_fields(cls):
            if f.name not in m:
                continue  # optional: the schema requires the others
            value = m[f.name]
            if f.metadata["kind"] == "rgb01" and isinstance(value, dict):  # { spectrum = "NAME" }: its RGB
                value = spectral.reflectance(value, f"materials.{key_text(name)}.{f.name}", name, f.name)
            values[f.name] = _floats(value) if isinstance(value, (list, tuple)) else float(value)
        out[name] = cls(name, **values)
    return out


def _object_where(kind: str, i: int, t: dict) -> str:
    """A mesh's or sphere's field path: ``meshes[2] (floor)``."""
    return f"{kind}[{i}] ({one_line(t['name'], 60)})"


def _check_material(err: Err, t: dict, where: str, materials: dict) -> None:
    if t["material"] not in materials:
        raise err(f"{where}.material", f"unknown material {t['material']!r}; defined: {', '.join(sorted(materials))}")


def _parse_sphere(err: Err, t: dict, i: int, materials: dict) -> Sphere:
    _check_material(err, t, _object_where("spheres", i, t), materials)
    return Sphere(t["name"], _floats(t["center"]), float(t["radius"]), t["material"])


def _parse_regions(err: Err, t: dict, objects: list[str]) -> dict[str, Region]:
    out = {}
    for name, g in t.items():
        w = f"regions.{key_text(name)}"
        raw = g.get("objects", [])
        for i, o in enumerate(raw):
            if o not in objects:
                close = closest(o, objects)
                hint = f"did you mean {close!r}?" if close else f"objects: {', '.join(objects)}"
                raise err(f"{w}.objects[{i}]", f"no object named {one_line(o, 60)!r}; {hint}")
        box = None
        if "box" in g:
            lo, hi = _floats(g["box"]["min"]), _floats(g["box"]["max"])
            if not all(a < z for a, z in zip(lo, hi)):
                raise err(f"{w}.box", f"min must be below max on every axis, got {list(lo)} and {list(hi)}")
            box = (lo, hi)
        if not raw and box is None:
            raise err(w, "a region needs objects, a box, or both")
        out[name] = Region(name, tuple(raw), box, g.get("description", ""))
    return out


def _parse_mesh(err: Err, t: dict, i: int, materials: dict, base: Path, spectral: SpectralReader) -> Mesh:
    w = _object_where("meshes", i, t)
    _check_material(err, t, w, materials)
    if "obj" in t and ("vertices" in t or "faces" in t):
        raise err(w, "give either obj or vertices/faces, not both")
    if "obj" in t:
        vertices, faces = _read_obj(err, base / t["obj"], f"{w}.obj")
    else:
        for key in ("vertices", "faces"):
            if key not in t:
                raise err(f"{w}.{key}", "missing required field (or give obj)")
        vertices, faces = t["vertices"], t["faces"]
    if not faces:
        raise err(f"{w}.faces", "a mesh needs at least one face")
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    tris = []
    for j, f in enumerate(faces):
        for x in f:
            if not 0 <= x < len(v):
                raise err(f"{w}.faces[{j}]", f"vertex index {x} out of range 0..{len(v) - 1}")
        tris.append(f[:3])
        if len(f) == 4:
            tris.append([f[0], f[2], f[3]])
    radiance = None
    if "emitter" in t:
        value = t["emitter"]["radiance"]
        radiance = (spectral.emission(value, f"{w}.emitter.radiance", t["name"], MAX_RADIANCE)
                    if isinstance(value, dict) else _floats(value))  # { spectrum = "NAME" }: its RGB
    return Mesh(t["name"], v, np.asarray(tris, dtype=np.int64), t["material"], radiance)


def _read_obj(err: Err, path: Path, field: str) -> tuple[list, list]:
    """Vertices and polygon faces of a Wavefront OBJ (positions only)."""
    try:
        lines = read_text(path, MAX_OBJ_FILE_BYTES).splitlines()
    except FileNotFoundError:
        raise err(field, f"OBJ file {path} does not exist") from None
    except OSError as e:
        raise err(field, f"cannot read OBJ file {path}: {e.strerror or e}") from None
    except ValueError as e:  # not UTF-8, too large, or a NUL in the path
        raise err(field, f"OBJ file {path}: {e}") from None
    vertices: list = []
    faces: list = []
    for n, line in enumerate(lines, 1):
        parts = line.split()
        if not parts:
            continue
        try:
            if parts[0] == "v":
                xyz = [float(x) for x in parts[1:4]]
                if len(xyz) != 3 or not all(math.isfinite(x) for x in xyz):
                    raise ValueError("needs 3 finite coordinates")
                if any(abs(x) > MAX_COORDINATE for x in xyz):
                    raise ValueError(f"coordinate out of range: |value| must be <= {MAX_COORDINATE:g}, got "
                                     f"{max(xyz, key=abs):g}")
                vertices.append(xyz)
            elif parts[0] == "f":
                idx = [int(p.split("/")[0]) for p in parts[1:]]
                idx = [k - 1 if k > 0 else len(vertices) + k for k in idx]
                if len(idx) < 3:
                    raise ValueError("a face needs at least 3 vertices")
                faces.extend([idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1))
        except ValueError as e:
            raise _error(path, f"line {n}", str(e)) from None
    return vertices, faces


def _bytes(n: int) -> str:
    for unit, size in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20)):
        if n >= size:
            return f"{_count(n // size)} {unit}" if n // size >= 10**15 else f"{n / size:.3g} {unit}"
    return f"{n} bytes"


def _count(n: int) -> str:
    """An integer for a message: as is, or as ``~1e400`` when it is huge (a float would overflow)."""
    return str(n) if n < 10**15 else f"~1e{len(str(n)) - 1}"


def _check_degenerate(err: Err, meshes: tuple[Mesh, ...]) -> None:
    # Coordinates are bounded (MAX_COORDINATE), so nothing here overflows; they are also rescaled
    # to the scene's size first, so a tiny but well-shaped scene's areas do not underflow to zero.
    v = np.concatenate([m.vertices for m in meshes])
    lo, span = v.min(0), v.max(0) - v.min(0)
    scale = float(span.max()) or 1.0
    size2 = float(np.sum((span / scale) ** 2)) or 1.0
    for i, m in enumerate(meshes):
        a, b, c = ((m.vertices[m.triangles[:, k]] - lo) / scale for k in range(3))
        area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
        bad = np.flatnonzero(area <= DEGENERATE_REL_AREA * size2)
        if bad.size:
            raise err(f"meshes[{i}] ({m.name})", f"triangle {int(bad[0])} is degenerate (zero area)")
