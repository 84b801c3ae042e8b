"""Scene conversion and ray queries shared by our renderers: Embree's triangles and analytic spheres.

:class:`SceneGeometry` turns a :class:`cornell_harness.scenes.model.Scene` into the
per-primitive float64 tables the shading code reads, and owns the Embree
scene that answers ray queries (:mod:`cornell_harness.renderers.core.embree`). It is the one place that computes triangle
areas and normals; the emitter-sampling tables built from them are
:mod:`cornell_harness.renderers.core.lights`' and the material tables :mod:`cornell_harness.renderers.core.bsdf`'.
Kernels get every table at once as :meth:`SceneGeometry.tables`, a
:class:`Tables` named tuple (numba passes it as one argument).

Primitives are numbered triangles first (0 .. T-1, Embree's ids), then
spheres (T .. T+S-1). Embree answers for the triangles; spheres are
intersected here in float64 (:func:`sphere_hit`), and the nearer hit wins
(:meth:`SceneGeometry.closest_hits`, :meth:`SceneGeometry.unoccluded`). A
scene without spheres never runs the sphere code.

Numerical conventions (every renderer of ours relies on them):

- All maths is float64; kernels also write float32 copies of the rays they
  make, because Embree takes float32 only (:mod:`cornell_harness.renderers.core.rays`).
- Queries start at tnear 0: rays leaving a surface start at
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

import math

from cornell_harness.scenes.model import Scene, triangle_arrays
from cornell_harness.renderers.core.bsdf import material_tables
from cornell_harness.renderers.core.embree import EmbreeScene, closest_triangles, ray_record, segments_clear
from cornell_harness.renderers.core.lights import emitter_tables
from cornell_harness.renderers.core.rays import add_unoccluded
from cornell_harness.renderers.core.sampling import jit

#: Ray-origin offset relative to the scene's size: far above float32 hit-point
#: error (~1e-7 of the coordinates), far below any feature of the scene.
OFFSET_REL = 1e-5


class Tables(NamedTuple):
    """What numba kernels read about the scene: per triangle t of T, per sphere s of S, per primitive p of
    N = T + S (float64 unless said)."""

    v0: np.ndarray  # (T, 3) first vertex
    e1: np.ndarray  # (T, 3) edge v1 - v0
    e2: np.ndarray  # (T, 3) edge v2 - v0
    normal: np.ndarray  # (T, 3) unit, (e1 × e2) / |e1 × e2|: the front side
    reflectance: np.ndarray  # (N, 3) ρ: diffuse albedo or mirror reflectance (cornell_harness.renderers.core.bsdf)
    radiance: np.ndarray  # (N, 3) emitted Le, 0 for non-emitters
    material: np.ndarray  # (N,) int8 type id (cornell_harness.renderers.core.bsdf)
    light_pdf_area: np.ndarray  # (N,) area pdf of emitter sampling (cornell_harness.renderers.core.lights)
    emitter_ids: np.ndarray  # (E,) int64 emitter triangles
    emitter_cdf: np.ndarray  # (E,) by power
    offset: float  # ray-origin offset, scaled to the scene
    eta: np.ndarray  # (N,) relative index of refraction of dielectrics, 1 otherwise
    n_triangles: int  # T: primitives from T on are spheres
    sphere_center: np.ndarray  # (S, 3)
    sphere_radius: np.ndarray  # (S,)
    embree: int  # handle of the committed Embree scene, for kernels that trace (trace_closest, trace_unoccluded)


class Hits(NamedTuple):
    """Closest hits of a wavefront (:meth:`SceneGeometry.closest_hits`): what a shading kernel reads first."""

    prim: np.ndarray  # (m,) int32 primitive hit by ray i, -1: missed
    t_sphere: np.ndarray  # (m,) float64 distance of a sphere hit (empty in a scene without spheres)


class SceneGeometry:
    """Triangles of a scene, with the Embree scene built over them."""

    def __init__(self, scene: Scene):
        tri = triangle_arrays(scene)
        verts, faces = tri["vertices"], tri["triangles"]
        self.v0 = verts[faces[:, 0]]
        self.e1 = verts[faces[:, 1]] - self.v0
        self.e2 = verts[faces[:, 2]] - self.v0
        cross = np.cross(self.e1, self.e2)
        double_area = np.linalg.norm(cross, axis=1)
        self.area = 0.5 * double_area
        self.normal = cross / double_area[:, None]  # scene loader rejects zero-area triangles
        self.n_triangles = len(faces)
        self.sphere_center = np.asarray([s.center for s in scene.spheres], np.float64).reshape(-1, 3)
        self.sphere_radius = np.asarray([s.radius for s in scene.spheres], np.float64)
        n_spheres = len(scene.spheres)
        # Per primitive: the object it belongs to (meshes, then spheres), and that object's tables.
        self.object = np.concatenate([tri["mesh"], len(scene.meshes) + np.arange(n_spheres)])
        kinds, rho, eta = material_tables(scene)
        self.material, self.reflectance, self.eta = kinds[self.object], rho[self.object], eta[self.object]
        self.radiance = np.concatenate([tri["radiance"], np.zeros((n_spheres, 3))])

        lo, hi = scene.bounds()
        self.extent = float(np.linalg.norm(hi - lo))
        # Coordinates far from the origin lose float32 precision in absolute
        # terms, so the offset follows whichever is larger.
        self.offset = OFFSET_REL * max(self.extent, float(np.abs(lo).max()), float(np.abs(hi).max()))

        emitters = emitter_tables(self.area, tri["radiance"])
        self.emitters = emitters._replace(pdf_area=np.concatenate([emitters.pdf_area, np.zeros(n_spheres)]))
        self.rays = 0  # rays traced so far (closest-hit and shadow), for benchmarks
        self._rays_lock = threading.Lock()
        self._embree = EmbreeScene(verts.astype(np.float32), faces)

    @property
    def has_emitters(self) -> bool:
        return self.emitters.ids.size > 0

    @property
    def has_spheres(self) -> bool:
        return self.sphere_radius.size > 0

    def tables(self) -> Tables:
        """Every per-primitive table, for numba kernels (one argument)."""
        return Tables(self.v0, self.e1, self.e2, self.normal, self.reflectance, self.radiance, self.material,
                      self.emitters.pdf_area, self.emitters.ids, self.emitters.cdf, self.offset, self.eta,
                      self.n_triangles, self.sphere_center, self.sphere_radius, self._embree.handle)

    # -- ray queries -------------------------------------------------------
    def count(self, n: int) -> None:
        """Add ``n`` rays a kernel traced itself (:func:`trace_closest`, :func:`trace_unoccluded`) to ``rays``."""
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
        self.count(len(origins))
        prim = np.empty(len(origins), np.int32)
        closest_triangles(self._embree.handle, origins, directions, prim, ray_record())
        return prim

    def closest_hits(self, rays) -> Hits:
        """Closest primitive per ray of a :class:`cornell_harness.renderers.core.rays.RayBuffer` (-1: miss), and distances.

        The distances (float64) are filled for sphere hits only, and are an
        empty array in a scene without spheres: kernels get a triangle's
        distance from its plane (:func:`surface_point`).
        """
        prim = self.intersect(rays.o32, rays.d32)
        if not self.has_spheres:
            return Hits(prim, np.empty(0))
        t = np.empty(len(prim))
        _nearer_spheres(prim, rays.o, rays.d, self.tables(), t)
        return Hits(prim, t)

    def unoccluded(self, origins: np.ndarray, directions: np.ndarray, tfar: np.ndarray) -> np.ndarray:
        """True where nothing lies along origin + t·direction for t in (0, tfar); float32 inputs."""
        if len(origins) == 0:
            return np.zeros(0, bool)
        self.count(len(origins))
        visible = np.empty(len(origins), bool)
        segments_clear(self._embree.handle, origins, directions, tfar, visible, ray_record())
        if self.has_spheres:
            _spheres_occlude(origins, directions, tfar, self.sphere_center, self.sphere_radius, visible)
        return visible


# -- numba helpers on the tables ---------------------------------------------------------

@jit
def triangle_normal(g, p):
    """Unit normal of triangle ``p`` as a 3-tuple."""
    return g.normal[p, 0], g.normal[p, 1], g.normal[p, 2]


@jit
def hit_distance(g, p, o, d, cos_o) -> float:
    """Distance along unit ``d`` from ``o`` to the plane of triangle ``p``, Embree's hit, in float64.

    ``cos_o = -d·n``, nonzero, negative for a hit from behind. Clamped at 0: a
    ray that starts a hair behind the plane still hits at its origin.
    """
    v0, n = g.v0, g.normal
    t = ((v0[p, 0] - o[0]) * n[p, 0] + (v0[p, 1] - o[1]) * n[p, 1] + (v0[p, 2] - o[2]) * n[p, 2]) / -cos_o
    return 0.0 if t < 0.0 else t


@jit
def sphere_hit(cx, cy, cz, r, o, d, tmax) -> float:
    """Nearest t in (0, tmax) where the ray o + t·d (d unit) meets the sphere; inf if none.

    The discriminant is computed as r² - |f|² with f = o - c - (f·d)d, the
    form of Haines et al., "Precision Improvements for Ray/Sphere
    Intersection" (Ray Tracing Gems, ch. 7, eq. 10), which keeps its digits
    when the ray passes far from the centre; the roots come from the stable
    quadratic formula (pbrt-v4 §6.2.2).
    """
    fx, fy, fz = o[0] - cx, o[1] - cy, o[2] - cz
    b = fx * d[0] + fy * d[1] + fz * d[2]
    px, py, pz = fx - b * d[0], fy - b * d[1], fz - b * d[2]
    disc = r * r - (px * px + py * py + pz * pz)
    if disc < 0.0:
        return math.inf
    c = fx * fx + fy * fy + fz * fz - r * r
    q = -b - math.copysign(math.sqrt(disc), b)
    if q == 0.0:
        return math.inf
    t0, t1 = c / q, q
    if t0 > t1:
        t0, t1 = t1, t0
    if 0.0 < t0 < tmax:
        return t0
    if 0.0 < t1 < tmax:
        return t1
    return math.inf


@jit
def _nearer_spheres(prim, o, d, g, t):
    """Where a sphere is nearer than Embree's triangle hit, ``prim[i]`` becomes that sphere and ``t[i]`` its distance."""
    for i in range(prim.size):
        oi = (o[i, 0], o[i, 1], o[i, 2])
        di = (d[i, 0], d[i, 1], d[i, 2])
        best = math.inf
        p = prim[i]
        if p >= 0:
            n = triangle_normal(g, p)
            cos_d = di[0] * n[0] + di[1] * n[1] + di[2] * n[2]
            best = ((g.v0[p, 0] - oi[0]) * n[0] + (g.v0[p, 1] - oi[1]) * n[1] + (g.v0[p, 2] - oi[2]) * n[2]) / cos_d
        for s in range(g.sphere_radius.size):
            ts = sphere_hit(g.sphere_center[s, 0], g.sphere_center[s, 1], g.sphere_center[s, 2], g.sphere_radius[s],
                            oi, di, best)
            if ts < best:
                best = ts
                prim[i] = g.n_triangles + s
        t[i] = best


