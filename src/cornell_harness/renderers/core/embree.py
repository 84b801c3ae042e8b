"""Embree 4's C API, called in 8-ray packets from numba kernels: every renderer's ray queries.

A wavefront's rays (:mod:`cornell_harness.renderers.core.rays`) are answered by a numba
loop over 8-ray packets (``rtcIntersect8``/``rtcOccluded8``; consecutive
rays belong to neighbouring pixels, so packets are coherent where it pays:
first-bounce shadow rays 2.3x the rays/s of one-at-a-time queries, camera
rays 1.2x, later bounces 1.1x; identical hits). One ray at a time
(``rtcIntersect1``, what embreex's ``run`` loops over) measured 1.06x
embreex; ``benchmarks/embree_direct.py`` times the packets on incoherent rays.
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
- The ray structures are Embree 4's ``rtcore_ray.h`` packet layouts
  (structures of arrays, 8 lanes per field), as 32-bit words of one array
  per query batch (:func:`ray_record`, aligned as Embree requires): the ray
  (org, tnear, dir, time, tfar, mask, id, flags), then the hit (Ng, u, v,
  primID, geomID, instID, instPrimID), then the lanes' valid flags.
  ``rtcOccluded8`` reads the ray and sets a blocked lane's tfar to -inf.

Rays are float32 with tnear 0 and tfar 1e37, and the scene is robust, as
embreex made them, so the hits are the ones embreex returned for the same
float32 rays (images are bit-identical to before): kernels keep our float64
maths and scene-scaled origin offsets (:mod:`cornell_harness.renderers.core.geometry`).
"""

from __future__ import annotations

import ctypes
import glob
import os
from functools import lru_cache

import numpy as np
from numba import types

from cornell_harness.renderers.core.sampling import jit

_GEOMETRY_TYPE_TRIANGLE, _BUFFER_TYPE_INDEX, _BUFFER_TYPE_VERTEX = 0, 0, 1
_FORMAT_UINT3, _FORMAT_FLOAT3 = 0x5003, 0x9003
_SCENE_FLAG_ROBUST = 1 << 2
INVALID_ID = np.uint32(0xFFFFFFFF)
#: Rays per query: Embree's 8-wide packets (rtcIntersect8/rtcOccluded8; AVX2).
PACKET = 8
#: Words of an RTCRayHit8 (structure of arrays: 12 ray fields, then Ng x/y/z, u, v, primID, geomID,
#: instID, instPrimID, 8 lanes each), then the packet's 8 valid flags at word 192 (32-byte aligned).
_PRIM_ID, _GEOM_ID, _VALID = 96 + 5 * PACKET, 96 + 6 * PACKET, 192
_TNEAR, _TFAR, _MASK = 3 * PACKET, 8 * PACKET, 9 * PACKET
RECORD_WORDS = _VALID + PACKET
_ALIGN = 64
#: tfar of a closest-hit query: embreex's, so both ask Embree exactly the same question.
_NO_TFAR = np.float32(1e37)


def library_path() -> str:
    """The path of the ``libembree4`` that embreex's wheel bundles (``site-packages/embreex.libs/``)."""
    import embreex

    libs = os.path.join(os.path.dirname(os.path.dirname(embreex.__file__)), "embreex.libs")
    found = glob.glob(os.path.join(libs, "libembree4*.so*"))
    if not found:
        raise ImportError(f"no libembree4 in {libs}: embreex's wheel is expected to bundle it")
    return found[0]


@lru_cache(maxsize=1)
def library() -> ctypes.CDLL:
    """embreex's bundled ``libembree4``, with the prototypes used here; also made visible to numba kernels."""
    import llvmlite.binding as llvm

    path = library_path()
    llvm.load_library_permanently(path)
    lib = ctypes.CDLL(path)
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
_signature = types.void(types.uintp, types.uintp, types.uintp, types.uintp)  # (valid, scene, rays, arguments)
_intersect8 = types.ExternalFunction("rtcIntersect8", _signature)
_occluded8 = types.ExternalFunction("rtcOccluded8", _signature)


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
    """A zeroed RTCRayHit8 and its valid flags (uint32 words), 64-byte aligned: one per query batch."""
    buf = np.zeros(RECORD_WORDS + _ALIGN // 4, np.uint32)
    k = (-buf.ctypes.data % _ALIGN) // 4
    return buf[k:k + RECORD_WORDS]


@jit
def _fill_packet(rec, f, o, d, first, n):
    """Rays first .. first+n-1 (n ≤ 8) into the packet's lanes, all but tfar; the other lanes invalid."""
    for k in range(PACKET):
        if k < n:
            i = first + k
            f[k], f[PACKET + k], f[2 * PACKET + k], f[_TNEAR + k] = o[i, 0], o[i, 1], o[i, 2], np.float32(0.0)
            f[4 * PACKET + k], f[5 * PACKET + k], f[6 * PACKET + k] = d[i, 0], d[i, 1], d[i, 2]
            f[7 * PACKET + k] = np.float32(0.0)  # time
            rec[_MASK + k], rec[_MASK + PACKET + k], rec[_MASK + 2 * PACKET + k] = INVALID_ID, 0, 0  # mask, id, flags
            rec[_VALID + k] = INVALID_ID  # -1: a valid lane
        else:
            rec[_VALID + k] = 0


@jit
def closest_triangles(scene, o, d, prim, rec):
    """``prim[i]``: id of the triangle ray i (float32 o, d; t > 0) hits first, -1 for none."""
    f = rec.view(np.float32)
    for first in range(0, prim.size, PACKET):
        n = min(PACKET, prim.size - first)
        _fill_packet(rec, f, o, d, first, n)
        for k in range(PACKET):
            f[_TFAR + k] = _NO_TFAR
            rec[_GEOM_ID + k] = INVALID_ID
        _intersect8(rec[_VALID:].ctypes.data, scene, rec.ctypes.data, 0)  # 0: default RTCIntersectArguments
        for k in range(n):
            prim[first + k] = -1 if rec[_GEOM_ID + k] == INVALID_ID else np.int32(rec[_PRIM_ID + k])


@jit
def segments_clear(scene, o, d, tfar, clear, rec):
    """``clear[k]``: no triangle lies on o + t·d for t in (0, tfar[k]) (float32 segments)."""
    f = rec.view(np.float32)
    for first in range(0, clear.size, PACKET):
        n = min(PACKET, clear.size - first)
        _fill_packet(rec, f, o, d, first, n)
        for k in range(n):
            f[_TFAR + k] = tfar[first + k]
        _occluded8(rec[_VALID:].ctypes.data, scene, rec.ctypes.data, 0)
        for k in range(n):
            clear[first + k] = not f[_TFAR + k] < 0.0  # Embree writes -inf into tfar on a hit
