"""The kernels of ``benchmarks/shading_soa.py``: one bounce of the path tracer's shading for Lambertian
triangles, path by path and as loops over arrays, and the draws of its random numbers.

Everything here is the benchmark's prototype, written out from the toolkit's functions (the module docstring of
``benchmarks/shading_soa.py`` says why and how it is checked against the kernel, bit for bit).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from cornell_harness.renderers import pathtracer
from cornell_harness.renderers.core.geometry import Hits
from cornell_harness.renderers.core.rays import SHADOW_TFAR_REL
from cornell_harness.renderers.core.rng import uniform
from cornell_harness.renderers.core.roulette import Q_MAX
from cornell_harness.renderers.core.sampler import (BSDF_U, EMITTER_PICK, EMITTER_U, ROULETTE, path_point, vertex_1d,
                                                    vertex_2d, vertex_dim)

INV_PI = 1.0 / math.pi
TWO_PI = 2.0 * math.pi
#: The loops of (d), in the order they run.
LOOPS = ("fetch hits", "surface and emission", "add emission", "pick emitters", "light sample",
         "BSDF sample and roulette", "write buffers")
ALL_LOOPS = (1 << len(LOOPS)) - 1
jit = numba.njit(nogil=True, error_model="numpy")
#: For the small helpers of the loops: inlined by numba, so a loop's fast-math flags reach them and no call is
#: left in the loop for the vectoriser to refuse.
jit_inline = numba.njit(nogil=True, error_model="numpy", inline="always")


#: A lane's state in (d), one float64 array per name (bool: ``live``, ``emits``, ``found``, ``alive``; int64:
#: ``q``), what one loop writes and the next reads: the path ``q``, the ray (``o``, ``d``), the primitive hit (its
#: normal ``n``, first vertex ``v``, reflectance ``r``, NEE's area pdf ``pa``, emission ``le``, then the emission
#: found), the throughput ``b``, the ray's ``pdf`` and ``scale``, the hit point ``x``; the emitter picked (its
#: first vertex ``y``, then the point on it; edges ``f`` and ``h``, normal ``m``, area pdf ``pe``, radiance ``c``,
#: then the segment's contribution), the shadow segment (origin ``a``, direction ``s``, ``tfar``); the next ray
#: (direction ``w``, throughput ``nb``, ``npdf``, origin ``no``).
LANE_FIELDS = ("live q o0 o1 o2 d0 d1 d2 n0 n1 n2 v0 v1 v2 b0 b1 b2 r0 r1 r2 pdf scale pa le0 le1 le2 x0 x1 x2 emits "
               "y0 y1 y2 f0 f1 f2 h0 h1 h2 m0 m1 m2 pe c0 c1 c2 found a0 a1 a2 s0 s1 s2 tfar "
               "alive w0 w1 w2 nb0 nb1 nb2 npdf no0 no1 no2").split()
Lanes = NamedTuple("Lanes", [(f, np.ndarray) for f in LANE_FIELDS])
_BOOL, _INT = {"live", "emits", "found", "alive"}, {"q"}


def lanes(m: int) -> Lanes:
    return Lanes(*(np.zeros(m, np.bool_ if f in _BOOL else np.int64 if f in _INT else np.float64)
                   for f in Lanes._fields))


class Draws(NamedTuple):
    """A lane's six numbers of its vertex (:mod:`cornell_harness.renderers.core.sampler`'s offsets)."""

    pick: np.ndarray
    u1: np.ndarray
    u2: np.ndarray
    w1: np.ndarray
    w2: np.ndarray
    rr: np.ndarray


def draws(m: int) -> Draws:
    return Draws(*(np.zeros(m) for _ in Draws._fields))


# -- (b) the draws ---------------------------------------------------------------------------------------

@jit
def draw_per_path(reps, prim, path, stream, first, depth, roulette, u):
    """(b): lane i's numbers by the sampler, one path at a time, as :func:`pathtracer._shade` draws them."""
    for _ in range(reps):
        for i in range(prim.size):
            if prim[i] < 0:
                continue
            pt = path_point(stream, first + path[i])
            u.pick[i] = vertex_1d(stream, pt, depth, EMITTER_PICK)
            u.u1[i], u.u2[i] = vertex_2d(stream, pt, depth, EMITTER_U)
            u.w1[i], u.w2[i] = vertex_2d(stream, pt, depth, BSDF_U)
            u.rr[i] = vertex_1d(stream, pt, depth, ROULETTE) if roulette else 1.0


