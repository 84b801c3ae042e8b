"""Scene conversion and Embree set-up shared by our renderers.

:class:`SceneGeometry` turns a :class:`harness.scenes.model.Scene` into the
per-triangle float64 tables the shading code reads, and owns the embreex
scene that answers ray queries. It is the one place that computes triangle
areas and normals; the emitter-sampling tables built from them are
:mod:`renderers.core.lights`' and the material ids :mod:`renderers.core.bsdf`'.
Kernels get every table at once as :meth:`SceneGeometry.tables`, a
:class:`Tables` named tuple (numba passes it as one argument).

Numerical conventions (every renderer of ours relies on them):

- All maths is float64; kernels also write float32 copies of the rays they
  make, because embreex takes float32 only (:mod:`renderers.core.rays`).
- embreex has no ``tnear``: rays leaving a surface start at
  ``x + offset * n`` on the side they travel to (:func:`offset_origin`; pbrt-v4
  §6.8.6 offsets by a bound of the hit point's error instead), with
  ``offset`` scaled to the scene (:data:`OFFSET_REL` of its size), so a scene
  scaled by 1e-3 or 1e3 gives the same image.
- Normals come from our own vertex data, never from Embree's ``Ng`` (which is
  not normalised), and hit distances from the triangle's plane in float64
  (:func:`hit_distance`).
"""

from __future__ import annotations

import threading
from typing import NamedTuple

import numpy as np

from harness.scenes.model import Scene, triangle_arrays
from renderers.core.bsdf import material_types
from renderers.core.lights import emitter_tables
from renderers.core.sampling import jit

#: Ray-origin offset relative to the scene's size: far above float32 hit-point
#: error (~1e-7 of the coordinates), far below any feature of the scene.
OFFSET_REL = 1e-5


class Tables(NamedTuple):
    """What numba kernels read about the scene, per triangle t of T (float64 unless said)."""

    v0: np.ndarray  # (T, 3) first vertex
    e1: np.ndarray  # (T, 3) edge v1 - v0
    e2: np.ndarray  # (T, 3) edge v2 - v0
    normal: np.ndarray  # (T, 3) unit, (e1 × e2) / |e1 × e2|: the front side
    reflectance: np.ndarray  # (T, 3) ρ
    radiance: np.ndarray  # (T, 3) emitted Le, 0 for non-emitters
    material: np.ndarray  # (T,) int8 type id (renderers.core.bsdf)
    light_pdf_area: np.ndarray  # (T,) area pdf of emitter sampling (renderers.core.lights)
    emitter_ids: np.ndarray  # (E,) int64 emitter triangles
    emitter_cdf: np.ndarray  # (E,) by power
    offset: float  # ray-origin offset, scaled to the scene


class SceneGeometry:
    """Triangles of a scene, with the Embree scene built over them."""

    def __init__(self, scene: Scene):
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh

        tri = triangle_arrays(scene)
        verts, faces = tri["vertices"], tri["triangles"]
        self.v0 = verts[faces[:, 0]]
        self.e1 = verts[faces[:, 1]] - self.v0
        self.e2 = verts[faces[:, 2]] - self.v0
        cross = np.cross(self.e1, self.e2)
        double_area = np.linalg.norm(cross, axis=1)
        self.area = 0.5 * double_area
        self.normal = cross / double_area[:, None]  # scene loader rejects zero-area triangles
        self.reflectance = tri["reflectance"]
        self.radiance = tri["radiance"]
        self.mesh = tri["mesh"]
        self.material = material_types(scene, self.mesh)

        lo, hi = verts.min(0), verts.max(0)
        self.extent = float(np.linalg.norm(hi - lo))
        # Coordinates far from the origin lose float32 precision in absolute
        # terms, so the offset follows whichever is larger.
        self.offset = OFFSET_REL * max(self.extent, float(np.abs(verts).max()))

        self.emitters = emitter_tables(self.area, self.radiance)
        self.rays = 0  # rays traced so far (closest-hit and shadow), for benchmarks
        self._rays_lock = threading.Lock()
        self._embree = rtcs.EmbreeScene()
        self._mesh = TriangleMesh(self._embree, verts.astype(np.float32), faces.astype(np.int32))

    @property
    def has_emitters(self) -> bool:
        return self.emitters.ids.size > 0

    def tables(self) -> Tables:
        """Every per-triangle table, for numba kernels (one argument)."""
        return Tables(self.v0, self.e1, self.e2, self.normal, self.reflectance, self.radiance, self.material,
                      self.emitters.pdf_area, self.emitters.ids, self.emitters.cdf, self.offset)

    # -- ray queries -------------------------------------------------------
    def _count(self, n: int) -> None:
        with self._rays_lock:
            self.rays += n

    def intersect(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Closest-hit triangle id per ray, -1 for a miss; float32 (n, 3) inputs.

        Only the id comes back: kernels recompute the distance in float64 from
        the triangle's plane (:func:`hit_distance`), which is cheaper than
        Embree's full hit record and more precise.
        """
        if len(origins) == 0:
            return np.zeros(0, np.int32)
        self._count(len(origins))
        return self._embree.run(origins, directions, query="INTERSECT")

    def unoccluded(self, origins: np.ndarray, directions: np.ndarray, tfar: np.ndarray) -> np.ndarray:
        """True where nothing lies along origin + t·direction for t in (0, tfar); float32 inputs."""
        if len(origins) == 0:
            return np.zeros(0, bool)
        self._count(len(origins))
        return self._embree.run(origins, directions, dists=tfar, query="OCCLUDED") == -1  # -1: unblocked


# -- numba helpers on the tables ---------------------------------------------------------

@jit
def triangle_normal(g, p):
    """Unit normal of triangle ``p`` as a 3-tuple."""
    return g.normal[p, 0], g.normal[p, 1], g.normal[p, 2]


@jit
def hit_distance(g, p, o, d, cos_o) -> float:
    """Distance along unit ``d`` from ``o`` to the plane of triangle ``p``, Embree's hit, in float64.

    ``cos_o = -d·n > 0`` (the caller has checked the side). Clamped at 0: a
    ray that starts a hair behind the plane still hits at its origin.
    """
    v0, n = g.v0, g.normal
    t = ((v0[p, 0] - o[0]) * n[p, 0] + (v0[p, 1] - o[1]) * n[p, 1] + (v0[p, 2] - o[2]) * n[p, 2]) / -cos_o
    return 0.0 if t < 0.0 else t


@jit
def offset_origin(x, n, eps):
    """``x + eps·n``: where a ray leaving the surface at ``x`` on the side of ``n`` starts (no tnear)."""
    return x[0] + eps * n[0], x[1] + eps * n[1], x[2] + eps * n[2]
