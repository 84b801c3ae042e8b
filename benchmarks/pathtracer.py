"""Path tracer speed, in one run: ours vs Mitsuba 3, and our rays vs raw embreex.

On ``cornell-box`` at the same resolution, spp and max_depth for both:

(a) raw embreex closest-hit rays/s on the scene's triangles (random rays
    from inside the box, batches of 2^17 on the same number of threads);
(b) our path tracer: paths/s and rays/s (closest-hit + shadow rays);
(c) Mitsuba ``path`` integrator (``llvm_ad_rgb`` when LLVM is found), paths/s
    after a warm-up render that compiles its kernels.

Each figure is the median of ``--repeats`` timed runs; the ratios printed
are ours/Mitsuba (paths/s) and our rays/s over raw rays/s. Run:

    .venv/bin/python benchmarks/pathtracer.py --spp 64 --repeats 5
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import threading
import time

import numpy as np

from harness.scenes.library import resolve_scene
from harness.scenes.model import Scene, triangle_arrays
from renderers.core.schedule import default_threads
from renderers.mitsuba3 import Mitsuba3, scene_dict
from renderers.pathtracer import PathTracer

RAW_BATCH = 1 << 17  # rays per embreex call in (a): large, its best case


def raw_embree_rays_per_s(scene: Scene, threads: int, repeats: int, batches_per_thread: int = 8) -> float:
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    tri = triangle_arrays(scene)
    emb = rtcs.EmbreeScene()
    TriangleMesh(emb, tri["vertices"].astype(np.float32), tri["triangles"].astype(np.int32))
    lo, hi = tri["vertices"].min(0), tri["vertices"].max(0)
    rng = np.random.default_rng(0)
    n = RAW_BATCH
    o = (lo + (hi - lo) * rng.random((n, 3))).astype(np.float32)
    d = rng.standard_normal((n, 3))
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)

    def work():
        for _ in range(batches_per_thread):
            emb.run(o, d, query="INTERSECT", output=1)

    times = []
    for _ in range(repeats):
        workers = [threading.Thread(target=work) for _ in range(threads)]
        t0 = time.perf_counter()
        for w in workers:
            w.start()
        for w in workers:
            w.join()
        times.append(time.perf_counter() - t0)
    return threads * batches_per_thread * n / statistics.median(times)


def ours(scene: Scene, spp: int, repeats: int) -> dict:
    pt = PathTracer()
    pt.render(scene.with_resolution(8, 8), 1, 0)  # numba cache load / compile
    runs = [pt.render(scene, spp, seed=k) for k in range(repeats)]
    t = statistics.median(r.time_s for r in runs)
    rays = statistics.median(r.info["rays"] for r in runs)
    paths = scene.camera.width * scene.camera.height * spp
    return {"time_s": t, "paths_per_s": paths / t, "rays_per_s": rays / t, "rays_per_path": rays / paths}


def mitsuba(scene: Scene, spp: int, repeats: int) -> dict:
    adapter = Mitsuba3()
    variant, note = adapter.variant()
    import mitsuba as mi

    mi_scene = mi.load_dict(scene_dict(scene, spp))
    np.asarray(mi.render(mi_scene, spp=spp, seed=12345))  # JIT warm-up
    times = []
    for k in range(repeats):
        t0 = time.perf_counter()
        np.asarray(mi.render(mi_scene, spp=spp, seed=k))  # asarray waits for the kernel
        times.append(time.perf_counter() - t0)
    t = statistics.median(times)
    return {"time_s": t, "paths_per_s": scene.camera.width * scene.camera.height * spp / t, "variant": variant}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="cornell-box")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", action="store_true", help="print the results as JSON too")
    args = ap.parse_args()
    base = resolve_scene(args.scene)
    threads = default_threads()
    raw = raw_embree_rays_per_s(base, threads, args.repeats)
    results = {"threads": threads, "cpus": os.cpu_count(), "spp": args.spp,
               "resolution": [base.camera.width, base.camera.height], "raw_embree_rays_per_s": raw, "depths": {}}
    print(f"{args.scene} {base.camera.width}x{base.camera.height}, {args.spp} spp, {threads} threads, "
          f"median of {args.repeats}")
    print(f"(a) raw embreex closest-hit: {raw / 1e6:7.2f} M rays/s")
    for max_depth in (base.max_depth, 8):
        scene = base.with_max_depth(max_depth)
        o, m = ours(scene, args.spp, args.repeats), mitsuba(scene, args.spp, args.repeats)
        label = "unbounded" if max_depth < 0 else f"max_depth {max_depth}"
        print(f"--- {label}")
        print(f"(b) ours:    {o['paths_per_s'] / 1e6:7.3f} M paths/s  {o['rays_per_s'] / 1e6:7.2f} M rays/s "
              f"({o['rays_per_path']:.2f} rays/path)")
        print(f"(c) mitsuba: {m['paths_per_s'] / 1e6:7.3f} M paths/s  ({m['variant']})")
        print(f"    ours/mitsuba paths/s = {o['paths_per_s'] / m['paths_per_s']:.2f}   "
              f"our rays / raw rays = {o['rays_per_s'] / raw:.2f}")
        results["depths"][label] = {"ours": o, "mitsuba": m,
                                    "ours_over_mitsuba": o["paths_per_s"] / m["paths_per_s"],
                                    "our_rays_over_raw": o["rays_per_s"] / raw}
    if args.json:
        print(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