@jit
def draw_independent_soa(reps, path, key, first, depth, roulette, u):
    """(b) for ``independent``, as one array loop: a counter hash of (key, path, dimension) per number."""
    base = vertex_dim(depth, 0)
    for _ in range(reps):
        for i in range(path.size):
            j = first + path[i]
            u.pick[i] = uniform(key, j, base + EMITTER_PICK)
            u.u1[i] = uniform(key, j, base + EMITTER_U)
            u.u2[i] = uniform(key, j, base + EMITTER_U + 1)
            u.w1[i] = uniform(key, j, base + BSDF_U)
            u.w2[i] = uniform(key, j, base + BSDF_U + 1)
            u.rr[i] = uniform(key, j, base + ROULETTE) if roulette else 1.0


# -- (a) the kernel, and (c) its shading one path at a time ------------------------------------------------

@jit
def shade_kernel(reps, prim, t_sphere, rays, stream, first, depth, roulette, geo, paths, out):
    """(a): :func:`pathtracer._shade` ``reps`` times (all live paths extend)."""
    ns = nn = 0
    for _ in range(reps):
        ns, nn = pathtracer._shade(Hits(prim, t_sphere), rays, stream, first, depth, True, roulette, geo, paths,
                                   out)
    return ns, nn


@jit
def shade_per_path(reps, prim, rays, u, roulette, geo, L, shadow, nxt, poly):
    """(c): ``_shade``'s work for Lambertian triangles with the numbers ``u``, one path at a time: the same
    operations in the same order (so the same bits), the scene's tables read in place. ``poly``: cos and sin
    of the BSDF sample by :func:`_cos_sin_turns`."""
    ns = nn = 0
    off, ne = geo.offset, geo.emitter_ids.size
    for _ in range(reps):
        ns = nn = 0
        for i in range(prim.size):
            p = prim[i]
            if p < 0:
                continue
            d0, d1, d2 = rays.d[i, 0], rays.d[i, 1], rays.d[i, 2]
            o0, o1, o2 = rays.o[i, 0], rays.o[i, 1], rays.o[i, 2]
            n0, n1, n2 = geo.normal[p, 0], geo.normal[p, 1], geo.normal[p, 2]
            cos_o = -(d0 * n0 + d1 * n1 + d2 * n2)
            if not cos_o > 0.0:
                continue
            t = ((geo.v0[p, 0] - o0) * n0 + (geo.v0[p, 1] - o1) * n1 + (geo.v0[p, 2] - o2) * n2) / -cos_o
            t = 0.0 if t < 0.0 else t
            x0, x1, x2 = o0 + t * d0, o1 + t * d1, o2 + t * d2
            q = rays.path[i]
            b0, b1, b2 = rays.beta[i, 0], rays.beta[i, 1], rays.beta[i, 2]
            pa = geo.light_pdf_area[p]
            if pa > 0.0 and cos_o > 0.0:
                w = _emission_weight(rays.pdf[i], pa, t, cos_o)
                L[q, 0] += b0 * geo.radiance[p, 0] * w
                L[q, 1] += b1 * geo.radiance[p, 1] * w
                L[q, 2] += b2 * geo.radiance[p, 2] * w
            r0, r1, r2 = geo.reflectance[p, 0], geo.reflectance[p, 1], geo.reflectance[p, 2]
            if ne > 0:
                e = geo.emitter_ids[min(np.searchsorted(geo.emitter_cdf, u.pick[i], side="right"), ne - 1)]
                su = math.sqrt(u.u1[i])
                e1, e2 = su * (1.0 - u.u2[i]), su * u.u2[i]
                y0 = geo.v0[e, 0] + e1 * geo.e1[e, 0] + e2 * geo.e2[e, 0]
                y1 = geo.v0[e, 1] + e1 * geo.e1[e, 1] + e2 * geo.e2[e, 1]
                y2 = geo.v0[e, 2] + e1 * geo.e1[e, 2] + e2 * geo.e2[e, 2]
                m0, m1, m2 = geo.normal[e, 0], geo.normal[e, 1], geo.normal[e, 2]
                pe = geo.light_pdf_area[e]
                w0, w1, w2 = y0 - x0, y1 - x1, y2 - x2
                dist2 = w0 * w0 + w1 * w1 + w2 * w2
                if dist2 > 0.0 and pe > 0.0:
                    dist = math.sqrt(dist2)
                    w0, w1, w2 = w0 / dist, w1 / dist, w2 / dist
                    cos_x = n0 * w0 + n1 * w1 + n2 * w2
                    cos_y = -(m0 * w0 + m1 * w1 + m2 * w2)
                    if cos_x > 0.0 and cos_y > 0.0:
                        g = cos_x * cos_y / dist2 * _power(pe * dist2 / cos_y, cos_x * INV_PI) / pe
                        a0, a1, a2 = x0 + off * n0, x1 + off * n1, x2 + off * n2
                        s0, s1, s2 = y0 + off * m0 - a0, y1 + off * m1 - a1, y2 + off * m2 - a2
                        sl = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
                        if sl > 0.0:
                            shadow.c[ns, 0] = b0 * r0 * INV_PI * geo.radiance[e, 0] * g
                            shadow.c[ns, 1] = b1 * r1 * INV_PI * geo.radiance[e, 1] * g
                            shadow.c[ns, 2] = b2 * r2 * INV_PI * geo.radiance[e, 2] * g
                            shadow.o[ns, 0], shadow.o[ns, 1], shadow.o[ns, 2] = a0, a1, a2
                            shadow.d[ns, 0], shadow.d[ns, 1], shadow.d[ns, 2] = s0 / sl, s1 / sl, s2 / sl
                            shadow.t[ns] = sl * SHADOW_TFAR_REL
                            shadow.path[ns] = q
                            ns += 1
            if poly:
                c0, c1, c2, lz = _cosine_direction_poly(n0, n1, n2, u.w1[i], u.w2[i])
            else:
                c0, c1, c2, lz = _cosine_direction(n0, n1, n2, u.w1[i], u.w2[i])
            if not lz > 0.0:
                continue
            b0, b1, b2 = b0 * r0, b1 * r1, b2 * r2
            bmax = max(b0, b1, b2)
            if bmax <= 0.0:
                continue
            scale = rays.scale[i] * 1.0
            if roulette:
                survive = min(bmax / scale, Q_MAX)
                if not u.rr[i] < survive:
                    continue
                b0, b1, b2 = b0 / survive, b1 / survive, b2 / survive
            no0, no1, no2 = x0 + off * n0, x1 + off * n1, x2 + off * n2
            nxt.o[nn, 0], nxt.o[nn, 1], nxt.o[nn, 2] = no0, no1, no2
            nxt.o32[nn, 0], nxt.o32[nn, 1], nxt.o32[nn, 2] = no0, no1, no2
            nxt.d[nn, 0], nxt.d[nn, 1], nxt.d[nn, 2] = c0, c1, c2
            nxt.d32[nn, 0], nxt.d32[nn, 1], nxt.d32[nn, 2] = c0, c1, c2
            nxt.path[nn] = q
            nxt.beta[nn, 0], nxt.beta[nn, 1], nxt.beta[nn, 2] = b0, b1, b2
            nxt.pdf[nn] = lz * INV_PI
            nxt.scale[nn] = scale
            nn += 1
    return ns, nn


