"""Embree's C API called from numba kernels, against embreex's batched call: groundwork for issue 14.

Issue 14 asks for a path-tracing core at least as fast as Mitsuba 3; one option it names is calling
Embree directly from numba, so that a kernel traces, shades and accumulates without a Python call or a
buffer per wavefront. This measures whether that path works here and what it buys on the ray query
alone: embreex's wheel bundles ``libembree4`` (``embreex.libs/``), whose C functions ctypes loads; the
scene is built through the C API (``rtcNewDevice``, ``rtcNewScene``, a triangle geometry with its vertex
and index buffers, ``rtcCommitScene``), and a numba ``njit`` kernel calls ``rtcIntersect1`` once per ray
through a ctypes function pointer (numba calls a ``CFUNCTYPE`` object in nopython mode), filling one
``RTCRayHit`` (Embree 4's ``rtcore_ray.h``: 12 words of ray, org, tnear, dir, time, tfar, mask, id, flags,
then the hit, Ng, u, v, primID, geomID, instID, instPrimID; 16-byte aligned).

Both answer the same closest-hit queries on ``cornell-box``'s triangles (float32, as Embree takes):
``--rays`` rays from a point inside the box in uniformly random directions, one thread each, the median of
``--repeats`` timed runs after a warm-up; the primitive ids must agree exactly. No renderer uses this yet.

Run: ``.venv/bin/python benchmarks/embree_direct.py`` (a few seconds).
"""

from __future__ import annotations

import argparse
import ctypes
import glob
import os
import statistics
import time

import numba
import numpy as np

from harness.scenes.library import resolve_scene
from harness.scenes.model import triangle_arrays

RTC_GEOMETRY_TYPE_TRIANGLE, RTC_BUFFER_TYPE_INDEX, RTC_BUFFER_TYPE_VERTEX = 0, 0, 1
RTC_FORMAT_UINT3, RTC_FORMAT_FLOAT3 = 0x5003, 0x9003
RTC_INVALID_GEOMETRY_ID = 0xFFFFFFFF
#: Words of one RTCRayHit (21 used), rounded up to its 16-byte alignment.
RAYHIT_WORDS = 24


def embree_library() -> ctypes.CDLL:
    """The ``libembree4`` embreex's wheel bundles, with the prototypes used here."""
    import embreex

    libs = os.path.join(os.path.dirname(os.path.dirname(embreex.__file__)), "embreex.libs")
    lib = ctypes.CDLL(glob.glob(os.path.join(libs, "libembree4*.so*"))[0])
    vp = ctypes.c_void_p
    lib.rtcNewDevice.restype, lib.rtcNewDevice.argtypes = vp, [ctypes.c_char_p]
    lib.rtcNewScene.restype, lib.rtcNewScene.argtypes = vp, [vp]
    lib.rtcNewGeometry.restype, lib.rtcNewGeometry.argtypes = vp, [vp, ctypes.c_int]
    lib.rtcSetNewGeometryBuffer.restype = vp
    lib.rtcSetNewGeometryBuffer.argtypes = [vp, ctypes.c_int, ctypes.c_uint, ctypes.c_int, ctypes.c_size_t,
                                            ctypes.c_size_t]
    lib.rtcAttachGeometry.restype, lib.rtcAttachGeometry.argtypes = ctypes.c_uint, [vp, vp]
    for name in ("rtcCommitGeometry", "rtcReleaseGeometry", "rtcCommitScene"):
        getattr(lib, name).argtypes = [vp]
    return lib


