"""Embree 4's C API, called one ray at a time from numba kernels: every renderer's ray queries.

A wavefront's rays (:mod:`renderers.core.rays`) are answered by a numba
loop calling ``rtcIntersect1``/``rtcOccluded1`` per ray: the same queries
embreex's batched ``run`` made, without its per-ray Cython overhead
(``benchmarks/embree_direct.py``: 1.06x its rays/s, identical hits; the
path tracer gains ~10%, since the query is not all of a wavefront's cost).
A path-at-a-time megakernel calling the same functions between bounces was
tried too and was slower than the wavefront (BENCHMARKS.md).

How it is wired:

- The library is the ``libembree4`` that embreex's wheel bundles
  (``site-packages/embreex.libs/``); :func:`library` loads it with ctypes
  (to build scenes) and into LLVM's symbol table
  (``llvmlite.binding.load_library_permanently``), so kernels call it as a
  numba ``ExternalFunction`` resolved *by name* when a kernel is linked:
  unlike a ctypes pointer (an address baked into the code), that survives
  numba's on-disk cache. Importing this module does both.
- :class:`EmbreeScene` builds a committed scene of one triangle geometry
  (float32 vertices, Embree's ids = our triangle ids) and releases it when
  collected. A committed Embree scene may be queried from many threads at
  once (Embree 4 API docs, ``rtcIntersect1``), so one scene serves every
  work unit; the kernels hold no GIL.
- The ray structures are Embree 4's ``rtcore_ray.h`` layouts, as 32-bit
  words of one array per query batch (:func:`ray_record`, 16-byte aligned
  as Embree requires): words 0-11 are the ray (org, tnear, dir, time, tfar,
  mask, id, flags), 12-20 the hit (Ng, u, v, primID, geomID, instID,
  instPrimID). ``rtcOccluded1`` reads the first 12 and sets tfar to -inf on
  a hit.

Rays are float32 with tnear 0 and tfar 1e37, and the scene is robust, as
embreex made them, so the hits are the ones embreex returned for the same
float32 rays (images are bit-identical to before): kernels keep our float64
maths and scene-scaled origin offsets (:mod:`renderers.core.geometry`).
"""

from __future__ import annotations

import ctypes
import glob
import os
from functools import lru_cache

import numpy as np
from numba import types

from renderers.core.sampling import jit

_GEOMETRY_TYPE_TRIANGLE, _BUFFER_TYPE_INDEX, _BUFFER_TYPE_VERTEX = 0, 0, 1
_FORMAT_UINT3, _FORMAT_FLOAT3 = 0x5003, 0x9003
_SCENE_FLAG_ROBUST = 1 << 2
INVALID_ID = np.uint32(0xFFFFFFFF)
#: Words of an RTCRayHit (21 used), rounded up to its 16-byte alignment; 4 more to align it.
RAYHIT_WORDS = 24
_SLACK = 4
_PRIM_ID, _GEOM_ID = 17, 18
#: tfar of a closest-hit query: embreex's, so both ask Embree exactly the same question.
_NO_TFAR = np.float32(1e37)


@lru_cache(maxsize=1)
def library() -> ctypes.CDLL:
    """embreex's bundled ``libembree4``, with the prototypes used here; also made visible to numba kernels."""
    import embreex
    import llvmlite.binding as llvm

    libs = os.path.join(os.path.dirname(os.path.dirname(embreex.__file__)), "embreex.libs")
    found = glob.glob(os.path.join(libs, "libembree4*.so*"))
    if not found:
        raise ImportError(f"no libembree4 in {libs}: embreex's wheel is expected to bundle it")
    llvm.load_library_permanently(found[0])
    lib = ctypes.CDLL(found[0])
    vp = ctypes.c_void_p
    lib.rtcNewDevice.restype, lib.rtcNewDevice.argtypes = vp, [ctypes.c_char_p]
    lib.rtcNewScene.restype, lib.rtcNewScene.argtypes = vp, [vp]
    lib.rtcNewGeometry.restype, lib.rtcNewGeometry.argtypes = vp, [vp, ctypes.c_int]
    lib.rtcSetNewGeometryBuffer.restype = vp
    lib.rtcSetNewGeometryBuffer.argtypes = [vp, ctypes.c_int, ctypes.c_uint, ctypes.c_int, ctypes.c_size_t,
                                            ctypes.c_size_t]
    lib.rtcAttachGeometry.restype, lib.rtcAttachGeometry.argtypes = ctypes.c_uint, [vp, vp]
    lib.rtcSetSceneFlags.argtypes = [vp, ctypes.c_int]
    for name in ("rtcCommitGeometry", "rtcReleaseGeometry", "rtcCommitScene", "rtcReleaseScene",
                 "rtcReleaseDevice"):
        getattr(lib, name).argtypes = [vp]
    return lib