@jit_inline
def _power(a, b):
    a2, b2 = a * a, b * b
    return a2 / (a2 + b2) if a2 + b2 > 0.0 else 0.0


@jit_inline
def _emission_weight(pdf, pa, t, cos_o):
    return 1.0 if pdf == 0.0 else _power(pdf, pa * t * t / cos_o if cos_o > 0.0 else 0.0)


@jit_inline
def _cosine_direction(nx, ny, nz, u1, u2):
    """:func:`cornell_harness.renderers.core.sampling.cosine_hemisphere`, written out: (dx, dy, dz, cos θ)."""
    r = math.sqrt(u1)
    phi = TWO_PI * u2
    lx, ly = r * math.cos(phi), r * math.sin(phi)
    return _about_normal(nx, ny, nz, lx, ly, math.sqrt(max(0.0, 1.0 - u1)))


@jit_inline
def _cosine_direction_poly(nx, ny, nz, u1, u2):
    """:func:`_cosine_direction` with cos 2πu2 and sin 2πu2 from polynomials (:func:`_cos_sin_turns`), which
    LLVM vectorises, instead of libm's calls."""
    r = math.sqrt(u1)
    c, s = _cos_sin_turns(u2)
    return _about_normal(nx, ny, nz, r * c, r * s, math.sqrt(max(0.0, 1.0 - u1)))


