"""Reading scene files: TOML in, a validated :class:`~cornell_harness.scenes.model.Scene` out.

Every error is a :class:`~cornell_harness.scenes.model.SceneError` that names the file
and the field, on one line; no other exception escapes :func:`load_scene`,
whatever the bytes of the file (``tests/scenes/test_fuzz.py`` keeps it so). The
format itself (fields, units, conventions, limits) is documented in
:mod:`cornell_harness.scenes.model`.
"""

from __future__ import annotations

import dataclasses
import math
import re
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from cornell_harness.scenes.materials import MATERIAL_TYPES, MAX_IOR, material_fields
from cornell_harness.scenes.model import (DEGENERATE_REL_AREA, FEATURES, FOV_AXES, IMAGE_BUFFERS, MAX_COORDINATE,
                                  MAX_DEPTH, MAX_IMAGE_BYTES, MAX_OBJ_FILE_BYTES, MAX_RADIANCE, MAX_SCENE_FILE_BYTES,
                                  PIXEL_FILTERS, Camera, Mesh, Region, Scene, SceneError, Sphere, extent,
                                  image_memory_bytes, object_bounds, one_line)
from cornell_harness.scenes.quantities import DEFAULT_QUANTITY, QUANTITIES, AmbientOcclusion, parse_ambient_occlusion
from cornell_harness.scenes.spectral_scene import SpectralReader
from cornell_harness.scenes.units import apply_length_scale
from cornell_harness.suggest import closest

#: The keys each table of a scene file may have; any other is an error (with a did-you-mean).
#: A material's keys are its type's fields (cornell_harness.scenes.materials).
SCENE_KEYS = {
    "": ("format", "name", "description", "quantity", "features", "camera", "render", "materials", "meshes",
         "spheres", "regions", "ambient_occlusion", "colour", "spectra",
         "length_scale"),
    "camera": ("type", "position", "look_at", "up", "fov_deg", "fov_axis", "resolution"),
    "render": ("max_depth", "pixel_filter"),
    "mesh": ("name", "material", "obj", "vertices", "faces", "emitter"),
    "sphere": ("name", "material", "center", "radius"),
    "emitter": ("radiance",),
    "region": ("objects", "box", "description"),
    "box": ("min", "max"),
}
#: Every key some material type has: what an untyped material table is checked against.
_ANY_MATERIAL_KEY = ("type",) + tuple(sorted({f.name for cls in MATERIAL_TYPES.values() for f in material_fields(cls)}))
_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def _key(key: str) -> str:
    """A table key as it is written in a field path: bare if it can be, else TOML-quoted."""
    key = key if len(key) <= 60 else key[:59] + "…"
    return key if _BARE_KEY.fullmatch(key) else '"' + key.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _error(file: Path | str, field: str, message: str) -> SceneError:
    return SceneError(one_line(str(file), 1000), one_line(field), one_line(message))


class _Reader:
    """Typed access to a parsed TOML table that raises SceneError with the path."""

    def __init__(self, file: Path):
        self.file = file

    def err(self, field: str, message: str) -> SceneError:
        return _error(self.file, field, message)

    def known(self, table: dict, where: str, keys: tuple[str, ...]) -> None:
        """Refuse a key of ``table`` that is not in ``keys``, suggesting the closest known one."""
        for key in table:
            if key in keys:
                continue
            field = f"{where}.{_key(key)}" if where else _key(key)
            close = closest(key, keys)
            hint = f"did you mean {close!r}?" if close else f"known: {', '.join(keys)}"
            raise self.err(field, f"unknown key ({hint})")

    def get(self, table: dict, key: str, where: str, kind: type | tuple, default: Any = ...) -> Any:
        field = f"{where}.{key}" if where else key
        if key not in table:
            if default is ...:
                raise self.err(field, "missing required field")
            return default
        value = table[key]
        kinds = kind if isinstance(kind, tuple) else (kind,)
        # bool is an int in Python; never accept it as a number.
        if isinstance(value, bool) and bool not in kinds:
            raise self.err(field, f"expected {_kind_name(kind)}, got a boolean")
        if float in kinds and isinstance(value, int) and not isinstance(value, bool):
            value = self.to_float(value, field)
        if not isinstance(value, kinds):
            raise self.err(field, f"expected {_kind_name(kind)}, got {type(value).__name__}")
        if isinstance(value, float) and not math.isfinite(value):
            raise self.err(field, f"must be finite, got {value}")
        return value

    def to_float(self, x: int | float, field: str) -> float:
        try:
            return float(x)
        except OverflowError:  # an integer beyond float64 (TOML integers are unbounded here)
            raise self.err(field, f"out of range: an integer of {len(str(abs(x)))} digits") from None

    def vec(self, table: dict, key: str, where: str, n: int = 3, default: Any = ...,
            bound: float | None = None) -> tuple[float, ...]:
        field = f"{where}.{key}" if where else key
        raw = self.get(table, key, where, list, default)
        if raw is default and default is not ...:
            return default
        return self.numbers(raw, field, n, bound)

    def numbers(self, raw: Any, field: str, n: int, bound: float | None = None) -> tuple[float, ...]:
        """``n`` finite numbers; with ``bound``, each of magnitude at most ``bound``."""
        if not isinstance(raw, list) or len(raw) != n:
            raise self.err(field, f"expected a list of {n} numbers")
        out = []
        for i, x in enumerate(raw):
            if isinstance(x, bool) or not isinstance(x, (int, float)):
                raise self.err(f"{field}[{i}]", f"expected a number, got {type(x).__name__}")
            x = self.to_float(x, f"{field}[{i}]")
            if not math.isfinite(x):
                raise self.err(f"{field}[{i}]", f"must be finite, got {x}")
            if bound is not None and abs(x) > bound:
                raise self.err(f"{field}[{i}]", f"out of range: |value| must be <= {bound:g}, got {x:g}")
            out.append(x)
        return tuple(out)