@jit
def trace_closest(g, rays, prim, t_sphere, rec, coherent=False):
    """:meth:`SceneGeometry.closest_hits` inside a kernel, for rays 0 .. ``prim.size`` - 1 of the
    :class:`cornell_harness.renderers.core.rays.RayBuffer` ``rays``: primitive ids into ``prim`` (-1: miss), sphere hits'
    distances into ``t_sphere`` (as long as ``prim``; empty in a scene without spheres). ``rec``:
    :func:`cornell_harness.renderers.core.embree.ray_record`. ``coherent``: camera rays, asked of Embree as
    rays that travel together (:func:`cornell_harness.renderers.core.embree.closest_triangles`).

    A renderer whose bounce loop is a kernel calls this instead of the method: each call of a kernel from
    Python costs ~0.3 ms of numba's argument typing when it takes the scene's tables (a named tuple of arrays),
    which was a fifth of the path tracer's time (BENCHMARKS.md).
    """
    closest_triangles(g.embree, rays.o32, rays.d32, prim, rec, coherent)
    if g.sphere_radius.size > 0:
        _nearer_spheres(prim, rays.o, rays.d, g, t_sphere)


@jit
def wavefront_hits(g, wf, rays, n, coherent=False):
    """The closest hits of rays 0 .. ``n`` - 1 of ``rays`` (``wf.cur`` or ``wf.nxt`` of the
    :class:`cornell_harness.renderers.core.rays.Wavefront` ``wf``), into ``wf``'s hit buffers: :func:`trace_closest`, as a
    :class:`Hits` of views. The first step of every bounce of a bounce loop that is one kernel; ``coherent``
    for its camera rays."""
    hits = Hits(wf.prim[:n], wf.t_sphere[:n])
    trace_closest(g, rays, hits.prim, hits.t_sphere, wf.record, coherent)
    return hits