@jit_inline
def _cos_sin_turns(u):
    """(cos 2πu, sin 2πu) for u in [0, 1), branch-free: u's quarter turn q (nearest) is exact, the rest θ in
    [-π/4, π/4] goes through Taylor series to θ^18 (truncation below 1e-17), and (cos θ, sin θ) is turned by
    q quarter turns. Within a few ulps of libm's, not its bits."""
    x = 4.0 * u
    q = math.floor(x + 0.5)
    t = (x - q) * (0.5 * math.pi)
    t2 = t * t
    s = t * (1.0 + t2 * (-1.0 / 6 + t2 * (1.0 / 120 + t2 * (-1.0 / 5040 + t2 * (1.0 / 362880 + t2 * (
        -1.0 / 39916800 + t2 * (1.0 / 6227020800 + t2 * (-1.0 / 1307674368000 + t2 / 355687428096000))))))))
    c = 1.0 + t2 * (-0.5 + t2 * (1.0 / 24 + t2 * (-1.0 / 720 + t2 * (1.0 / 40320 + t2 * (-1.0 / 3628800 + t2 * (
        1.0 / 479001600 + t2 * (-1.0 / 87178291200 + t2 * (1.0 / 20922789888000 - t2 / 6402373705728000))))))))
    k = q - 4.0 * math.floor(q * 0.25)  # q mod 4
    cos = c if k == 0.0 else -s if k == 1.0 else -c if k == 2.0 else s
    sin = s if k == 0.0 else c if k == 1.0 else -s if k == 2.0 else -c
    return cos, sin


@jit_inline
def _about_normal(nx, ny, nz, lx, ly, lz):
    """The local direction (lx, ly, lz) in the frame of unit normal n (Duff et al. 2017's basis)."""
    sign = 1.0 if nz >= 0.0 else -1.0
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    s0, s1, s2 = 1.0 + sign * nx * nx * a, sign * b, -sign * nx
    t0, t1, t2 = b, sign + ny * ny * a, -ny
    return s0 * lx + t0 * ly + nx * lz, s1 * lx + t1 * ly + ny * lz, s2 * lx + t2 * ly + nz * lz, lz


# -- (d) the shading as loops over arrays ------------------------------------------------------------------

