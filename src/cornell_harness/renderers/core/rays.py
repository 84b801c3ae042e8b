"""Ray buffers of a wavefront, and the numba helpers that write rays into them.

A wavefront renderer keeps one ray per live path in flat arrays (the
queues of pbrt-v4's wavefront integrator, ch. 15, are the same idea): kernels
read one buffer and write the next, and Embree answers each buffer in one call.

- :class:`RayBuffer`: float64 origin and direction (what shading reads),
  one float32 copy of both (``o32``, ``d32``: Embree takes float32 only),
  the path's index in its work unit, its throughput β, the solid-angle
  pdf of the sampling decision that made the ray (0 for camera rays and
  delta-BSDF samples), and the part of β that refraction's radiance scaling
  contributed (``scale``, 1 until the path crosses into another medium).
- :class:`ShadowBuffer`: float32 segments for Embree's occlusion query,
  with the path they belong to and the contribution they carry if
  unoccluded.

Kernels write a ray with :func:`set_ray` (both copies at once, so they can
never disagree) and :func:`set_path`, and a shadow segment with
:func:`shadow_segment` and :func:`set_shadow`. All arguments that are points
or vectors are 3-tuples of float64.

Why the writers are straight-line code and every decision lives in a
function of scalars: a numba function that takes arrays (or tuples of them)
and branches may keep an atomic reference-count increment and decrement of
every array per call (numba's pruning of them is pattern-based), and LLVM
declines to inline a large one, whose arguments are flattened to a few
hundred scalars. Either made the path tracer's kernel 2x slower.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from cornell_harness.renderers.core.embree import ray_record
from cornell_harness.renderers.core.sampling import jit

#: tfar of a shadow segment, relative to its length: stop short of the far
#: point's surface (itself offset off it), which must not occlude itself.
SHADOW_TFAR_REL = 1.0 - 1e-6


class RayBuffer(NamedTuple):
    o: np.ndarray  # (m, 3) float64
    d: np.ndarray  # (m, 3) float64, unit
    o32: np.ndarray  # (m, 3) float32 copy of o, for Embree
    d32: np.ndarray  # (m, 3) float32 copy of d
    path: np.ndarray  # (m,) int64: the path's index in its unit
    beta: np.ndarray  # (m, 3) float64 throughput
    pdf: np.ndarray  # (m,) float64 solid-angle pdf of the sample that made the ray (0: camera ray, delta sample)
    scale: np.ndarray  # (m,) float64 product of the (η_i/η_t)² factors of the path's refractions, in β


class ShadowBuffer(NamedTuple):
    o: np.ndarray  # (m, 3) float32
    d: np.ndarray  # (m, 3) float32, unit
    t: np.ndarray  # (m,) float32 tfar
    path: np.ndarray  # (m,) int64
    c: np.ndarray  # (m, 3) float64 contribution if unoccluded


def ray_buffer(m: int) -> RayBuffer:
    return RayBuffer(np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 3), np.float32),
                     np.empty((m, 3), np.float32), np.empty(m, np.int64), np.empty((m, 3)), np.empty(m), np.empty(m))


def shadow_buffer(m: int) -> ShadowBuffer:
    return ShadowBuffer(np.empty((m, 3), np.float32), np.empty((m, 3), np.float32), np.empty(m, np.float32),
                        np.empty(m, np.int64), np.empty((m, 3)))


class Wavefront(NamedTuple):
    """Every buffer of a bounce loop that runs inside one kernel (:func:`wavefront`): the rays being traced and
    those the bounce writes (swapped each bounce), the shadow segments, and what the queries answer
    (:func:`cornell_harness.renderers.core.geometry.trace_closest`, :func:`cornell_harness.renderers.core.geometry.trace_unoccluded`)."""

    cur: RayBuffer
    nxt: RayBuffer
    shadow: ShadowBuffer
    prim: np.ndarray  # (m,) int32 closest primitive, -1: missed
    t_sphere: np.ndarray  # (m,) float64 sphere hits' distances; (0,) in a scene without spheres
    visible: np.ndarray  # (m,) bool: shadow segment unoccluded
    record: np.ndarray  # Embree's packet record (cornell_harness.renderers.core.embree.ray_record)


def wavefront(m: int, spheres: bool) -> Wavefront:
    """The buffers of a bounce loop over ``m`` paths, in a scene with or without spheres."""
    return Wavefront(ray_buffer(m), ray_buffer(m), shadow_buffer(m), np.empty(m, np.int32),
                     np.empty(m if spheres else 0), np.empty(m, np.bool_), ray_record())


def head(buf, n: int):
    """The first ``n`` entries of a buffer (views, same type)."""
    return type(buf)(*(a[:n] for a in buf))


@jit
def set_ray(buf, i, o, d):
    """Ray ``i`` of ``buf`` from point ``o`` along unit ``d``, in float64 and its float32 copy."""
    buf.o[i, 0], buf.o[i, 1], buf.o[i, 2] = o
    buf.o32[i, 0], buf.o32[i, 1], buf.o32[i, 2] = o
    buf.d[i, 0], buf.d[i, 1], buf.d[i, 2] = d
    buf.d32[i, 0], buf.d32[i, 1], buf.d32[i, 2] = d


@jit
def set_path(buf, i, path, beta, pdf, scale=1.0):
    """The path state that ray ``i`` carries: path index, throughput (3-tuple), pdf of its direction, and the
    refraction scaling in the throughput (see :class:`RayBuffer`)."""
    buf.path[i] = path
    buf.beta[i, 0], buf.beta[i, 1], buf.beta[i, 2] = beta
    buf.pdf[i] = pdf
    buf.scale[i] = scale


@jit
def shadow_segment(a, b):
    """From point ``a`` towards point ``b``, stopping just short of ``b``: (unit direction, tfar, length).

    Both points are already offset off their surfaces. Length 0 when they
    coincide: there is no direction to test, and the caller writes no segment.
    """
    s0, s1, s2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    sl = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    if not sl > 0.0:
        return (0.0, 0.0, 0.0), 0.0, 0.0
    return (s0 / sl, s1 / sl, s2 / sl), sl * SHADOW_TFAR_REL, sl


@jit
def set_shadow(buf, k, o, d, tfar, path, value):
    """Shadow segment ``k`` of ``buf``: from ``o`` along unit ``d`` up to ``tfar``, for ``path``, carrying the
    3-tuple ``value`` (what it adds to the path's estimate if unoccluded)."""
    buf.c[k, 0], buf.c[k, 1], buf.c[k, 2] = value
    buf.o[k, 0], buf.o[k, 1], buf.o[k, 2] = o
    buf.d[k, 0], buf.d[k, 1], buf.d[k, 2] = d
    buf.t[k] = tfar
    buf.path[k] = path


@jit
def add_unoccluded(L, shadow, visible):
    """L[path] += contribution of shadow segment k wherever ``visible[k]``, in segment order (segments
    0 .. ``visible.size`` - 1)."""
    for k in range(visible.size):
        if visible[k]:
            for c in range(3):
                L[shadow.path[k], c] += shadow.c[k, c]