@jit
def add_unoccluded_light(g, L, segments, visible, rec):
    """``L[path] +=`` what shadow segment k carries wherever nothing blocks it, for segments 0 ..
    ``visible.size`` - 1 (``visible`` is filled here): :func:`trace_unoccluded`, then
    :func:`cornell_harness.renderers.core.rays.add_unoccluded`."""
    trace_unoccluded(g, segments, visible, rec)
    add_unoccluded(L, segments, visible)


@jit
def trace_unoccluded(g, segments, visible, rec):
    """:meth:`SceneGeometry.unoccluded` inside a kernel: ``visible[k]`` for segments 0 .. ``visible.size`` - 1
    of the :class:`cornell_harness.renderers.core.rays.ShadowBuffer` ``segments``."""
    segments_clear(g.embree, segments.o, segments.d, segments.t, visible, rec)
    if g.sphere_radius.size > 0:
        _spheres_occlude(segments.o, segments.d, segments.t, g.sphere_center, g.sphere_radius, visible)


@jit
def _spheres_occlude(o, d, tfar, center, radius, visible):
    """Clear ``visible[k]`` where a sphere lies on segment k (float32 segments, float64 maths)."""
    for k in range(visible.size):
        if not visible[k]:
            continue
        ok = (np.float64(o[k, 0]), np.float64(o[k, 1]), np.float64(o[k, 2]))
        dk = (np.float64(d[k, 0]), np.float64(d[k, 1]), np.float64(d[k, 2]))
        for s in range(radius.size):
            if sphere_hit(center[s, 0], center[s, 1], center[s, 2], radius[s], ok, dk, np.float64(tfar[k])) < math.inf:
                visible[k] = False
                break