def soa_kernels(fastmath, poly=False):
    """(d): the per-bounce driver (``run``) and its loops, the three maths loops compiled with ``fastmath``
    (numba's flag: False, a set of LLVM fast-math flags, or True for all of them). The loops that fetch from
    the scene's tables by index, add into the estimates, or write the survivors stay scalar: gathers and
    scatters, which LLVM's cost model does not vectorise here. ``poly``: cos and sin of the BSDF sample by
    :func:`_cos_sin_turns`. Returns a dict of the compiled functions."""
    vec = numba.njit(nogil=True, error_model="numpy", fastmath=fastmath)
    vec_inline = numba.njit(nogil=True, error_model="numpy", fastmath=fastmath, inline="always")
    power = vec_inline(_power.py_func)
    cosine_direction = vec_inline((_cosine_direction_poly if poly else _cosine_direction).py_func)

    @jit
    def fetch_hits(s, e, prim, rays, geo, ln):
        """The ray, its path state and its primitive's tables, per lane."""
        for k in range(e - s):
            i = s + k
            p = prim[i]
            ln.live[k] = p >= 0
            p = max(p, 0)
            ln.q[k] = rays.path[i]
            ln.o0[k], ln.o1[k], ln.o2[k] = rays.o[i, 0], rays.o[i, 1], rays.o[i, 2]
            ln.d0[k], ln.d1[k], ln.d2[k] = rays.d[i, 0], rays.d[i, 1], rays.d[i, 2]
            ln.b0[k], ln.b1[k], ln.b2[k] = rays.beta[i, 0], rays.beta[i, 1], rays.beta[i, 2]
            ln.pdf[k], ln.scale[k] = rays.pdf[i], rays.scale[i]
            ln.n0[k], ln.n1[k], ln.n2[k] = geo.normal[p, 0], geo.normal[p, 1], geo.normal[p, 2]
            ln.v0[k], ln.v1[k], ln.v2[k] = geo.v0[p, 0], geo.v0[p, 1], geo.v0[p, 2]
            ln.r0[k], ln.r1[k], ln.r2[k] = geo.reflectance[p, 0], geo.reflectance[p, 1], geo.reflectance[p, 2]
            ln.le0[k], ln.le1[k], ln.le2[k] = geo.radiance[p, 0], geo.radiance[p, 1], geo.radiance[p, 2]
            ln.pa[k] = geo.light_pdf_area[p]

    @vec
    def surface(m, ln):
        """The hit point, the side hit, and the MIS-weighted emission found."""
        for k in range(m):
            cos_o = -(ln.d0[k] * ln.n0[k] + ln.d1[k] * ln.n1[k] + ln.d2[k] * ln.n2[k])
            t = ((ln.v0[k] - ln.o0[k]) * ln.n0[k] + (ln.v1[k] - ln.o1[k]) * ln.n1[k]
                 + (ln.v2[k] - ln.o2[k]) * ln.n2[k]) / -cos_o
            t = 0.0 if t < 0.0 else t
            ln.x0[k], ln.x1[k], ln.x2[k] = ln.o0[k] + t * ln.d0[k], ln.o1[k] + t * ln.d1[k], ln.o2[k] + t * ln.d2[k]
            live = ln.live[k] and cos_o > 0.0
            ln.live[k] = live
            pa = ln.pa[k]
            ln.emits[k] = live and pa > 0.0
            w = 1.0 if ln.pdf[k] == 0.0 else power(ln.pdf[k], pa * t * t / cos_o if cos_o > 0.0 else 0.0)
            ln.le0[k], ln.le1[k], ln.le2[k] = ln.b0[k] * ln.le0[k] * w, ln.b1[k] * ln.le1[k] * w, ln.b2[k] * ln.le2[k] * w

    @jit
    def add_emission(m, ln, L):
        for k in range(m):
            if ln.emits[k]:
                q = ln.q[k]
                L[q, 0] += ln.le0[k]
                L[q, 1] += ln.le1[k]
                L[q, 2] += ln.le2[k]

    @jit
    def pick_emitters(s, e, u, geo, ln):
        """The emitter triangle by power, and its tables, per lane."""
        ne = geo.emitter_ids.size
        for k in range(e - s):
            t = geo.emitter_ids[min(np.searchsorted(geo.emitter_cdf, u.pick[s + k], side="right"), ne - 1)]
            ln.y0[k], ln.y1[k], ln.y2[k] = geo.v0[t, 0], geo.v0[t, 1], geo.v0[t, 2]
            ln.f0[k], ln.f1[k], ln.f2[k] = geo.e1[t, 0], geo.e1[t, 1], geo.e1[t, 2]
            ln.h0[k], ln.h1[k], ln.h2[k] = geo.e2[t, 0], geo.e2[t, 1], geo.e2[t, 2]
            ln.m0[k], ln.m1[k], ln.m2[k] = geo.normal[t, 0], geo.normal[t, 1], geo.normal[t, 2]
            ln.c0[k], ln.c1[k], ln.c2[k] = geo.radiance[t, 0], geo.radiance[t, 1], geo.radiance[t, 2]
            ln.pe[k] = geo.light_pdf_area[t]

    @vec
    def light(s, e, u, off, ln):
        """The light sample: the point, the geometry term with MIS, the shadow segment and its contribution."""
        for k in range(e - s):
            su = math.sqrt(u.u1[s + k])
            u2 = u.u2[s + k]
            e1, e2 = su * (1.0 - u2), su * u2
            y0 = ln.y0[k] + e1 * ln.f0[k] + e2 * ln.h0[k]
            y1 = ln.y1[k] + e1 * ln.f1[k] + e2 * ln.h1[k]
            y2 = ln.y2[k] + e1 * ln.f2[k] + e2 * ln.h2[k]
            x0, x1, x2 = ln.x0[k], ln.x1[k], ln.x2[k]
            n0, n1, n2 = ln.n0[k], ln.n1[k], ln.n2[k]
            m0, m1, m2 = ln.m0[k], ln.m1[k], ln.m2[k]
            pe = ln.pe[k]
            w0, w1, w2 = y0 - x0, y1 - x1, y2 - x2
            dist2 = w0 * w0 + w1 * w1 + w2 * w2
            dist = math.sqrt(dist2)
            w0, w1, w2 = w0 / dist, w1 / dist, w2 / dist
            cos_x = n0 * w0 + n1 * w1 + n2 * w2
            cos_y = -(m0 * w0 + m1 * w1 + m2 * w2)
            g = cos_x * cos_y / dist2 * power(pe * dist2 / cos_y, cos_x * INV_PI) / pe
            a0, a1, a2 = x0 + off * n0, x1 + off * n1, x2 + off * n2
            s0, s1, s2 = y0 + off * m0 - a0, y1 + off * m1 - a1, y2 + off * m2 - a2
            sl = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
            ln.found[k] = (ln.live[k] and dist2 > 0.0 and pe > 0.0 and cos_x > 0.0 and cos_y > 0.0
                           and sl > 0.0)
            ln.a0[k], ln.a1[k], ln.a2[k] = a0, a1, a2
            ln.s0[k], ln.s1[k], ln.s2[k] = s0 / sl, s1 / sl, s2 / sl
            ln.tfar[k] = sl * SHADOW_TFAR_REL
            ln.c0[k] = ln.b0[k] * ln.r0[k] * INV_PI * ln.c0[k] * g
            ln.c1[k] = ln.b1[k] * ln.r1[k] * INV_PI * ln.c1[k] * g
            ln.c2[k] = ln.b2[k] * ln.r2[k] * INV_PI * ln.c2[k] * g

    @vec
    def bsdf(s, e, u, roulette, off, ln):
        """The cosine-weighted direction, the throughput after it, Russian roulette, the next ray's origin."""
        for k in range(e - s):
            n0, n1, n2 = ln.n0[k], ln.n1[k], ln.n2[k]
            c0, c1, c2, lz = cosine_direction(n0, n1, n2, u.w1[s + k], u.w2[s + k])
            b0, b1, b2 = ln.b0[k] * ln.r0[k], ln.b1[k] * ln.r1[k], ln.b2[k] * ln.r2[k]
            bmax = max(b0, b1, b2)
            alive = ln.live[k] and lz > 0.0 and not bmax <= 0.0  # a NaN goes on, as in the kernel
            if roulette:
                survive = min(bmax / ln.scale[k], Q_MAX)
                alive = alive and u.rr[s + k] < survive
                b0, b1, b2 = b0 / survive, b1 / survive, b2 / survive
            ln.alive[k] = alive
            ln.w0[k], ln.w1[k], ln.w2[k] = c0, c1, c2
            ln.nb0[k], ln.nb1[k], ln.nb2[k] = b0, b1, b2
            ln.npdf[k] = lz * INV_PI
            ln.no0[k], ln.no1[k], ln.no2[k] = ln.x0[k] + off * n0, ln.x1[k] + off * n1, ln.x2[k] + off * n2

    @jit
    def write(m, ln, shadow, nxt, ns, nn):
        """The shadow segments found and the rays that go on, packed into the kernel's buffers in path order."""
        for k in range(m):
            if ln.found[k]:
                shadow.c[ns, 0], shadow.c[ns, 1], shadow.c[ns, 2] = ln.c0[k], ln.c1[k], ln.c2[k]
                shadow.o[ns, 0], shadow.o[ns, 1], shadow.o[ns, 2] = ln.a0[k], ln.a1[k], ln.a2[k]
                shadow.d[ns, 0], shadow.d[ns, 1], shadow.d[ns, 2] = ln.s0[k], ln.s1[k], ln.s2[k]
                shadow.t[ns] = ln.tfar[k]
                shadow.path[ns] = ln.q[k]
                ns += 1
            if ln.alive[k]:
                nxt.o[nn, 0], nxt.o[nn, 1], nxt.o[nn, 2] = ln.no0[k], ln.no1[k], ln.no2[k]
                nxt.o32[nn, 0], nxt.o32[nn, 1], nxt.o32[nn, 2] = ln.no0[k], ln.no1[k], ln.no2[k]
                nxt.d[nn, 0], nxt.d[nn, 1], nxt.d[nn, 2] = ln.w0[k], ln.w1[k], ln.w2[k]
                nxt.d32[nn, 0], nxt.d32[nn, 1], nxt.d32[nn, 2] = ln.w0[k], ln.w1[k], ln.w2[k]
                nxt.path[nn] = ln.q[k]
                nxt.beta[nn, 0], nxt.beta[nn, 1], nxt.beta[nn, 2] = ln.nb0[k], ln.nb1[k], ln.nb2[k]
                nxt.pdf[nn] = ln.npdf[k]
                nxt.scale[nn] = ln.scale[k]
                nn += 1
        return ns, nn

    @jit
    def run(reps, chunk, prim, rays, u, roulette, geo, L, shadow, nxt, ln, loops=ALL_LOOPS):
        """The bounce, ``reps`` times, ``chunk`` lanes at a time; ``loops``: a bit mask of the loops to run
        (:data:`LOOPS`' order), to time them one by one."""
        ns = nn = 0
        for _ in range(reps):
            ns = nn = 0
            for s in range(0, prim.size, chunk):
                e = min(s + chunk, prim.size)
                if loops & 1:
                    fetch_hits(s, e, prim, rays, geo, ln)
                if loops & 2:
                    surface(e - s, ln)
                if loops & 4:
                    add_emission(e - s, ln, L)
                if loops & 8:
                    pick_emitters(s, e, u, geo, ln)
                if loops & 16:
                    light(s, e, u, geo.offset, ln)
                if loops & 32:
                    bsdf(s, e, u, roulette, geo.offset, ln)
                if loops & 64:
                    ns, nn = write(e - s, ln, shadow, nxt, ns, nn)
        return ns, nn

    return {**dict(zip(LOOPS, (fetch_hits, surface, add_emission, pick_emitters, light, bsdf, write))), "run": run}