def _kind_name(kind: type | tuple) -> str:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    names = {int: "an integer", float: "a number", str: "a string", list: "a list", dict: "a table", bool: "a boolean"}
    return " or ".join(names.get(k, k.__name__) for k in kinds)


def _read_text(path: Path, limit: int) -> str:
    """The UTF-8 text of ``path``, at most ``limit`` bytes; OSError, or ValueError saying what is wrong."""
    with open(path, "rb") as f:
        data = f.read(limit + 1)
    if len(data) > limit:
        raise ValueError(f"larger than the {limit / 2**20:g} MiB limit")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ValueError(f"not UTF-8 text: byte 0x{data[e.start]:02x} at offset {e.start}") from None


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene file; raise :class:`SceneError` on bad input, and nothing else."""
    return parse_scene(*read_scene_document(path))


def read_scene_document(path: str | Path) -> tuple[dict, Path]:
    """The parsed TOML of a scene file (not yet validated) and the file's path (``scene.toml`` for a folder)."""
    path = Path(path)
    try:
        if path.is_dir():
            path = path / "scene.toml"
        text = _read_text(path, MAX_SCENE_FILE_BYTES)
    except FileNotFoundError:
        raise _error(path, "(file)", "no such file") from None
    except OSError as e:
        raise _error(path, "(file)", e.strerror or str(e)) from None
    except ValueError as e:  # not UTF-8, too large, or a NUL in the path
        raise _error(path, "(file)", str(e)) from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise _error(path, "(syntax)", f"invalid TOML: {e}") from None
    except RecursionError:
        raise _error(path, "(syntax)", "invalid TOML: arrays or tables nested too deeply") from None
    except ValueError as e:  # e.g. an integer of more than 4300 digits
        raise _error(path, "(syntax)", f"invalid TOML: {e}") from None
    return doc, path


