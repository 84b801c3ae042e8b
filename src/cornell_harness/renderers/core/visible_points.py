"""Visible points: camera paths followed through specular bounces to their first diffuse surface.

The camera pass of photon mapping (Jensen 2001 §9.1: "ray tracing" of
specular surfaces) and of SPPM (Hachisuka & Jensen 2009 §4.1; pbrt-v4
§16.2.1 ``SPPMIntegrator``, the "visible points"): a path leaves the camera,
is reflected and refracted by mirrors and glass (the BSDF sampled, Fresnel
choosing, Russian roulette as :mod:`cornell_harness.renderers.core.roulette`), and stops at the
first diffuse surface it meets. There the caller estimates the reflected
light from photons; this module adds what photons must not carry:

- emission seen along the way (the camera ray, or after specular bounces:
  no light sampling could have found it, so it counts with weight 1), and
  at the visible point itself;
- direct light at the visible point by next-event estimation (one emitter
  sample, no MIS: nothing else estimates L D(camera) paths), as pbrt-v4's
  SPPM does, so photons carry only indirect light and caustics.

Both are switched off for final-gathering rays, which reuse the walk
(:func:`walk_to_diffuse`). Every number comes from the pass's
:class:`cornell_harness.renderers.core.sampler.Stream` in its per-vertex layout, shifted by
``dim_base`` so a photon mapper's gather rays draw numbers of their own.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from cornell_harness.scenes.model import Scene
from cornell_harness.renderers.core.bsdf import bsdf_sample, faces, is_delta, lambert_pdf, lambert_sample, refraction_scale
from cornell_harness.renderers.core.camera import camera_basis, camera_rays
from cornell_harness.renderers.core.direct import sample_ld
from cornell_harness.renderers.core.geometry import SceneGeometry, add_unoccluded_light, offset_origin, ray_hit, wavefront_hits
from cornell_harness.renderers.core.rays import (RayBuffer, ShadowBuffer, Wavefront, set_path, set_ray, set_shadow,
                                 wavefront)
from cornell_harness.renderers.core.roulette import RR_DEPTH, continue_path
from cornell_harness.renderers.core.sampler import (BSDF_U, EMITTER_PICK, EMITTER_U, ROULETTE, Stream, gather_dim,
                                                    path_point, sample_1d, sample_2d, shifted_vertex_dim)
from cornell_harness.renderers.core.sampling import jit


class VisiblePoints(NamedTuple):
    """Where each path of a unit met its first diffuse surface (``found``), per path of the unit."""

    position: np.ndarray  # (m, 3) float64
    normal: np.ndarray  # (m, 3) float64 unit, the side the path arrived on
    weight: np.ndarray  # (m, 3) float64 β·ρ: the reflected radiance is weight/π · irradiance
    depth: np.ndarray  # (m,) int64 camera segments to the point
    found: np.ndarray  # (m,) bool
    incoming: np.ndarray  # (m, 3) float64 unit direction of the segment that reached the point
    distance: np.ndarray  # (m,) float64 the path's length from where the walk started (the camera) to the point


def visible_buffer(m: int) -> VisiblePoints:
    return VisiblePoints(np.zeros((m, 3)), np.zeros((m, 3)), np.zeros((m, 3)), np.zeros(m, np.int64),
                         np.zeros(m, bool), np.zeros((m, 3)), np.zeros(m))


class Walk(NamedTuple):
    """What every bounce of a walk shares: path j = ``first`` + path draws from ``stream``, its vertex
    dimensions shifted by ``dim_base``; whether it adds ``emission`` and ``nee``."""

    stream: Stream
    first: int
    dim_base: int
    emission: bool
    nee: bool


class Found(NamedTuple):
    """What a walk's bounces write: per path, the light found and the visible point; per bounce, the NEE
    shadow segments and the rays going on."""

    L: np.ndarray  # (paths, 3) float64
    vp: VisiblePoints
    shadow: ShadowBuffer
    nxt: RayBuffer


@jit
def _vertex_1d(walk, pt, depth, offset) -> float:
    return sample_1d(walk.stream, pt, shifted_vertex_dim(walk.dim_base, depth, offset))


@jit
def _vertex_2d(walk, pt, depth, offset):
    return sample_2d(walk.stream, pt, shifted_vertex_dim(walk.dim_base, depth, offset))


@jit
def _step(hits, rays, walk, depth, extend, roulette, geo, out):
    """One bounce: record diffuse hits as visible points (with NEE), continue specular ones.

    Returns (shadow segments, rays going on).
    """
    ns = 0
    nn = 0
    for i in range(hits.prim.size):
        p = hits.prim[i]
        if p < 0:
            continue
        d, x, n, cos_o, t, mat = ray_hit(geo, rays, i, p, hits.t_sphere)
        if not faces(mat, cos_o):
            continue
        q = rays.path[i]
        out.vp.distance[q] += t  # one live ray per path: its segments add up to the path's length
        beta = (rays.beta[i, 0], rays.beta[i, 1], rays.beta[i, 2])
        if walk.emission and geo.light_pdf_area[p] > 0.0 and cos_o > 0.0:
            for c in range(3):
                out.L[q, c] += beta[c] * geo.radiance[p, c]
        pt = path_point(walk.stream, walk.first + q)
        rho = (geo.reflectance[p, 0], geo.reflectance[p, 1], geo.reflectance[p, 2])
        if not is_delta(mat):
            vp = out.vp
            vp.found[q] = True
            vp.depth[q] = depth
            for c in range(3):
                vp.position[q, c] = x[c]
                vp.normal[q, c] = n[c]
                vp.weight[q, c] = beta[c] * rho[c]
                vp.incoming[q, c] = d[c]
            if walk.nee and extend:
                u = _vertex_2d(walk, pt, depth, EMITTER_U)
                found, a, sd, tfar, c = sample_ld(x, n, mat, (beta[0] * rho[0], beta[1] * rho[1], beta[2] * rho[2]),
                                                  (_vertex_1d(walk, pt, depth, EMITTER_PICK), u[0], u[1]), geo, False)
                if found:
                    set_shadow(out.shadow, ns, a, sd, tfar, q, c)
                    ns += 1
            continue
        if not extend:
            continue
        u = _vertex_2d(walk, pt, depth, BSDF_U)
        wi, cos_w, f, valid = bsdf_sample(mat, n, (-d[0], -d[1], -d[2]), cos_o, rho, geo.eta[p], u[0], u[1])
        scale = rays.scale[i] * refraction_scale(mat, cos_o, cos_w, geo.eta[p])
        alive, b, pdf = continue_path(mat, valid, cos_w, f, beta, scale,
                                      _vertex_1d(walk, pt, depth, ROULETTE) if roulette else 1.0, roulette)
        if alive:
            side = n if cos_w > 0.0 else (-n[0], -n[1], -n[2])
            set_ray(out.nxt, nn, offset_origin(x, side, geo.offset), wi)
            set_path(out.nxt, nn, q, b, pdf, scale)
            nn += 1
    return ns, nn


def walk_to_diffuse(geom: SceneGeometry, scene: Scene, rays: RayBuffer, stream: Stream, first: int,
                    depth: int = 1, dim_base: int = 0, emission: bool = True, nee: bool = True,
                    bounded: bool = True, paths: int | None = None) -> tuple[np.ndarray, VisiblePoints]:
    """Follow ``rays`` (their first segment is number ``depth``) to diffuse surfaces.

    Ray i belongs to path ``rays.path[i]`` of the unit (``paths`` of them,
    default one per ray). Returns, per path, the light found on the way
    (``emission``; ``nee``: direct light at the diffuse point, by
    :func:`cornell_harness.renderers.core.direct.sample_ld` without MIS) and the
    :class:`VisiblePoints`. Random numbers are drawn from ``stream`` for path
    ``first + path``, dimensions shifted by ``dim_base``. ``bounded=False``
    ignores the scene's max_depth (a caller that counts depth itself, from a
    later vertex).
    """
    wf = wavefront(len(rays.path), geom.has_spheres)
    for mine, theirs in zip(wf.cur, rays):  # the walk starts from a copy: the caller's buffer is never written
        mine[...] = theirs
    return _walk_from(geom, scene, wf, Walk(stream, first, dim_base, emission, nee), depth, bounded,
                      len(rays.path) if paths is None else paths)


def _walk_from(geom: SceneGeometry, scene: Scene, wf: Wavefront, walk: Walk, depth: int, bounded: bool,
               paths: int) -> tuple[np.ndarray, VisiblePoints]:
    """:func:`walk_to_diffuse` from the rays in ``wf.cur`` (all of them), which it overwrites."""
    L, vp = np.zeros((paths, 3)), visible_buffer(paths)
    geom.count(_walk(geom.tables(), walk, depth, scene.max_depth, scene.max_depth < 0 or not bounded, wf, L, vp))
    return L, vp


@jit
def _walk(geo, walk, depth, max_depth, unbounded, wf, L, vp):
    """The bounce loop of :func:`walk_to_diffuse` as one kernel, as :func:`cornell_harness.renderers.pathtracer._trace` (why
    there): per bounce the closest hits, :func:`_step`, and the NEE segments' queries, until no path is left.
    Returns the rays traced."""
    cur, nxt = wf.cur, wf.nxt  # double buffer: a bounce reads one wavefront, writes the next
    n, traced = cur.path.size, 0
    while n:
        hits = wavefront_hits(geo, wf, cur, n)
        extend = unbounded or depth + 1 <= max_depth
        ns, n_next = _step(hits, cur, walk, depth, extend, depth >= RR_DEPTH, geo, Found(L, vp, wf.shadow, nxt))
        traced += n + ns
        add_unoccluded_light(geo, L, wf.shadow, wf.visible[:ns], wf.record)
        cur, nxt = nxt, cur
        n = n_next
        depth += 1
    return traced


def camera_visible_points(geom: SceneGeometry, scene: Scene, first: int, stop: int, pixels: int,
                          stream: Stream) -> tuple[np.ndarray, VisiblePoints]:
    """Camera paths ``first .. stop-1`` of a pass (path j sees pixel j mod ``pixels``) to their visible points,
    their numbers drawn from the pass's ``stream``."""
    cam = scene.camera
    wf = wavefront(stop - first, geom.has_spheres)
    camera_rays(camera_basis(cam), cam.width, cam.height, first, pixels, stream, wf.cur)
    return _walk_from(geom, scene, wf, Walk(stream, first, dim_base=0, emission=True, nee=True), depth=1,
                      bounded=True, paths=stop - first)


@jit
def gather_rays(vp, stream, first, g, count, offset, rays):
    """Gather ray ``g`` (of ``count``) from each found visible point into ``rays``, cosine-weighted; returns
    how many.

    Ray r carries path = its visible point's index and throughput weight/``count``
    (the weight of Lambert's cosine sample is ρ, already in ``weight``), and
    the sample's pdf; it draws its direction from the sampler's
    :func:`cornell_harness.renderers.core.sampler.gather_dim` of path
    ``first + index`` of ``stream``.
    """
    r = 0
    for i in range(vp.found.size):
        if not vp.found[i]:
            continue
        n = (vp.normal[i, 0], vp.normal[i, 1], vp.normal[i, 2])
        u = sample_2d(stream, path_point(stream, first + i), gather_dim(g))
        dx, dy, dz, cos = lambert_sample(n, u[0], u[1])
        if not cos > 0.0:
            continue
        x = (vp.position[i, 0], vp.position[i, 1], vp.position[i, 2])
        set_ray(rays, r, offset_origin(x, n, offset), (dx, dy, dz))
        set_path(rays, r, i, (vp.weight[i, 0] / count, vp.weight[i, 1] / count, vp.weight[i, 2] / count),
                 lambert_pdf(cos))
        r += 1
    return r