try:
    library()  # before any kernel below is compiled or loaded from the cache
except (ImportError, OSError):
    pass  # no kernel here can run; ToolkitRenderer.unavailable_reason says why
_intersect1 = types.ExternalFunction("rtcIntersect1", types.void(types.uintp, types.uintp, types.uintp))
_occluded1 = types.ExternalFunction("rtcOccluded1", types.void(types.uintp, types.uintp, types.uintp))


class EmbreeScene:
    """A committed Embree scene of one triangle mesh; ``handle`` is what kernels take."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray):
        lib = self._lib = library()
        self._device = lib.rtcNewDevice(None)
        self.handle = lib.rtcNewScene(self._device)
        # Robust traversal, as embreex's scenes have: without it a ray grazing the open front edge of
        # cornell-box's wall slipped past a triangle that embreex (and Mitsuba) hit.
        lib.rtcSetSceneFlags(self.handle, _SCENE_FLAG_ROBUST)
        if len(triangles):
            geom = lib.rtcNewGeometry(self._device, _GEOMETRY_TYPE_TRIANGLE)
            for kind, fmt, data in ((_BUFFER_TYPE_VERTEX, _FORMAT_FLOAT3, np.ascontiguousarray(vertices, np.float32)),
                                    (_BUFFER_TYPE_INDEX, _FORMAT_UINT3, np.ascontiguousarray(triangles, np.uint32))):
                ptr = lib.rtcSetNewGeometryBuffer(geom, kind, 0, fmt, 12, len(data))
                ctypes.memmove(ptr, data.ctypes.data, data.nbytes)  # Embree owns (and pads) its buffer
            lib.rtcCommitGeometry(geom)
            lib.rtcAttachGeometry(self.handle, geom)
            lib.rtcReleaseGeometry(geom)
        lib.rtcCommitScene(self.handle)

    def __del__(self):
        lib = getattr(self, "_lib", None)
        if lib is not None:
            lib.rtcReleaseScene(self.handle)
            lib.rtcReleaseDevice(self._device)


def ray_record() -> np.ndarray:
    """A zeroed RTCRayHit (uint32 words), 16-byte aligned: one per query batch, reused for every ray."""
    buf = np.zeros(RAYHIT_WORDS + _SLACK, np.uint32)
    k = (-buf.ctypes.data % 16) // 4
    return buf[k:k + RAYHIT_WORDS]


@jit
def _set_ray(rec, f, o, d, i, tfar):
    f[0], f[1], f[2], f[3] = o[i, 0], o[i, 1], o[i, 2], np.float32(0.0)  # origin, tnear
    f[4], f[5], f[6], f[7] = d[i, 0], d[i, 1], d[i, 2], np.float32(0.0)  # direction, time
    f[8] = tfar
    rec[9], rec[10], rec[11] = INVALID_ID, 0, 0  # mask: every geometry; id; flags


@jit
def closest_triangles(scene, o, d, prim, rec):
    """``prim[i]``: id of the triangle ray i (float32 o, d; t > 0) hits first, -1 for none."""
    f = rec.view(np.float32)
    for i in range(prim.size):
        _set_ray(rec, f, o, d, i, _NO_TFAR)
        rec[_PRIM_ID], rec[_GEOM_ID] = INVALID_ID, INVALID_ID
        _intersect1(scene, rec.ctypes.data, 0)  # 0: default RTCIntersectArguments
        prim[i] = -1 if rec[_GEOM_ID] == INVALID_ID else np.int32(rec[_PRIM_ID])


@jit
def segments_clear(scene, o, d, tfar, clear, rec):
    """``clear[k]``: no triangle lies on o + t·d for t in (0, tfar[k]) (float32 segments)."""
    f = rec.view(np.float32)
    for k in range(clear.size):
        _set_ray(rec, f, o, d, k, tfar[k])
        _occluded1(scene, rec.ctypes.data, 0)
        clear[k] = not f[8] < 0.0  # Embree writes -inf into tfar on a hit