def parse_scene(doc: dict, path: Path) -> Scene:
    """Validate a parsed scene document (see :func:`load_scene`)."""
    r = _Reader(path)
    r.known(doc, "", SCENE_KEYS[""])
    fmt = r.get(doc, "format", "", int)
    if fmt != 1:
        raise r.err("format", f"unsupported scene format {fmt}; this harness reads format 1")
    name = r.get(doc, "name", "", str)
    description = r.get(doc, "description", "", str, "")

    camera = _parse_camera(r, r.get(doc, "camera", "", dict))
    render = r.get(doc, "render", "", dict)
    r.known(render, "render", SCENE_KEYS["render"])
    max_depth = r.get(render, "max_depth", "render", int)
    if max_depth == 0 or max_depth < -1:
        raise r.err("render.max_depth", f"must be -1 (unbounded) or >= 1, got {max_depth}")
    if max_depth > MAX_DEPTH:
        raise r.err("render.max_depth", f"out of range: at most {MAX_DEPTH} (or -1, unbounded), got {max_depth}")
    pixel_filter = r.get(render, "pixel_filter", "render", str)
    if pixel_filter not in PIXEL_FILTERS:
        raise r.err("render.pixel_filter", f"unknown filter {pixel_filter!r}; known: {', '.join(PIXEL_FILTERS)}")

    spectral = SpectralReader(r, doc, _key)  # [colour] and [spectra]: before the values that name a spectrum
    materials = _parse_materials(r, r.get(doc, "materials", "", dict), spectral)
    raw_meshes = r.get(doc, "meshes", "", list)
    if not raw_meshes:
        raise r.err("meshes", "a scene needs at least one mesh")
    meshes = tuple(_parse_mesh(r, m, i, materials, path.parent, spectral) for i, m in enumerate(raw_meshes))
    spheres = tuple(_parse_sphere(r, t, i, materials) for i, t in enumerate(r.get(doc, "spheres", "", list, [])))
    names = [m.name for m in meshes] + [s.name for s in spheres]
    for n in names:
        if names.count(n) > 1:
            raise r.err("meshes" if n in [m.name for m in meshes] else "spheres",
                        f"object name {n!r} is used more than once")
    _check_degenerate(r, meshes)
    regions = _parse_regions(r, r.get(doc, "regions", "", dict, {}), names)
    quantity, ao = _parse_quantity(r, doc, meshes, spheres)

    declared = r.get(doc, "features", "", list)
    for i, f in enumerate(declared):
        if not isinstance(f, str):
            raise r.err(f"features[{i}]", f"expected a string, got {type(f).__name__}")
        if f not in FEATURES:
            raise r.err(f"features[{i}]", f"unknown feature {f!r}; known: {', '.join(FEATURES)}")
    used = _features_used(meshes, spheres, materials, pixel_filter)
    if missing := sorted(used - set(declared)):
        raise r.err("features", f"the scene uses {', '.join(missing)} but does not declare it")
    if unused := sorted(set(declared) - used):
        raise r.err("features", f"declares {', '.join(unused)} but does not use it")

    return apply_length_scale(r, doc, Scene(
        name=name,
        path=path,
        features=frozenset(declared),
        camera=camera,
        materials=materials,
        meshes=meshes,
        max_depth=max_depth,
        pixel_filter=pixel_filter,
        description=description,
        spheres=spheres,
        regions=regions,
        quantity=quantity,
        ambient_occlusion=ao,
        spectral=spectral.finish(),
    ), _check_degenerate)


def _parse_quantity(r: _Reader, doc: dict, meshes, spheres) -> tuple[str, AmbientOcclusion | None]:
    """The scene's quantity and, for ambient occlusion, the definition it pins (:mod:`.quantities`)."""
    quantity = r.get(doc, "quantity", "", str, DEFAULT_QUANTITY)
    if quantity not in QUANTITIES:
        raise r.err("quantity", f"unknown quantity {quantity!r}; known: {', '.join(QUANTITIES)}")
    table = r.get(doc, "ambient_occlusion", "", dict, None)
    if quantity != "ambient_occlusion":
        if table is not None:
            raise r.err("ambient_occlusion", f"only a scene of quantity = \"ambient_occlusion\" has this table; "
                                             f"this one's quantity is {quantity!r}")
        return quantity, None
    if table is None:
        raise r.err("ambient_occlusion", "missing required table: an ambient-occlusion scene pins max_distance "
                                         "(or max_distance_relative), weighting, normal and miss_value")
    return quantity, parse_ambient_occlusion(r, table, extent(*object_bounds(meshes, spheres)))


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


def _parse_camera(r: _Reader, t: dict) -> Camera:
    w = "camera"
    r.known(t, w, SCENE_KEYS["camera"])
    kind = r.get(t, "type", w, str)
    if kind != "pinhole":
        raise r.err("camera.type", f"unknown camera {kind!r}; known: pinhole")
    position = r.vec(t, "position", w, bound=MAX_COORDINATE)
    look_at = r.vec(t, "look_at", w, bound=MAX_COORDINATE)
    up = r.vec(t, "up", w, bound=MAX_COORDINATE)
    fov = r.get(t, "fov_deg", w, float)
    if not 0.0 < fov < 180.0:
        raise r.err("camera.fov_deg", f"must be in (0, 180), got {fov}")
    axis = r.get(t, "fov_axis", w, str)
    if axis not in FOV_AXES:
        raise r.err("camera.fov_axis", f"unknown axis {axis!r}; known: {', '.join(FOV_AXES)}")
    res = r.get(t, "resolution", w, list)
    if len(res) != 2 or any(isinstance(x, bool) or not isinstance(x, int) for x in res):
        raise r.err("camera.resolution", "expected [width, height] as two integers")
    if res[0] <= 0 or res[1] <= 0:
        raise r.err("camera.resolution", f"width and height must be positive, got {res}")
    if (need := image_memory_bytes(res[0], res[1])) > MAX_IMAGE_BYTES:
        raise r.err("camera.resolution",
                    f"{_count(res[0])}x{_count(res[1])} is too large: its image buffers need an estimated "
                    f"{_bytes(need)} (width x height x 3 channels x float64 x {IMAGE_BUFFERS} buffers), "
                    f"over the {_bytes(MAX_IMAGE_BYTES)} limit")
    forward = np.subtract(look_at, position)
    if np.linalg.norm(forward) == 0.0:
        raise r.err("camera.look_at", "equals camera.position")
    if np.linalg.norm(np.cross(forward, up)) <= 1e-9 * np.linalg.norm(forward) * np.linalg.norm(up):
        raise r.err("camera.up", "is zero or parallel to the viewing direction")
    return Camera(position, look_at, up, fov, axis, int(res[0]), int(res[1]))


