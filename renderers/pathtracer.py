"""Unidirectional path tracing with next-event estimation and MIS, on Embree.

The estimator is the standard one of Veach 1997 (thesis §9.2) as in
pbrt-v4 §13.4 (``PathIntegrator``), for one-sided Lambertian surfaces and
one-sided diffuse area emitters:

- **Next-event estimation**: at each surface vertex an emitter triangle is
  picked in proportion to its power and a point on it uniformly by area
  (:meth:`SceneGeometry.sample_emitter`); the area pdf is converted to solid
  angle, ``p_ω = p_A · r² / cos θ_y``.
- **BSDF sampling**: cosine-weighted directions (pdf cos θ / π), which for a
  Lambertian BRDF ρ/π make the throughput update exactly ρ.
- **MIS**: both strategies are weighted by the power heuristic (β = 2,
  Veach eq. 9.13). Emission found by a BSDF-sampled ray is weighted against
  the NEE pdf of that point; emission seen by the camera ray is not weighted.
- **Russian roulette** from the :data:`RR_DEPTH`-th vertex on: a path goes on
  with probability ``q = min(max_c β_c, Q_MAX)`` and its throughput is
  divided by ``q``, so the estimate stays unbiased (pbrt-v4 §13.1.5 uses the
  same rule; Mitsuba 3 too, with 0.95). Capping ``q`` at ``Q_MAX < 1`` ends
  every path with probability 1 even when every albedo is 1: the expected
  length past ``RR_DEPTH`` is at most ``1 / (1 - Q_MAX)`` = 20 vertices.
- ``max_depth`` is the harness's convention (segments from the camera;
  -1 unbounded): emission at vertex k counts if k ≤ max_depth, NEE at vertex
  k adds a segment and counts if k + 1 ≤ max_depth.

Robustness: maths in float64; every pdf division is guarded (a zero pdf
gives a zero contribution, never NaN or Inf); a surface hit from its back
side reflects nothing and ends the path (one-sided BSDF, as Mitsuba's
``diffuse``).
"""

from __future__ import annotations

import math
import time
from typing import Sequence

import numpy as np

from harness.adapters.registry import RenderResult
from harness.adapters.settings import Setting
from harness.scenes.model import Scene
from renderers.core.geometry import SceneGeometry
from renderers.core.rng import uniform
from renderers.core.sampling import (INV_PI, camera_basis, camera_ray, cosine_hemisphere, jit, power_heuristic,
                                     triangle_barycentrics)
from renderers.core.wavefront import render_wavefront

RR_DEPTH = 5
Q_MAX = 0.99
#: Random dimensions per vertex: emitter choice, 2 for the point on it, 2 for the BSDF direction, RR.
_DIMS = 6


class _Rays:
    """A wavefront's ray buffers: float64 for shading, float32 copies for embreex."""

    def __init__(self, m: int):
        self.o, self.d = np.empty((m, 3)), np.empty((m, 3))
        self.o32, self.d32 = np.empty((m, 3), np.float32), np.empty((m, 3), np.float32)
        self.path = np.empty(m, np.int64)
        self.beta = np.empty((m, 3))
        self.pdf = np.empty(m)  # solid-angle pdf of the BSDF sample that made the ray (0: camera ray)

    def fields(self):
        return self.o, self.d, self.o32, self.d32, self.path, self.beta, self.pdf


@jit
def _camera_rays(basis, width, height, first, pixels, key, o, d, o32, d32, path, beta, pdf):
    """Camera rays for paths first .. first + len(path) - 1 (path j sees pixel j mod pixels)."""
    for i in range(path.size):
        j = first + i
        d0, d1, d2 = camera_ray(basis, width, height, j % pixels, uniform(key, j, 0), uniform(key, j, 1))
        for c in range(3):
            o[i, c] = basis[0, c]
            o32[i, c] = basis[0, c]
            beta[i, c] = 1.0
        d[i, 0], d[i, 1], d[i, 2] = d0, d1, d2
        d32[i, 0], d32[i, 1], d32[i, 2] = d0, d1, d2
        path[i] = i
        pdf[i] = 0.0


