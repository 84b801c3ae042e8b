"""Scene conversion and Embree set-up shared by our renderers.

:class:`SceneGeometry` turns a :class:`harness.scene.Scene` into the per-
triangle float64 arrays the shading code reads (unit normals, areas,
reflectance, emitted radiance, emitter-sampling tables), and owns the embreex
scene that answers ray queries.

Numerical conventions (every renderer of ours relies on them):

- All maths is float64; kernels also write float32 copies of the rays they
  make, because embreex takes float32 only.
- embreex has no ``tnear``: rays leaving a surface start at
  ``x + offset * n`` on the side they travel to, with ``offset`` scaled to the
  scene (:data:`OFFSET_REL` of its size), so a scene scaled by 1e-3 or 1e3
  gives the same image.
- Normals come from our own vertex data, never from Embree's ``Ng`` (which is
  not normalised).
"""

from __future__ import annotations

import threading

import numpy as np

from harness.scenes.model import Scene, triangle_arrays

#: Ray-origin offset relative to the scene's size: far above float32 hit-point
#: error (~1e-7 of the coordinates), far below any feature of the scene.
OFFSET_REL = 1e-5


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

        lo, hi = verts.min(0), verts.max(0)
        self.extent = float(np.linalg.norm(hi - lo))
        # Coordinates far from the origin lose float32 precision in absolute
        # terms, so the offset follows whichever is larger.
        self.offset = OFFSET_REL * max(self.extent, float(np.abs(verts).max()))

        self._init_emitters()
        self.rays = 0  # rays traced so far (closest-hit and shadow), for benchmarks
        self._rays_lock = threading.Lock()
        self._embree = rtcs.EmbreeScene()
        self._mesh = TriangleMesh(self._embree, verts.astype(np.float32), faces.astype(np.int32))

    # -- emitters ---------------------------------------------------------
    def _init_emitters(self) -> None:
        """Tables to pick an emitter triangle in proportion to its power.

        Power of a one-sided Lambertian emitter is π·A·Le; we weight by the
        mean over the three channels. ``emitter_cdf`` over ``emitter_ids``
        picks a triangle; a point on it is then uniform by area, so the area
        pdf of a point on triangle t is ``P(t) / A(t) = mean(Le_t) / Σ A·mean(Le)``,
        stored per triangle in ``light_pdf_area`` (zero for non-emitters).
        """
        weight = self.area * self.radiance.mean(axis=1)
        self.emitter_ids = np.flatnonzero(weight > 0)
        total = float(weight.sum())
        self.light_pdf_area = np.zeros(len(self.area))
        if total > 0:
            self.light_pdf_area[self.emitter_ids] = self.radiance[self.emitter_ids].mean(axis=1) / total
            cdf = np.cumsum(weight[self.emitter_ids]) / total
            cdf[-1] = 1.0
            self.emitter_cdf = cdf
        else:
            self.emitter_cdf = np.zeros(0)

    @property
    def has_emitters(self) -> bool:
        return self.emitter_ids.size > 0

    # -- ray queries -------------------------------------------------------
    def _count(self, n: int) -> None:
        with self._rays_lock:
            self.rays += n

    def intersect(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Closest-hit triangle id per ray, -1 for a miss; float32 (n, 3) inputs.

        Only the id comes back: kernels recompute the distance in float64 from
        the triangle's plane, which is cheaper than Embree's full hit record and
        more precise.
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