def _parse_materials(r: _Reader, t: dict, spectral: SpectralReader) -> dict:
    if not t:
        raise r.err("materials", "a scene needs at least one material")
    out = {}
    for name, m in t.items():
        w = f"materials.{_key(name)}"
        if not isinstance(m, dict):
            raise r.err(w, f"expected a table, got {type(m).__name__}")
        if "type" not in m:  # a misspelt "typ" gets its did-you-mean, not "type: missing"
            r.known(m, w, _ANY_MATERIAL_KEY)
        kind = r.get(m, "type", w, str)
        if kind not in MATERIAL_TYPES:
            close = closest(kind, MATERIAL_TYPES)
            hint = f"did you mean {close!r}?" if close else f"known: {', '.join(MATERIAL_TYPES)}"
            raise r.err(f"{w}.type", f"unknown material type {one_line(kind, 60)!r}; {hint}")
        cls = MATERIAL_TYPES[kind]
        fields = material_fields(cls)
        r.known(m, w, ("type",) + tuple(f.name for f in fields))
        out[name] = cls(name, **{f.name: _material_field(r, m, w, f, spectral, name) for f in fields if f.name in m
                                 or f.default is dataclasses.MISSING})
    return out


def _material_field(r: _Reader, m: dict, w: str, f: dataclasses.Field, spectral: SpectralReader, material: str):
    """One field of a material table, checked against its kind (cornell_harness.scenes.materials)."""
    kind = f.metadata["kind"]
    if kind == "rgb01" and isinstance(m.get(f.name), dict):  # { spectrum = "NAME" }: its RGB projection
        return spectral.reflectance(m[f.name], f"{w}.{f.name}", material, f.name)
    if kind == "rgb01":
        rgb = r.vec(m, f.name, w)
        for i, x in enumerate(rgb):
            if not 0.0 <= x <= 1.0:
                raise r.err(f"{w}.{f.name}[{i}]", f"must be in [0, 1], got {x}")
        return rgb
    if kind == "ior":
        x = r.get(m, f.name, w, float)
        if not 0.0 < x <= MAX_IOR:
            raise r.err(f"{w}.{f.name}", f"an index of refraction must be in (0, {MAX_IOR:g}], got {x}")
        return x
    raise AssertionError(f"material field kind {kind!r} has no parser")  # a programming error in materials.py


def _object_header(r: _Reader, t: Any, where: str, keys: tuple[str, ...], materials: dict) -> tuple[str, str, str]:
    """A mesh's or sphere's table checked, its field path (``meshes[2] (floor)``), name and material."""
    if not isinstance(t, dict):
        raise r.err(where, f"expected a table, got {type(t).__name__}")
    w = f"{where} ({one_line(t['name'], 60)})" if isinstance(t.get("name"), str) else where
    r.known(t, w, keys)
    name = r.get(t, "name", w, str)
    material = r.get(t, "material", w, str)
    if material not in materials:
        raise r.err(f"{w}.material", f"unknown material {material!r}; defined: {', '.join(sorted(materials))}")
    return w, name, material


def _parse_sphere(r: _Reader, t: Any, i: int, materials: dict) -> Sphere:
    w, name, material = _object_header(r, t, f"spheres[{i}]", SCENE_KEYS["sphere"], materials)
    center = r.vec(t, "center", w, bound=MAX_COORDINATE)
    radius = r.get(t, "radius", w, float)
    if not 0.0 < radius <= MAX_COORDINATE:
        raise r.err(f"{w}.radius", f"must be in (0, {MAX_COORDINATE:g}], got {radius}")
    return Sphere(name, center, radius, material)