@jit
def _shade(prim, o, d, path, beta, pdf_bsdf, key, first, depth, extend, roulette,
           v0, e1, e2, nrm, rho, le, light_pdf_area, emitter_ids, emitter_cdf, eps,
           L, sh_o, sh_d, sh_t, sh_path, sh_c, nx_o, nx_d, nx_o32, nx_d32, nx_path, nx_beta, nx_pdf):
    """Shade one bounce of a wavefront.

    For each ray that hit a surface (``prim >= 0``): add the emission it found
    (MIS-weighted except for camera rays, depth 1); then, if ``extend``
    (max_depth allows another segment), make one NEE shadow ray (``sh_*``:
    float32 origin, direction, tfar; path; unoccluded contribution) and one
    continuation ray (``nx_*``), with Russian roulette if ``roulette``.
    ``path`` holds indices local to the unit; random numbers are drawn for
    path ``first + path``, its index in the pass. Returns (shadow rays, next rays).
    """
    ns = 0
    nn = 0
    n_emit = emitter_ids.size
    dim0 = 2 + (depth - 1) * 6  # this vertex's random dimensions (2 went to the camera ray)
    for i in range(prim.size):
        p = prim[i]
        if p < 0:
            continue
        dx, dy, dz = d[i, 0], d[i, 1], d[i, 2]
        n0, n1, n2 = nrm[p, 0], nrm[p, 1], nrm[p, 2]
        cos_o = -(dx * n0 + dy * n1 + dz * n2)
        if cos_o <= 0.0:
            continue  # back side (or grazing): one-sided emitters and BSDFs give nothing, the path ends
        # Distance to the triangle's plane in float64 (Embree gave the triangle).
        ti = ((v0[p, 0] - o[i, 0]) * n0 + (v0[p, 1] - o[i, 1]) * n1 + (v0[p, 2] - o[i, 2]) * n2) / -cos_o
        if ti < 0.0:
            ti = 0.0
        x0, x1, x2 = o[i, 0] + ti * dx, o[i, 1] + ti * dy, o[i, 2] + ti * dz
        q = path[i]
        j = first + q
        pa = light_pdf_area[p]
        if pa > 0.0:
            w = 1.0 if depth == 1 else power_heuristic(pdf_bsdf[i], pa * ti * ti / cos_o)
            for c in range(3):
                L[q, c] += beta[i, c] * le[p, c] * w
        if not extend:
            continue

        # Next-event estimation: a point on an emitter triangle chosen by power.
        if n_emit > 0:
            k = min(np.searchsorted(emitter_cdf, uniform(key, j, dim0), side="right"), n_emit - 1)
            e = emitter_ids[k]
            b1, b2 = triangle_barycentrics(uniform(key, j, dim0 + 1), uniform(key, j, dim0 + 2))
            y0 = v0[e, 0] + b1 * e1[e, 0] + b2 * e2[e, 0]
            y1 = v0[e, 1] + b1 * e1[e, 1] + b2 * e2[e, 1]
            y2 = v0[e, 2] + b1 * e1[e, 2] + b2 * e2[e, 2]
            w0, w1, w2 = y0 - x0, y1 - x1, y2 - x2
            dist2 = w0 * w0 + w1 * w1 + w2 * w2
            pe = light_pdf_area[e]
            if dist2 > 0.0 and pe > 0.0:
                dist = math.sqrt(dist2)
                w0, w1, w2 = w0 / dist, w1 / dist, w2 / dist
                cos_x = n0 * w0 + n1 * w1 + n2 * w2
                cos_y = -(nrm[e, 0] * w0 + nrm[e, 1] * w1 + nrm[e, 2] * w2)
                if cos_x > 0.0 and cos_y > 0.0:
                    # Shadow ray between the two offset points, stopping short of the light.
                    a0, a1, a2 = x0 + eps * n0, x1 + eps * n1, x2 + eps * n2
                    s0 = y0 + eps * nrm[e, 0] - a0
                    s1 = y1 + eps * nrm[e, 1] - a1
                    s2 = y2 + eps * nrm[e, 2] - a2
                    sl = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
                    if sl > 0.0:
                        w = power_heuristic(pe * dist2 / cos_y, cos_x * INV_PI)
                        g = cos_x * cos_y / dist2 * w / pe
                        sh_o[ns, 0], sh_o[ns, 1], sh_o[ns, 2] = a0, a1, a2
                        sh_d[ns, 0], sh_d[ns, 1], sh_d[ns, 2] = s0 / sl, s1 / sl, s2 / sl
                        sh_t[ns] = sl * (1.0 - 1e-6)
                        sh_path[ns] = q
                        for c in range(3):
                            sh_c[ns, c] = beta[i, c] * rho[p, c] * INV_PI * le[e, c] * g
                        ns += 1

        # BSDF sampling: for cosine-weighted Lambertian, f·cos/pdf = ρ.
        wx, wy, wz, cos_w = cosine_hemisphere(n0, n1, n2, uniform(key, j, dim0 + 3), uniform(key, j, dim0 + 4))
        if cos_w <= 0.0:
            continue  # zero-pdf direction
        b0, b1_, b2_ = beta[i, 0] * rho[p, 0], beta[i, 1] * rho[p, 1], beta[i, 2] * rho[p, 2]
        bmax = max(b0, b1_, b2_)
        if bmax <= 0.0:
            continue
        if roulette:
            survive = min(bmax, Q_MAX)
            # Written so a NaN throughput ends the path (NaN < x is false): its NaN
            # has already reached L, where the NaN count reports it.
            if not uniform(key, j, dim0 + 5) < survive:
                continue
            b0, b1_, b2_ = b0 / survive, b1_ / survive, b2_ / survive
        ox, oy, oz = x0 + eps * n0, x1 + eps * n1, x2 + eps * n2
        nx_o[nn, 0], nx_o[nn, 1], nx_o[nn, 2] = ox, oy, oz
        nx_o32[nn, 0], nx_o32[nn, 1], nx_o32[nn, 2] = ox, oy, oz
        nx_d[nn, 0], nx_d[nn, 1], nx_d[nn, 2] = wx, wy, wz
        nx_d32[nn, 0], nx_d32[nn, 1], nx_d32[nn, 2] = wx, wy, wz
        nx_path[nn] = q
        nx_beta[nn, 0], nx_beta[nn, 1], nx_beta[nn, 2] = b0, b1_, b2_
        nx_pdf[nn] = cos_w * INV_PI
        nn += 1
    return ns, nn


