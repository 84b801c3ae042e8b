"""Reading scene files: TOML in, a validated :class:`~harness.scenes.model.Scene` out.

Every error is a :class:`~harness.scenes.model.SceneError` that names the file
and the field. The format itself (fields, units, conventions) is documented in
:mod:`harness.scenes.model`.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from harness.scenes.model import (_DEGENERATE_REL_AREA, FEATURES, FOV_AXES, PIXEL_FILTERS, Camera, Diffuse, Mesh,
                                  Scene, SceneError)


class _Reader:
    """Typed access to a parsed TOML table that raises SceneError with the path."""

    def __init__(self, file: Path):
        self.file = file

    def err(self, field: str, message: str) -> SceneError:
        return SceneError(self.file, field, message)

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
            value = float(value)
        if not isinstance(value, kinds):
            raise self.err(field, f"expected {_kind_name(kind)}, got {type(value).__name__}")
        if isinstance(value, float) and not math.isfinite(value):
            raise self.err(field, f"must be finite, got {value}")
        return value

    def vec(self, table: dict, key: str, where: str, n: int = 3, default: Any = ...) -> tuple[float, ...]:
        field = f"{where}.{key}" if where else key
        raw = self.get(table, key, where, list, default)
        if raw is default and default is not ...:
            return default
        return self.numbers(raw, field, n)

    def numbers(self, raw: Any, field: str, n: int) -> tuple[float, ...]:
        if not isinstance(raw, list) or len(raw) != n:
            raise self.err(field, f"expected a list of {n} numbers")
        out = []
        for i, x in enumerate(raw):
            if isinstance(x, bool) or not isinstance(x, (int, float)):
                raise self.err(f"{field}[{i}]", f"expected a number, got {type(x).__name__}")
            if not math.isfinite(x):
                raise self.err(f"{field}[{i}]", f"must be finite, got {x}")
            out.append(float(x))
        return tuple(out)


def _kind_name(kind: type | tuple) -> str:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    names = {int: "an integer", float: "a number", str: "a string", list: "a list", dict: "a table", bool: "a boolean"}
    return " or ".join(names.get(k, k.__name__) for k in kinds)


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene file; raise :class:`SceneError` on bad input."""
    path = Path(path)
    if path.is_dir():
        path = path / "scene.toml"
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SceneError(path, "(file)", "no such file") from None
    except OSError as e:
        raise SceneError(path, "(file)", e.strerror or str(e)) from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SceneError(path, "(syntax)", f"invalid TOML: {e}") from None
    return parse_scene(doc, path)


def parse_scene(doc: dict, path: Path) -> Scene:
    """Validate a parsed scene document (see :func:`load_scene`)."""
    r = _Reader(path)
    fmt = r.get(doc, "format", "", int)
    if fmt != 1:
        raise r.err("format", f"unsupported scene format {fmt}; this harness reads format 1")
    name = r.get(doc, "name", "", str)
    description = r.get(doc, "description", "", str, "")

    camera = _parse_camera(r, r.get(doc, "camera", "", dict))
    render = r.get(doc, "render", "", dict)
    max_depth = r.get(render, "max_depth", "render", int)
    if max_depth == 0 or max_depth < -1:
        raise r.err("render.max_depth", f"must be -1 (unbounded) or >= 1, got {max_depth}")
    pixel_filter = r.get(render, "pixel_filter", "render", str)
    if pixel_filter not in PIXEL_FILTERS:
        raise r.err("render.pixel_filter", f"unknown filter {pixel_filter!r}; known: {', '.join(PIXEL_FILTERS)}")

    materials = _parse_materials(r, r.get(doc, "materials", "", dict))
    raw_meshes = r.get(doc, "meshes", "", list)
    if not raw_meshes:
        raise r.err("meshes", "a scene needs at least one mesh")
    meshes = tuple(_parse_mesh(r, m, i, materials, path.parent) for i, m in enumerate(raw_meshes))
    names = [m.name for m in meshes]
    for n in names:
        if names.count(n) > 1:
            raise r.err("meshes", f"mesh name {n!r} is used more than once")
    _check_degenerate(r, meshes)

    declared = r.get(doc, "features", "", list)
    for i, f in enumerate(declared):
        if not isinstance(f, str):
            raise r.err(f"features[{i}]", f"expected a string, got {type(f).__name__}")
        if f not in FEATURES:
            raise r.err(f"features[{i}]", f"unknown feature {f!r}; known: {', '.join(FEATURES)}")
    used = _features_used(meshes, pixel_filter)
    if missing := sorted(used - set(declared)):
        raise r.err("features", f"the scene uses {', '.join(missing)} but does not declare it")
    if unused := sorted(set(declared) - used):
        raise r.err("features", f"declares {', '.join(unused)} but does not use it")

    return Scene(
        name=name,
        path=path,
        features=frozenset(declared),
        camera=camera,
        materials=materials,
        meshes=meshes,
        max_depth=max_depth,
        pixel_filter=pixel_filter,
        description=description,
    )