def _parse_regions(r: _Reader, t: dict, objects: list[str]) -> dict[str, Region]:
    out = {}
    for name, g in t.items():
        w = f"regions.{_key(name)}"
        if not isinstance(g, dict):
            raise r.err(w, f"expected a table, got {type(g).__name__}")
        r.known(g, w, SCENE_KEYS["region"])
        raw = r.get(g, "objects", w, list, [])
        for i, o in enumerate(raw):
            if not isinstance(o, str):
                raise r.err(f"{w}.objects[{i}]", f"expected a string, got {type(o).__name__}")
            if o not in objects:
                close = closest(o, objects)
                hint = f"did you mean {close!r}?" if close else f"objects: {', '.join(objects)}"
                raise r.err(f"{w}.objects[{i}]", f"no object named {one_line(o, 60)!r}; {hint}")
        box = None
        if "box" in g:
            b = r.get(g, "box", w, dict)
            r.known(b, f"{w}.box", SCENE_KEYS["box"])
            lo = r.vec(b, "min", f"{w}.box", bound=MAX_COORDINATE)
            hi = r.vec(b, "max", f"{w}.box", bound=MAX_COORDINATE)
            if not all(a < z for a, z in zip(lo, hi)):
                raise r.err(f"{w}.box", f"min must be below max on every axis, got {list(lo)} and {list(hi)}")
            box = (lo, hi)
        if not raw and box is None:
            raise r.err(w, "a region needs objects, a box, or both")
        out[name] = Region(name, tuple(raw), box, r.get(g, "description", w, str, ""))
    return out


def _parse_mesh(r: _Reader, t: Any, i: int, materials: dict, base: Path, spectral: SpectralReader) -> Mesh:
    w, name, material = _object_header(r, t, f"meshes[{i}]", SCENE_KEYS["mesh"], materials)
    if "obj" in t and ("vertices" in t or "faces" in t):
        raise r.err(w, "give either obj or vertices/faces, not both")
    if "obj" in t:
        obj = base / r.get(t, "obj", w, str)
        vertices, faces = _read_obj(r, obj, f"{w}.obj")
    else:
        raw_v = r.get(t, "vertices", w, list)
        vertices = [r.numbers(v, f"{w}.vertices[{j}]", 3, MAX_COORDINATE) for j, v in enumerate(raw_v)]
        raw_f = r.get(t, "faces", w, list)
        faces = []
        for j, f in enumerate(raw_f):
            if not isinstance(f, list) or len(f) not in (3, 4) or any(isinstance(x, bool) or not isinstance(x, int) for x in f):
                raise r.err(f"{w}.faces[{j}]", "expected a list of 3 or 4 integer vertex indices")
            faces.append(f)
    if not faces:
        raise r.err(f"{w}.faces", "a mesh needs at least one face")
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    tris = []
    for j, f in enumerate(faces):
        for x in f:
            if not 0 <= x < len(v):
                raise r.err(f"{w}.faces[{j}]", f"vertex index {x} out of range 0..{len(v) - 1}")
        tris.append(f[:3])
        if len(f) == 4:
            tris.append([f[0], f[2], f[3]])
    radiance = None
    if "emitter" in t:
        e = r.get(t, "emitter", w, dict)
        r.known(e, f"{w}.emitter", SCENE_KEYS["emitter"])
        if isinstance(e.get("radiance"), dict):  # { spectrum = "NAME" }: its RGB
            radiance = spectral.emission(e["radiance"], f"{w}.emitter.radiance", name, MAX_RADIANCE)
        else:
            radiance = r.vec(e, "radiance", f"{w}.emitter", bound=MAX_RADIANCE)
        if min(radiance) < 0.0:
            raise r.err(f"{w}.emitter.radiance", f"must be non-negative, got {list(radiance)}")
    return Mesh(name, v, np.asarray(tris, dtype=np.int64), material, radiance)


def _read_obj(r: _Reader, path: Path, field: str) -> tuple[list, list]:
    """Vertices and polygon faces of a Wavefront OBJ (positions only)."""
    try:
        lines = _read_text(path, MAX_OBJ_FILE_BYTES).splitlines()
    except FileNotFoundError:
        raise r.err(field, f"OBJ file {path} does not exist") from None
    except OSError as e:
        raise r.err(field, f"cannot read OBJ file {path}: {e.strerror or e}") from None
    except ValueError as e:  # not UTF-8, too large, or a NUL in the path
        raise r.err(field, f"OBJ file {path}: {e}") from None
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


def _check_degenerate(r: _Reader, meshes: tuple[Mesh, ...]) -> None:
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
            raise r.err(f"meshes[{i}] ({m.name})", f"triangle {int(bad[0])} is degenerate (zero area)")