@jit
def _add_visible(L, sh_path, sh_c, visible):
    for j in range(sh_path.size):
        if visible[j]:
            for c in range(3):
                L[sh_path[j], c] += sh_c[j, c]


def trace_paths(geom: SceneGeometry, scene: Scene, first: int, stop: int, pixels: int, key: np.uint64,
                rr_depth: int = RR_DEPTH) -> np.ndarray:
    """Radiance estimates (m, 3) for paths ``first .. stop-1`` (path j sees pixel j mod ``pixels``)."""
    m = stop - first
    cam = scene.camera
    unbounded = scene.max_depth < 0
    g = geom
    tables = (g.v0, g.e1, g.e2, g.normal, g.reflectance, g.radiance, g.light_pdf_area, g.emitter_ids,
              g.emitter_cdf, g.offset)
    L = np.zeros((m, 3))
    cur, nxt = _Rays(m), _Rays(m)  # double buffer: shade reads one wavefront, writes the next
    sh_o, sh_d = np.empty((m, 3), np.float32), np.empty((m, 3), np.float32)
    sh_t, sh_path, sh_c = np.empty(m, np.float32), np.empty(m, np.int64), np.empty((m, 3))
    _camera_rays(camera_basis(cam), cam.width, cam.height, first, pixels, key, *cur.fields())
    n, depth = m, 1  # live rays; segments so far, the current ray included
    while n:
        prim = geom.intersect(cur.o32[:n], cur.d32[:n])
        extend = unbounded or depth + 1 <= scene.max_depth
        o, d, _, _, path, beta, pdf = (a[:n] for a in cur.fields())
        ns, n = _shade(prim, o, d, path, beta, pdf, key, first, depth, extend, depth >= rr_depth,
                       *tables, L, sh_o, sh_d, sh_t, sh_path, sh_c, *nxt.fields())
        if ns:
            _add_visible(L, sh_path[:ns], sh_c[:ns], geom.unoccluded(sh_o[:ns], sh_d[:ns], sh_t[:ns]))
        cur, nxt = nxt, cur
        depth += 1
    return L


class PathTracer:
    """Our path tracer (embreex, vectorised wavefront, multithreaded)."""

    name = "pathtracer"
    features = frozenset({"triangle_mesh", "diffuse", "area_light", "pinhole_camera", "box_filter"})
    approximations: tuple[str, ...] = ()
    settings = (Setting("rr_depth", int, RR_DEPTH, "path vertex from which Russian roulette may end a path",
                        low=1, high=1000),)

    def __init__(self, threads: int | None = None):
        self.threads = threads

    def unavailable_reason(self) -> str | None:
        try:
            import embreex  # noqa: F401
        except ImportError as e:
            return f"embreex is not installed ({e}); pip install embreex"
        return None

    def version(self) -> str:
        from importlib.metadata import version

        return f"cornell-harness {version('cornell-harness')} (embreex {version('embreex')})"

    def render(self, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = (),
               settings: dict | None = None) -> RenderResult:
        rr_depth = (settings or {}).get("rr_depth", RR_DEPTH)
        t0 = time.perf_counter()
        geom = SceneGeometry(scene)
        # Compile (or load from numba's cache) before the clock starts.
        trace_paths(geom, scene, 0, 1, 1, np.uint64(0), rr_depth)
        geom.rays = 0
        setup_s = time.perf_counter() - t0
        result = render_wavefront(scene, spp, seed, lambda *unit: trace_paths(geom, scene, *unit, rr_depth),
                                  checkpoints, self.threads, {"rr_depth": rr_depth, "rr_q_max": Q_MAX})
        result.info.update(rays=geom.rays, setup_s=round(setup_s, 3))
        return result