def embree_scene(lib: ctypes.CDLL, vertices: np.ndarray, triangles: np.ndarray) -> int:
    """A committed Embree scene of one triangle geometry, built through the C API; its handle."""
    device = lib.rtcNewDevice(None)
    scene = lib.rtcNewScene(device)
    geom = lib.rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE)
    for kind, fmt, data in ((RTC_BUFFER_TYPE_VERTEX, RTC_FORMAT_FLOAT3, vertices),
                            (RTC_BUFFER_TYPE_INDEX, RTC_FORMAT_UINT3, triangles)):
        ptr = lib.rtcSetNewGeometryBuffer(geom, kind, 0, fmt, 12, len(data))
        ctypes.memmove(ptr, data.ctypes.data, data.nbytes)  # Embree owns (and pads) the buffer
    lib.rtcCommitGeometry(geom)
    lib.rtcAttachGeometry(scene, geom)
    lib.rtcReleaseGeometry(geom)
    lib.rtcCommitScene(scene)
    return scene


def intersect_kernel(lib: ctypes.CDLL):
    """A numba kernel ``trace(scene, o, d, prim, rayhit)`` that calls ``rtcIntersect1`` per ray (prim -1: miss)."""
    rtc_intersect1 = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p)(
        ctypes.cast(lib.rtcIntersect1, ctypes.c_void_p).value)

    @numba.njit(nogil=True)
    def trace(scene, o, d, prim, rayhit):
        f = rayhit.view(np.float32)
        for i in range(o.shape[0]):
            f[0], f[1], f[2], f[3] = o[i, 0], o[i, 1], o[i, 2], 0.0  # origin, tnear
            f[4], f[5], f[6], f[7] = d[i, 0], d[i, 1], d[i, 2], 0.0  # direction, time
            f[8] = np.inf  # tfar
            rayhit[9], rayhit[10], rayhit[11] = 0xFFFFFFFF, 0, 0  # mask, id, flags
            rayhit[17], rayhit[18] = RTC_INVALID_GEOMETRY_ID, RTC_INVALID_GEOMETRY_ID  # primID, geomID
            rtc_intersect1(scene, rayhit.ctypes.data, 0)  # NULL: default intersect arguments
            prim[i] = np.int32(rayhit[17]) if rayhit[18] != RTC_INVALID_GEOMETRY_ID else -1

    return trace


def median_seconds(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rays", type=int, default=1 << 18, help="closest-hit queries per timed run")
    ap.add_argument("--repeats", type=int, default=7, help="timed runs (the median is reported)")
    a = ap.parse_args()
    tri = triangle_arrays(resolve_scene("cornell-box"))
    vertices, triangles = tri["vertices"].astype(np.float32), tri["triangles"].astype(np.uint32)
    rng = np.random.default_rng(0)
    o = np.tile(np.array([0.0, 0.0, 0.5], np.float32), (a.rays, 1))
    d = rng.normal(size=(a.rays, 3)).astype(np.float32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)

    lib = embree_library()
    scene = embree_scene(lib, vertices, triangles)
    trace = intersect_kernel(lib)
    rayhit = np.zeros(RAYHIT_WORDS, np.uint32)
    assert rayhit.ctypes.data % 16 == 0, "RTCRayHit must be 16-byte aligned"
    prim = np.empty(a.rays, np.int32)
    trace(scene, o[:8], d[:8], prim[:8], rayhit)  # compile before the clock

    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    ex = rtcore_scene.EmbreeScene()
    TriangleMesh(ex, vertices, triangles.astype(np.int32))
    expected = ex.run(o, d, query="INTERSECT")
    direct_s = median_seconds(lambda: trace(scene, o, d, prim, rayhit), a.repeats)
    batch_s = median_seconds(lambda: ex.run(o, d, query="INTERSECT"), a.repeats)
    agree = float((prim == expected).mean())
    print(f"| closest hit, cornell-box, {a.rays} rays, 1 thread, median of {a.repeats} | Mrays/s |\n|---|---|\n"
          f"| numba kernel calling rtcIntersect1 per ray | {a.rays / direct_s / 1e6:.1f} |\n"
          f"| embreex batched `run(query='INTERSECT')` | {a.rays / batch_s / 1e6:.1f} |\n\n"
          f"ratio {batch_s / direct_s:.2f}; primitive ids agree on {agree:.4%} of rays")
    assert agree == 1.0


if __name__ == "__main__":
    main()
