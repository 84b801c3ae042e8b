"""Binary little-endian PLY files of triangle meshes: the one mesh file every export format reads.

Mitsuba 3 (``ply`` shape), LuxCore (``scene.shapes.NAME.ply``) and pbrt-v4 (``Shape "plymesh"``) all
read PLY; writing one kind keeps vertex order and precision the same across formats. Vertices are
written as float32 (what every one of those renderers stores), indices as uint32.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def write_ply(path: Path | str, vertices: np.ndarray, triangles: np.ndarray,
              normals: np.ndarray | None = None) -> None:
    """Write a triangle mesh (``vertices`` (V, 3), ``triangles`` (T, 3) indices) as binary PLY.

    ``normals`` (V, 3), when given, are written as the vertices' ``nx ny nz`` (shading normals: a
    tessellated sphere's analytic ones)."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    props = "property float x\nproperty float y\nproperty float z\n"
    if normals is not None:
        v = np.concatenate([v, np.asarray(normals, dtype=np.float64)], axis=1)
        props += "property float nx\nproperty float ny\nproperty float nz\n"
    v = np.ascontiguousarray(v, dtype="<f4")
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(v)}\n{props}"
        f"element face {len(t)}\nproperty list uchar uint vertex_indices\nend_header\n"
    ).encode("ascii")
    faces = np.empty(len(t), dtype=[("n", "u1"), ("i", "<u4", (3,))])
    faces["n"] = 3
    faces["i"] = t
    with open(path, "wb") as f:
        f.write(header)
        f.write(v.tobytes())
        f.write(faces.tobytes())


def read_ply(path: Path | str) -> tuple[np.ndarray, np.ndarray]:
    """(vertices float64 (V, 3), triangles int64 (T, 3)) of a PLY written by :func:`write_ply`."""
    data = Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    counts = {line.split()[1]: int(line.split()[2]) for line in header if line.startswith("element")}
    nv, nf = counts["vertex"], counts["face"]
    floats = sum(1 for line in header if line.startswith("property float"))  # 3, or 6 with normals
    v = np.frombuffer(data, dtype="<f4", count=floats * nv, offset=end).reshape(nv, floats)[:, :3]
    faces = np.frombuffer(data, dtype=[("n", "u1"), ("i", "<u4", (3,))], count=nf, offset=end + 4 * floats * nv)
    if nf and not (faces["n"] == 3).all():
        raise ValueError(f"{path}: only triangles are read")
    return v.astype(np.float64), faces["i"].astype(np.int64)
