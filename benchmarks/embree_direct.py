"""Embree's C API called from numba kernels, against embreex's batched call.

Issue 14 asked for a path-tracing core at least as fast as Mitsuba 3; one option it named is calling
Embree directly from numba. This measures what that buys on the ray query alone: the toolkit's
:mod:`cornell_harness.renderers.core.embree` (embreex's bundled ``libembree4``, a scene built through the C API, a numba
loop over 8-ray packets, ``rtcIntersect8``, bound by name so numba's cache keeps it) against embreex's
``run``, which loops over the single-ray call in Cython. These random rays are incoherent: the packets'
gain is on a wavefront's coherent rays (module docstring of ``cornell_harness.renderers.core.embree``).

Both answer the same closest-hit queries on ``cornell-box``'s triangles (float32, as Embree takes):
``--rays`` rays from a point inside the box in uniformly random directions, one thread each, the median of
``--repeats`` timed runs after a warm-up; the primitive ids must agree exactly. Since issue 14 the kernel
measured is the toolkit's own (``cornell_harness.renderers.core.embree.closest_triangles``), which every renderer uses.

Run: ``.venv/bin/python benchmarks/embree_direct.py`` (a few seconds).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.model import triangle_arrays
from cornell_harness.renderers.core.embree import EmbreeScene, closest_triangles, ray_record


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

    scene = EmbreeScene(vertices, triangles)
    prim = np.empty(a.rays, np.int32)
    closest_triangles(scene.handle, o[:8], d[:8], prim[:8], ray_record())  # compile before the clock

    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    ex = rtcore_scene.EmbreeScene()
    TriangleMesh(ex, vertices, triangles.astype(np.int32))
    expected = ex.run(o, d, query="INTERSECT")
    direct_s = median_seconds(lambda: closest_triangles(scene.handle, o, d, prim, ray_record()), a.repeats)
    batch_s = median_seconds(lambda: ex.run(o, d, query="INTERSECT"), a.repeats)
    agree = float((prim == expected).mean())
    print(f"| closest hit, cornell-box, {a.rays} rays, 1 thread, median of {a.repeats} | Mrays/s |\n|---|---|\n"
          f"| `cornell_harness.renderers.core.embree.closest_triangles` (numba, 8-ray packets) | "
          f"{a.rays / direct_s / 1e6:.1f} |\n"
          f"| embreex batched `run(query='INTERSECT')` | {a.rays / batch_s / 1e6:.1f} |\n\n"
          f"ratio {batch_s / direct_s:.2f}; primitive ids agree on {agree:.4%} of rays")
    assert agree == 1.0


if __name__ == "__main__":
    main()