@jit
def surface_point(g, p, o, d, t_sphere):
    """Where the ray ``o + t·d`` meets primitive ``p``: (x, front-side unit normal n, cos_o = -d·n, t).

    ``cos_o`` is negative for a hit from behind. For a triangle, t is the
    distance to its plane (:func:`hit_distance`); for a sphere it is
    ``t_sphere`` from :meth:`SceneGeometry.closest_hits`, and x is moved
    onto the surface along the normal (pbrt-v4 §6.8.5's reprojection), so
    the ray offset is measured from the true surface.
    """
    if p < g.n_triangles:
        n = triangle_normal(g, p)
        cos_o = -(d[0] * n[0] + d[1] * n[1] + d[2] * n[2])
        t = hit_distance(g, p, o, d, cos_o)
        return (o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]), n, cos_o, t
    s = p - g.n_triangles
    cx, cy, cz, r = g.sphere_center[s, 0], g.sphere_center[s, 1], g.sphere_center[s, 2], g.sphere_radius[s]
    x0, x1, x2 = o[0] + t_sphere * d[0] - cx, o[1] + t_sphere * d[1] - cy, o[2] + t_sphere * d[2] - cz
    k = 1.0 / math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    n = (x0 * k, x1 * k, x2 * k)
    cos_o = -(d[0] * n[0] + d[1] * n[1] + d[2] * n[2])
    return (cx + r * n[0], cy + r * n[1], cz + r * n[2]), n, cos_o, t_sphere


@jit
def offset_origin(x, n, eps):
    """``x + eps·n``: where a ray leaving the surface at ``x`` on the side of ``n`` starts (no tnear)."""
    return x[0] + eps * n[0], x[1] + eps * n[1], x[2] + eps * n[2]


@jit
def ray_hit(g, rays, i, p, t_sphere):
    """Ray ``i`` of wavefront ``rays`` (:class:`cornell_harness.renderers.core.rays.RayBuffer`) hit primitive ``p`` ≥ 0:
    (d, x, n, cos_o, t, material), as :func:`surface_point` gives them, with the ray's direction ``d`` and
    the material id of ``p``. ``t_sphere`` is :meth:`SceneGeometry.closest_hits`' sphere distances.

    The prologue of every shading kernel. Whether the side hit can scatter is
    :func:`cornell_harness.renderers.core.bsdf.faces`.
    """
    d = (rays.d[i, 0], rays.d[i, 1], rays.d[i, 2])
    o = (rays.o[i, 0], rays.o[i, 1], rays.o[i, 2])
    x, n, cos_o, t = surface_point(g, p, o, d, t_sphere[i] if p >= g.n_triangles else 0.0)
    return d, x, n, cos_o, t, g.material[p]
