"""Embree 4's C API, called in ray packets from numba kernels: every renderer's ray queries.

A wavefront's rays (:mod:`cornell_harness.renderers.core.rays`) are answered by a numba
loop over 8-ray packets (``rtcIntersect8``/``rtcOccluded8``; consecutive
rays belong to neighbouring pixels, so packets are coherent where it pays:
first-bounce shadow rays 2.3x the rays/s of one-at-a-time queries, camera
rays 1.2x, later bounces 1.1x; identical hits). One ray at a time
(``rtcIntersect1``, what embreex's ``run`` loops over) measured 1.06x
embreex; ``benchmarks/embree_direct.py`` times the packets on incoherent rays.
A path-at-a-time megakernel calling the same functions between bounces was
tried too and was slower than the wavefront (BENCHMARKS.md).

Rays that travel together (a pinhole's camera rays, neighbouring pixels one after another) are asked as
such (``closest_triangles(..., coherent=True)``): 16-ray packets (``rtcIntersect16``) with Embree's
``RTC_RAY_QUERY_FLAG_COHERENT``, which Mitsuba 3 passes for its camera rays too. On camera rays that is
2.5-3x faster than the default 8-wide call, and 1.4x faster than 8-wide coherent packets
(``benchmarks/embree_floor.py``); on bounce rays the flag makes the query ~1.4x slower, so every other
query keeps the default. The answer is the same triangle but where a ray meets an edge two triangles share
at one distance (2 camera rays in a million on ``cornell-box``, each on the diagonal of one of its quads),
and there it depends only on the packet's rays, which the work unit fixes, never the thread count.

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
  (structures of arrays, 8 or 16 lanes per field), as 32-bit words of one
  array per query batch (:func:`ray_record`, aligned as Embree requires):
  the ray (org, tnear, dir, time, tfar, mask, id, flags), then the hit (Ng,
  u, v, primID, geomID, instID, instPrimID), then the lanes' valid flags;
  at its end, the ``RTCIntersectArguments`` of a coherent query, written
  once when the record is made (a call passes its address, nothing more).
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
_RAY_QUERY_FLAG_COHERENT = 1 << 16
_FEATURE_FLAG_ALL = 0xFFFFFFFF
INVALID_ID = np.uint32(0xFFFFFFFF)
#: Rays per query: Embree's 8-wide packets (rtcIntersect8/rtcOccluded8; AVX2).
PACKET = 8
#: Rays per coherent query: 16-wide packets (rtcIntersect16; native with AVX-512, which every machine measured has).
COHERENT_PACKET = 16
#: Fields of an RTCRayHitN (structure of arrays, N lanes each: org x/y/z, tnear, dir x/y/z, time, tfar, mask,
#: id, flags, then Ng x/y/z, u, v, primID, geomID, instID, instPrimID); the N valid flags follow at word
#: _FIELDS·N (32- or 64-byte aligned), and the coherent query's RTCIntersectArguments after the 16 valid flags.
_FIELDS = 24
_TNEAR, _TFAR, _MASK, _PRIM_ID, _GEOM_ID = 3, 8, 9, 17, 18
_ARGS = _FIELDS * COHERENT_PACKET + COHERENT_PACKET
#: RTCIntersectArguments: flags, feature_mask, then the context, filter and intersect pointers (null: Embree's
#: defaults), and minWidthDistanceFactor in builds with RTC_MIN_WIDTH; 48 bytes, 16-byte aligned.
_ARGS_WORDS = 12
RECORD_WORDS = _ARGS + _ARGS_WORDS
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
_intersect16 = types.ExternalFunction("rtcIntersect16", _signature)
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
    """A zeroed ray-packet record (uint32 words), 64-byte aligned, its coherent query's arguments filled in: one
    per query batch, for packets of either width."""
    buf = np.zeros(RECORD_WORDS + _ALIGN // 4, np.uint32)
    k = (-buf.ctypes.data % _ALIGN) // 4
    rec = buf[k:k + RECORD_WORDS]
    rec[_ARGS], rec[_ARGS + 1] = _RAY_QUERY_FLAG_COHERENT, _FEATURE_FLAG_ALL
    return rec


@jit
def _fill_packet(rec, f, o, d, first, n, w):
    """Rays first .. first+n-1 (n ≤ w) into the lanes of a ``w``-wide packet, all but tfar; the other lanes
    invalid."""
    valid = _FIELDS * w
    for k in range(w):
        if k < n:
            i = first + k
            f[k], f[w + k], f[2 * w + k], f[_TNEAR * w + k] = o[i, 0], o[i, 1], o[i, 2], np.float32(0.0)
            f[4 * w + k], f[5 * w + k], f[6 * w + k] = d[i, 0], d[i, 1], d[i, 2]
            f[7 * w + k] = np.float32(0.0)  # time
            rec[_MASK * w + k], rec[(_MASK + 1) * w + k], rec[(_MASK + 2) * w + k] = INVALID_ID, 0, 0  # mask, id, flags
            rec[valid + k] = INVALID_ID  # -1: a valid lane
        else:
            rec[valid + k] = 0


@jit
def closest_triangles(scene, o, d, prim, rec, coherent=False):
    """``prim[i]``: id of the triangle ray i (float32 o, d; t > 0) hits first, -1 for none. ``coherent``: the
    rays travel together, one after another (camera rays): 16-wide packets with Embree's coherent flag."""
    w = COHERENT_PACKET if coherent else PACKET
    f = rec.view(np.float32)
    for first in range(0, prim.size, w):
        n = min(w, prim.size - first)
        _fill_packet(rec, f, o, d, first, n, w)
        for k in range(w):
            f[_TFAR * w + k] = _NO_TFAR
            rec[_GEOM_ID * w + k] = INVALID_ID
        if coherent:
            _intersect16(rec[_FIELDS * w:].ctypes.data, scene, rec.ctypes.data, rec[_ARGS:].ctypes.data)
        else:
            _intersect8(rec[_FIELDS * w:].ctypes.data, scene, rec.ctypes.data, 0)  # 0: default arguments
        for k in range(n):
            prim[first + k] = -1 if rec[_GEOM_ID * w + k] == INVALID_ID else np.int32(rec[_PRIM_ID * w + k])


@jit
def segments_clear(scene, o, d, tfar, clear, rec):
    """``clear[k]``: no triangle lies on o + t·d for t in (0, tfar[k]) (float32 segments)."""
    w = PACKET
    f = rec.view(np.float32)
    for first in range(0, clear.size, w):
        n = min(w, clear.size - first)
        _fill_packet(rec, f, o, d, first, n, w)
        for k in range(n):
            f[_TFAR * w + k] = tfar[first + k]
        _occluded8(rec[_FIELDS * w:].ctypes.data, scene, rec.ctypes.data, 0)
        for k in range(n):
            clear[first + k] = not f[_TFAR * w + k] < 0.0  # Embree writes -inf into tfar on a hit