def _features_used(meshes: tuple[Mesh, ...], pixel_filter: str) -> set[str]:
    used = {"triangle_mesh", "diffuse", "pinhole_camera"}
    if any(m.is_emitter for m in meshes):
        used.add("area_light")
    if pixel_filter == "box":
        used.add("box_filter")
    return used


def _parse_camera(r: _Reader, t: dict) -> Camera:
    w = "camera"
    kind = r.get(t, "type", w, str)
    if kind != "pinhole":
        raise r.err("camera.type", f"unknown camera {kind!r}; known: pinhole")
    position = r.vec(t, "position", w)
    look_at = r.vec(t, "look_at", w)
    up = r.vec(t, "up", w)
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
    forward = np.subtract(look_at, position)
    if np.linalg.norm(forward) == 0.0:
        raise r.err("camera.look_at", "equals camera.position")
    if np.linalg.norm(np.cross(forward, up)) <= 1e-9 * np.linalg.norm(forward) * np.linalg.norm(up):
        raise r.err("camera.up", "is zero or parallel to the viewing direction")
    return Camera(position, look_at, up, fov, axis, int(res[0]), int(res[1]))


def _parse_materials(r: _Reader, t: dict) -> dict[str, Diffuse]:
    if not t:
        raise r.err("materials", "a scene needs at least one material")
    out = {}
    for name, m in t.items():
        w = f"materials.{name}"
        if not isinstance(m, dict):
            raise r.err(w, f"expected a table, got {type(m).__name__}")
        kind = r.get(m, "type", w, str)
        if kind != "diffuse":
            raise r.err(f"{w}.type", f"unknown material type {kind!r}; known: diffuse")
        rho = r.vec(m, "reflectance", w)
        for i, x in enumerate(rho):
            if not 0.0 <= x <= 1.0:
                raise r.err(f"{w}.reflectance[{i}]", f"must be in [0, 1], got {x}")
        out[name] = Diffuse(name, rho)
    return out


def _parse_mesh(r: _Reader, t: Any, i: int, materials: dict, base: Path) -> Mesh:
    w = f"meshes[{i}]"
    if not isinstance(t, dict):
        raise r.err(w, f"expected a table, got {type(t).__name__}")
    name = r.get(t, "name", w, str)
    w = f"meshes[{i}] ({name})"
    material = r.get(t, "material", w, str)
    if material not in materials:
        known = ", ".join(sorted(materials))
        raise r.err(f"{w}.material", f"unknown material {material!r}; defined: {known}")
    if "obj" in t and ("vertices" in t or "faces" in t):
        raise r.err(w, "give either obj or vertices/faces, not both")
    if "obj" in t:
        obj = base / r.get(t, "obj", w, str)
        vertices, faces = _read_obj(r, obj, f"{w}.obj")
    else:
        raw_v = r.get(t, "vertices", w, list)
        vertices = [r.numbers(v, f"{w}.vertices[{j}]", 3) for j, v in enumerate(raw_v)]
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
        radiance = r.vec(e, "radiance", f"{w}.emitter")
        if min(radiance) < 0.0:
            raise r.err(f"{w}.emitter.radiance", f"must be non-negative, got {list(radiance)}")
    return Mesh(name, v, np.asarray(tris, dtype=np.int64), material, radiance)


def _read_obj(r: _Reader, path: Path, field: str) -> tuple[list, list]:
    """Vertices and polygon faces of a Wavefront OBJ (positions only)."""
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except FileNotFoundError:
        raise r.err(field, f"OBJ file {path} does not exist") from None
    except OSError as e:
        raise r.err(field, f"cannot read OBJ file {path}: {e.strerror or e}") from None
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
                vertices.append(xyz)
            elif parts[0] == "f":
                idx = [int(p.split("/")[0]) for p in parts[1:]]
                idx = [k - 1 if k > 0 else len(vertices) + k for k in idx]
                if len(idx) < 3:
                    raise ValueError("a face needs at least 3 vertices")
                faces.extend([idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1))
        except ValueError as e:
            raise SceneError(path, f"line {n}", str(e)) from None
    return vertices, faces


def _check_degenerate(r: _Reader, meshes: tuple[Mesh, ...]) -> None:
    v = np.concatenate([m.vertices for m in meshes])
    size2 = float(np.sum((v.max(0) - v.min(0)) ** 2)) or 1.0
    for i, m in enumerate(meshes):
        a, b, c = (m.vertices[m.triangles[:, k]] for k in range(3))
        area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
        bad = np.flatnonzero(area <= _DEGENERATE_REL_AREA * size2)
        if bad.size:
            raise r.err(f"meshes[{i}] ({m.name})", f"triangle {int(bad[0])} is degenerate (zero area)")
