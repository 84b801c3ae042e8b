"""Visible points: camera paths followed through specular bounces to their first diffuse surface.

The camera pass of photon mapping (Jensen 2001 §9.1: "ray tracing" of
specular surfaces) and of SPPM (Hachisuka & Jensen 2009 §4.1; pbrt-v4
§16.2.1 ``SPPMIntegrator``, the "visible points"): a path leaves the camera,
is reflected and refracted by mirrors and glass (the BSDF sampled, Fresnel
choosing, Russian roulette as :mod:`renderers.core.roulette`), and stops at the
first diffuse surface it meets. There the caller estimates the reflected
light from photons; this module adds what photons must not carry:

- emission seen along the way (the camera ray, or after specular bounces:
  no light sampling could have found it, so it counts with weight 1), and
  at the visible point itself;
- direct light at the visible point by next-event estimation (one emitter
  sample, no MIS: nothing else estimates L D(camera) paths), as pbrt-v4's
  SPPM does, so photons carry only indirect light and caustics.

Both are switched off for final-gathering rays, which reuse the walk
(:func:`walk_to_diffuse`). Sample dimensions are :mod:`renderers.core.sampler`'s
per-vertex layout, shifted by ``dim_base`` so a photon mapper's gather rays
draw numbers of their own.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from harness.scenes.model import Scene
from renderers.core.bsdf import (LAMBERT, bsdf_eval, bsdf_sample, is_delta, lambert_pdf, lambert_sample,
                                 refraction_scale, two_sided)
from renderers.core.camera import camera_basis, camera_rays
from renderers.core.geometry import SceneGeometry, offset_origin, surface_point
from renderers.core.lights import sample_emitter, towards_emitter
from renderers.core.rays import (RayBuffer, add_unoccluded, head, ray_buffer, set_path, set_ray, set_shadow,
                                 shadow_buffer, shadow_segment)
from renderers.core.rng import uniform
from renderers.core.roulette import RR_DEPTH, continue_path
from renderers.core.sampler import BSDF_U, BSDF_V, EMITTER_PICK, EMITTER_U, EMITTER_V, ROULETTE, independent, vertex_dim
from renderers.core.sampling import jit


class VisiblePoints(NamedTuple):
    """Where each path of a unit met its first diffuse surface (``found``), per path of the unit."""

    position: np.ndarray  # (m, 3) float64
    normal: np.ndarray  # (m, 3) float64 unit, the side the path arrived on
    weight: np.ndarray  # (m, 3) float64 β·ρ: the reflected radiance is weight/π · irradiance
    depth: np.ndarray  # (m,) int64 camera segments to the point
    found: np.ndarray  # (m,) bool
    incoming: np.ndarray  # (m, 3) float64 unit direction of the segment that reached the point


def visible_buffer(m: int) -> VisiblePoints:
    return VisiblePoints(np.zeros((m, 3)), np.zeros((m, 3)), np.zeros((m, 3)), np.zeros(m, np.int64),
                         np.zeros(m, bool), np.zeros((m, 3)))


@jit
def _u(key, j, dim_base, depth, offset):
    return uniform(key, j, dim_base + vertex_dim(depth, offset))


@jit
def _step(prim, t_sphere, rays, key, first, dim_base, depth, emission, nee, extend, roulette, geo, L, vp,
          shadow, nxt):
    """One bounce: record diffuse hits as visible points (with NEE), continue specular ones.

    Returns (shadow segments, rays going on).
    """
    ns = 0
    nn = 0
    for i in range(prim.size):
        p = prim[i]
        if p < 0:
            continue
        d = (rays.d[i, 0], rays.d[i, 1], rays.d[i, 2])
        o = (rays.o[i, 0], rays.o[i, 1], rays.o[i, 2])
        x, n, cos_o, t = surface_point(geo, p, o, d, t_sphere[i] if p >= geo.n_triangles else 0.0)
        mat = geo.material[p]
        if not (cos_o > 0.0 or (cos_o < 0.0 and two_sided(mat))):
            continue
        q = rays.path[i]
        beta = (rays.beta[i, 0], rays.beta[i, 1], rays.beta[i, 2])
        if emission and geo.light_pdf_area[p] > 0.0 and cos_o > 0.0:
            for c in range(3):
                L[q, c] += beta[c] * geo.radiance[p, c]
        j = first + q
        rho = (geo.reflectance[p, 0], geo.reflectance[p, 1], geo.reflectance[p, 2])
        if not is_delta(mat):
            vp.found[q] = True
            vp.depth[q] = depth
            for c in range(3):
                vp.position[q, c] = x[c]
                vp.normal[q, c] = n[c]
                vp.weight[q, c] = beta[c] * rho[c]
                vp.incoming[q, c] = d[c]
            if nee and extend and geo.emitter_ids.size > 0:
                y, ny, e, pe = sample_emitter(_u(key, j, dim_base, depth, EMITTER_PICK),
                                              _u(key, j, dim_base, depth, EMITTER_U),
                                              _u(key, j, dim_base, depth, EMITTER_V), geo)
                wi, dist2, cos_x, cos_y = towards_emitter(x, n, y, ny)
                if cos_x > 0.0 and pe > 0.0:
                    g = cos_x * cos_y / dist2 / pe
                    a = offset_origin(x, n, geo.offset)
                    sd, tfar, sl = shadow_segment(a, offset_origin(y, ny, geo.offset))
                    if sl > 0.0:
                        set_shadow(shadow, ns, a, sd, tfar, q)
                        for c in range(3):
                            shadow.c[ns, c] = bsdf_eval(LAMBERT, beta[c] * rho[c], cos_x) * geo.radiance[e, c] * g
                        ns += 1
            continue
        if not extend:
            continue
        wi, cos_w, f, valid = bsdf_sample(mat, n, (-d[0], -d[1], -d[2]), cos_o, rho, geo.eta[p],
                                          _u(key, j, dim_base, depth, BSDF_U), _u(key, j, dim_base, depth, BSDF_V))
        scale = rays.scale[i] * refraction_scale(mat, cos_o, cos_w, geo.eta[p])
        alive, b, pdf = continue_path(mat, valid, cos_w, f, beta, scale,
                                      _u(key, j, dim_base, depth, ROULETTE) if roulette else 1.0, roulette)
        if alive:
            side = n if cos_w > 0.0 else (-n[0], -n[1], -n[2])
            set_ray(nxt, nn, offset_origin(x, side, geo.offset), wi)
            set_path(nxt, nn, q, b, pdf, scale)
            nn += 1
    return ns, nn


def walk_to_diffuse(geom: SceneGeometry, scene: Scene, rays: RayBuffer, key: np.uint64, first: int,
                    depth: int = 1, dim_base: int = 0, emission: bool = True, nee: bool = True,
                    bounded: bool = True, paths: int | None = None) -> tuple[np.ndarray, VisiblePoints]:
    """Follow ``rays`` (their first segment is number ``depth``) to diffuse surfaces.

    Ray i belongs to path ``rays.path[i]`` of the unit (``paths`` of them,
    default one per ray). Returns, per path, the light found on the way
    (``emission``; ``nee``: direct light at the diffuse point) and the
    :class:`VisiblePoints`. Random numbers are drawn for path ``first + path``,
    dimensions shifted by ``dim_base``. ``bounded=False`` ignores the scene's
    max_depth (a caller that counts depth itself, from a later vertex).
    """
    m = len(rays.path)
    paths = m if paths is None else paths
    geo = geom.tables()
    L = np.zeros((paths, 3))
    vp = visible_buffer(paths)
    cur, nxt = rays, ray_buffer(m)
    shadow = shadow_buffer(m)
    unbounded = scene.max_depth < 0 or not bounded
    n = m
    while n:
        live = head(cur, n)
        prim, t_sphere = geom.closest_hits(live)
        extend = unbounded or depth + 1 <= scene.max_depth
        ns, n = _step(prim, t_sphere, live, key, first, dim_base, depth, emission, nee, extend, depth >= RR_DEPTH,
                      geo, L, vp, shadow, nxt)
        if ns:
            seg = head(shadow, ns)
            add_unoccluded(L, seg, geom.unoccluded(seg.o, seg.d, seg.t))
        if cur is rays:
            cur = ray_buffer(m)  # the caller's buffer is read once, never written
        cur, nxt = nxt, cur
        depth += 1
    return L, vp


def camera_visible_points(geom: SceneGeometry, scene: Scene, first: int, stop: int, pixels: int,
                          key: np.uint64) -> tuple[np.ndarray, VisiblePoints]:
    """Camera paths ``first .. stop-1`` of a pass (path j sees pixel j mod ``pixels``) to their visible points."""
    cam = scene.camera
    rays = ray_buffer(stop - first)
    camera_rays(camera_basis(cam), cam.width, cam.height, first, pixels, independent(key), rays)
    return walk_to_diffuse(geom, scene, rays, key, first)


@jit
def gather_rays(vp, key, first, dim, count, offset, rays):
    """One cosine-weighted ray from each found visible point into ``rays``; returns how many.

    Ray r carries path = its visible point's index and throughput weight/``count``
    (the weight of Lambert's cosine sample is ρ, already in ``weight``), and
    the sample's pdf; it uses dimensions ``dim`` and ``dim + 1`` of the path.
    """
    r = 0
    for i in range(vp.found.size):
        if not vp.found[i]:
            continue
        n = (vp.normal[i, 0], vp.normal[i, 1], vp.normal[i, 2])
        dx, dy, dz, cos = lambert_sample(n, uniform(key, first + i, dim), uniform(key, first + i, dim + 1))
        if not cos > 0.0:
            continue
        x = (vp.position[i, 0], vp.position[i, 1], vp.position[i, 2])
        set_ray(rays, r, offset_origin(x, n, offset), (dx, dy, dz))
        set_path(rays, r, i, (vp.weight[i, 0] / count, vp.weight[i, 1] / count, vp.weight[i, 2] / count),
                 lambert_pdf(cos))
        r += 1
    return r
