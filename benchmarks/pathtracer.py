"""Path tracer speed and efficiency, in one run: ours vs Mitsuba 3, and our rays vs raw embreex.

On ``cornell-box`` at the same resolution, spp and max_depth for both:

(a) raw embreex closest-hit rays/s on the scene's triangles (random rays
    from inside the box, batches of 2^17 on the same number of threads);
(b) our path tracer: paths/s and rays/s (closest-hit + shadow rays);
(c) Mitsuba ``path`` integrator (``llvm_ad_rgb`` when LLVM is found), paths/s
    after a warm-up render that compiles its kernels;
(d) efficiency 1/(MSE·time) at ``--efficiency-spp`` against the stored
    reference, median over ``--seeds`` seeds, for each of our samplers and
    Mitsuba's ``independent``, ``multijitter`` and ``ldsampler``;
(e) time to ΔE mean ≤ ``--target`` (CIEDE2000, the harness's metric), median
    over the seeds: ours with the sampler of best efficiency (checkpoints of one
    progressive render, every power of two from 16), Mitsuba with its best (one
    timed render per spp of :data:`MITSUBA_SPPS`), interpolated log-log between
    the renders that bracket it;
(f) where one thread's time per path goes, with the scene's max_depth: the
    whole bounce loop per work unit, and Embree's queries alone (timed in a
    Python copy of the loop that must give the kernel's estimates bit for
    bit), against Mitsuba's whole path per thread (threads ÷ its paths/s).

Each throughput figure is the median of ``--repeats`` timed runs; the ratios
printed are ours/Mitsuba (paths/s, efficiency, time to target) and our rays/s
over raw rays/s. ``--markdown FILE`` (repeatable) writes (a)-(c), (d), (e) and (f) into the file's blocks
``pathtracer.py#throughput``, ``#efficiency``, ``#time-to-target`` and ``#breakdown``
(``benchmarks/markdown_blocks.py``); (f) runs with (a)-(c), part ``abc``.
Run (about 15 minutes on 2 cores):

    .venv/bin/python -m benchmarks.pathtracer --spp 64 --repeats 5 --json --markdown BENCHMARKS.md
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import statistics
import sys
import threading
import time
from pathlib import Path

import numpy as np

import pandas as pd

from benchmarks import markdown_blocks
from cornell_harness.evaluate import metrics
from cornell_harness.evaluate.convergence import time_to_target
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.model import Scene, triangle_arrays
from cornell_harness.store.references import load_reference
from cornell_harness.renderers import pathtracer
from cornell_harness.renderers.core.adapter import warmed_geometry
from cornell_harness.renderers.core.camera import camera_basis, camera_rays
from cornell_harness.renderers.core.embree import closest_triangles, segments_clear
from cornell_harness.renderers.core.geometry import Hits
from cornell_harness.renderers.core.rays import add_unoccluded, wavefront
from cornell_harness.renderers.core.roulette import RR_DEPTH
from cornell_harness.renderers.core.sampler import SAMPLER_SETTING, SAMPLERS, independent, pass_stream
from cornell_harness.adapters.api import default_threads, process_cpu_s
from cornell_harness.cli.allocator import keep_freed_memory
from cornell_harness.renderers.mitsuba3 import Mitsuba3, scene_dict
from cornell_harness.renderers.pathtracer import PathTracer, trace_paths

#: The command the blocks name (run as a module, so that other benchmarks can import this one).
COMMAND = " ".join([".venv/bin/python -m benchmarks.pathtracer", *map(shlex.quote, sys.argv[1:])])
RAW_BATCH = 1 << 17  # rays per embreex call in (a): large, its best case
MITSUBA_SAMPLERS = ("independent", "multijitter", "ldsampler")
#: Our renders of (d) and (e): each sampler with its default variance (pmj02 and sobol: 8 batches), and pmj02 as
#: one randomisation that reports no variance (``variance = none``), as Mitsuba's samplers do.
OURS = {**{sampler: {"sampler": sampler} for sampler in SAMPLERS},
        "pmj02 variance=none": {"sampler": "pmj02", "variance": "none"}}
#: Squares and powers of two, so multijitter and ldsampler take them as they are.
MITSUBA_SPPS = (16, 64, 256, 1024, 4096)


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


def ours(scene: Scene, spp: int, repeats: int, sampler: str) -> dict:
    pt = PathTracer()
    settings = {"sampler": sampler}
    pt.render(scene.with_resolution(8, 8), 1, 0, settings=settings)  # numba cache load / compile
    runs = [pt.render(scene, spp, seed=k, settings=settings) for k in range(repeats)]
    t = statistics.median(r.time_s for r in runs)
    rays = statistics.median(r.info["rays"] for r in runs)
    paths = scene.camera.width * scene.camera.height * spp
    return {"time_s": t, "paths_per_s": paths / t, "rays_per_s": rays / t, "rays_per_path": rays / paths}


def time_per_path(scene: Scene, sampler: str, units: int, clock=time.perf_counter) -> dict:
    """Where one thread's time per path goes (ns): the whole bounce loop (:func:`cornell_harness.renderers.pathtracer.trace_paths`,
    one work unit of 2^15 paths at a time), and Embree's queries alone, timed in :func:`_replay_queries`. The rest
    is shading, sampling and the buffers. Medians over ``units`` consecutive units of one pass, on ``clock``
    (seconds; :func:`time.thread_time` for the calling thread's CPU time, which a shared machine's waits leave
    out: the kernels and Embree's calls run on that thread)."""
    cam = scene.camera
    pixels, m = cam.width * cam.height, 1 << 15
    stream = pass_stream(sampler, 0, 0, pixels, 0)
    geom, _ = warmed_geometry(scene, lambda g: trace_paths(g, scene, 0, 1, 1, independent(0)))
    whole, queries = [], []
    for k in range(units):
        t0 = clock()
        estimates = trace_paths(geom, scene, k * m, (k + 1) * m, pixels, stream)
        whole.append(clock() - t0)
        replayed, spent = _replay_queries(geom, scene, k * m, m, pixels, stream, clock)
        assert np.array_equal(estimates, replayed), "the replay no longer traces the kernel's rays"
        queries.append(spent)
    ns = {"whole": statistics.median(whole) / m * 1e9, "embree": statistics.median(queries) / m * 1e9}
    return {**ns, "rest": ns["whole"] - ns["embree"]}


def _replay_queries(geom, scene: Scene, first: int, m: int, pixels: int, stream,
                    clock=time.perf_counter) -> tuple[np.ndarray, float]:
    """The estimates of paths ``first .. first + m - 1`` and the seconds spent in Embree's queries: a Python copy
    of :func:`cornell_harness.renderers.pathtracer._trace`'s loop (no spheres) that calls the same kernels, bounce by bounce, and
    times the two queries (called with plain arrays: their call costs ~1 µs). :func:`time_per_path` checks that
    it gives the kernel's estimates bit for bit."""
    assert not geom.has_spheres
    cam, geo = scene.camera, geom.tables()
    wf, L = wavefront(m, False), np.zeros((m, 3))
    paths = pathtracer.Paths(L, np.zeros((0, 6)), np.ones(0, np.bool_))
    cur, nxt = wf.cur, wf.nxt
    camera_rays(camera_basis(cam), cam.width, cam.height, first, pixels, stream, cur)
    n, depth, spent = m, 1, 0.0
    while n:
        prim = wf.prim[:n]
        t0 = clock()
        closest_triangles(geo.embree, cur.o32, cur.d32, prim, wf.record, depth == 1)  # camera rays: coherent
        spent += clock() - t0
        extend = scene.max_depth < 0 or depth + 1 <= scene.max_depth
        ns, n = pathtracer._shade(Hits(prim, wf.t_sphere[:n]), cur, stream, first, depth, extend, depth >= RR_DEPTH,
                                  geo, paths, pathtracer.Bounce(wf.shadow, nxt))
        if ns:
            visible = wf.visible[:ns]
            t0 = clock()
            segments_clear(geo.embree, wf.shadow.o, wf.shadow.d, wf.shadow.t, visible, wf.record)
            spent += clock() - t0
            add_unoccluded(L, wf.shadow, visible)
        cur, nxt = nxt, cur
        depth += 1
    return L, spent


def breakdown_markdown(per_path: dict, mitsuba_paths_per_s: float, threads: int) -> list[str]:
    """(f): one thread's ns per path, ours per sampler, against Mitsuba's whole path per thread."""
    samplers = list(per_path)
    mi = threads / mitsuba_paths_per_s * 1e9
    rows = [("whole path (the bounce loop)", "whole"), ("Embree's queries (closest hit + shadow)", "embree"),
            ("shading, sampling, buffers (the rest)", "rest")]
    lines = ["| ns per path, one thread | " + " | ".join(f"ours `{s}`" for s in samplers) + " |",
             "| --- |" + " --- |" * len(samplers)]
    lines += [f"| {name} | " + " | ".join(f"{per_path[s][key]:.0f} ({per_path[s][key] / mi:.2f}× Mitsuba's path)"
                                          for s in samplers) + " |" for name, key in rows]
    lines.append(f"| Mitsuba `path`, whole path ({threads} threads ÷ paths/s of (c)) | "
                 + " | ".join(f"{mi:.0f}" for _ in samplers) + " |")
    return lines


def mitsuba(scene: Scene, spp: int, repeats: int) -> dict:
    mi_scene = mitsuba_scene(scene, spp, "independent")
    t = statistics.median(mitsuba_render(mi_scene, spp, k)[1] for k in range(repeats))
    return {"time_s": t, "paths_per_s": scene.camera.width * scene.camera.height * spp / t,
            "variant": Mitsuba3().variant()[0]}


def mitsuba_scene(scene: Scene, spp: int, sampler: str):
    """The scene loaded in Mitsuba with ``sampler``, its kernels compiled by one render at ``spp``."""
    import mitsuba as mi

    Mitsuba3().variant()  # selects the variant
    mi_scene = mi.load_dict(scene_dict(scene, spp, sampler))
    np.asarray(mi.render(mi_scene, spp=spp, seed=12345))  # JIT warm-up
    return mi_scene


def mitsuba_render(mi_scene, spp: int, seed: int) -> tuple[np.ndarray, float, float]:
    """One render of a loaded Mitsuba scene: (image, wall seconds, CPU seconds of the process)."""
    import mitsuba as mi

    t0, c0 = time.perf_counter(), process_cpu_s()
    img = np.asarray(mi.render(mi_scene, spp=spp, seed=seed), dtype=np.float64)  # asarray waits for the kernel
    return img, time.perf_counter() - t0, process_cpu_s() - c0


def efficiency(scene: Scene, ref: np.ndarray, spp: int, seeds: int) -> dict:
    """{label: (median MSE, median time s, 1/(MSE·time))} for our samplers and Mitsuba's, at ``spp``."""
    out = {}
    pt = PathTracer()
    for label, settings in OURS.items():
        pt.render(scene.with_resolution(8, 8), 1, 0, settings=settings)  # compile
        runs = [pt.render(scene, spp, seed, settings=settings) for seed in range(seeds)]
        out[f"ours {label}"] = _figures([np.mean((r.image - ref) ** 2) for r in runs], [r.time_s for r in runs])
    for sampler in MITSUBA_SAMPLERS:
        mi_scene = mitsuba_scene(scene, spp, sampler)
        runs = [mitsuba_render(mi_scene, spp, seed) for seed in range(seeds)]
        out[f"mitsuba {sampler}"] = _figures([np.mean((img - ref) ** 2) for img, _, _ in runs], [t for _, t, _ in runs])
    return out


def _figures(mses: list, times: list) -> tuple[float, float, float]:
    mse, t = statistics.median(mses), statistics.median(times)
    return mse, t, 1.0 / (mse * t)


def time_to_delta_e(scene: Scene, ref: np.ndarray, ours: list[str], mitsuba_sampler: str, target: float,
                    seeds: int, max_spp: int) -> dict[str, float]:
    """Median seconds to ΔE mean ≤ ``target`` of each of ``ours`` (labels of :data:`OURS`) and of Mitsuba's
    ``mitsuba_sampler`` (key ``mitsuba``); NaN if not reached by ``max_spp``."""
    exposure = metrics.exposure_scale(ref)
    spps = [s for s in MITSUBA_SPPS if s <= max_spp]
    rows = []
    pt = PathTracer()
    checkpoints = [1 << k for k in range(4, max_spp.bit_length()) if 1 << k <= max_spp]  # free for us
    for label in ours:
        for seed in range(seeds):
            r = pt.render(scene, max_spp, seed, checkpoints=checkpoints, settings=OURS[label])
            rows += [(label, seed, c.time_s, metrics.delta_e2000(c.image, ref, exposure)) for c in r.checkpoints]
    mi_scenes = {spp: mitsuba_scene(scene, spp, mitsuba_sampler) for spp in spps}
    for seed in range(seeds):
        for spp in spps:
            img, t, _ = mitsuba_render(mi_scenes[spp], spp, seed)
            rows.append(("mitsuba", seed, t, metrics.delta_e2000(img, ref, exposure)))
    df = pd.DataFrame(rows, columns=["who", "seed", "time_s", "delta_e"])
    return {who: time_to_target(df[df.who == who], "delta_e", target) for who in (*ours, "mitsuba")}


def throughput_markdown(results: dict) -> list[str]:
    """(a)-(c) as BENCHMARKS.md tabulates them: per depth, Mitsuba's paths/s and ours per sampler (ratio to it)."""
    depths = results["depths"]
    variant = next(iter(depths.values()))["mitsuba"]["variant"]
    lines = ["| | " + " | ".join(depths) + " |", "| --- |" + " --- |" * len(depths),
             f"| (a) raw embreex closest-hit rays/s | {results['raw_embree_rays_per_s'] / 1e6:.2f} M |"
             + " same run |" * (len(depths) - 1),
             f"| (c) Mitsuba `{variant}` paths/s | "
             + " | ".join(f"{d['mitsuba']['paths_per_s'] / 1e6:.3f} M" for d in depths.values()) + " |"]
    for sampler in ("independent", "pmj02"):
        note = " (default)" if sampler == SAMPLER_SETTING.default else ""
        lines.append(f"| (b) ours `{sampler}`{note} paths/s | " + " | ".join(
            f"{d[f'ours {sampler}']['paths_per_s'] / 1e6:.3f} M (**{d[f'ours {sampler}']['ours_over_mitsuba']:.2f}×**)"
            for d in depths.values()) + " |")
    return lines


def efficiency_markdown(eff: dict) -> list[str]:
    """(d): RMSE, time and 1/(MSE·time) per sampler, against Mitsuba's multijitter (ours' default in bold)."""
    baseline = eff["mitsuba multijitter"][2]
    lines = ["| | RMSE | time (s) | efficiency | / Mitsuba multijitter |", "|---|---|---|---|---|"]
    for label, (mse, t, e) in eff.items():
        who, what = label.split(maxsplit=1)
        default = who == "ours" and what == SAMPLER_SETTING.default
        name = f"{'ours' if who == 'ours' else 'Mitsuba'} `{what}`" + (" (default)" if default else "")
        lines.append(f"| {name} | {mse ** 0.5:.5f} | {t:.2f} | {e:.1f} | "
                     f"{markdown_blocks.bold(f'{e / baseline:.2f}', default)} |")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="cornell-box")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--seeds", type=int, default=3, help="seeds of (d) and (e) (medians over them)")
    ap.add_argument("--units", type=int, default=20, help="work units of 2^15 paths timed one by one for (f)")
    ap.add_argument("--efficiency-spp", type=int, default=256, help="spp of the efficiency comparison (d)")
    ap.add_argument("--target", type=float, default=1.0, help="ΔE mean of the time-to-target comparison (e)")
    ap.add_argument("--max-spp", type=int, default=1024, help="largest spp rendered for (e)")
    ap.add_argument("--parts", default="abc,d,e", help="which parts to run, comma-separated: abc (throughput), "
                    "d (efficiency), e (time to target, which needs d's ranking); default all")
    ap.add_argument("--json", action="store_true", help="print the results as JSON too")
    ap.add_argument("--markdown", type=Path, action="append", default=[],
                    help="write the parts run into this file's blocks pathtracer.py#... (repeatable)")
    args = ap.parse_args()
    keep_freed_memory()  # as every cbox command runs (cornell_harness.cli.allocator): ours measured as users run it
    base = resolve_scene(args.scene)
    threads = default_threads()
    parts = set(args.parts.split(","))
    raw = raw_embree_rays_per_s(base, threads, args.repeats) if "abc" in parts else 0.0
    results = {"threads": threads, "cpus": os.cpu_count(), "spp": args.spp,
               "resolution": [base.camera.width, base.camera.height], "raw_embree_rays_per_s": raw, "depths": {}}
    print(f"{args.scene} {base.camera.width}x{base.camera.height}, {args.spp} spp, {threads} threads, "
          f"median of {args.repeats}")
    print(f"(a) raw embreex closest-hit: {raw / 1e6:7.2f} M rays/s")
    for max_depth in (base.max_depth, 8) if "abc" in parts else ():
        scene = base.with_max_depth(max_depth)
        m = mitsuba(scene, args.spp, args.repeats)
        label = "unbounded" if max_depth < 0 else f"max_depth {max_depth}"
        print(f"--- {label}")
        print(f"(c) mitsuba: {m['paths_per_s'] / 1e6:7.3f} M paths/s  ({m['variant']}, independent sampler)")
        results["depths"][label] = {"mitsuba": m}
        for sampler in ("independent", "pmj02"):
            o = ours(scene, args.spp, args.repeats, sampler)
            print(f"(b) ours ({sampler}): {o['paths_per_s'] / 1e6:7.3f} M paths/s  {o['rays_per_s'] / 1e6:7.2f} M "
                  f"rays/s ({o['rays_per_path']:.2f} rays/path); ours/mitsuba paths/s = "
                  f"{o['paths_per_s'] / m['paths_per_s']:.2f}, our rays / raw rays = {o['rays_per_s'] / raw:.2f}")
            results["depths"][label][f"ours {sampler}"] = {**o, "ours_over_mitsuba": o["paths_per_s"] / m["paths_per_s"],
                                                          "our_rays_over_raw": o["rays_per_s"] / raw}
    blocks = {"pathtracer.py#throughput": throughput_markdown(results)} if "abc" in parts else {}
    if "abc" in parts:
        per_path = {sampler: time_per_path(base, sampler, args.units) for sampler in ("independent", "pmj02")}
        first = next(iter(results["depths"].values()))
        print(f"--- (f) one thread, ns per path ({args.units} units of 2^15 paths)")
        for sampler, ns in per_path.items():
            print(f"ours ({sampler}): whole {ns['whole']:.0f}, Embree {ns['embree']:.0f}, rest {ns['rest']:.0f}")
        print(f"mitsuba: whole {threads / first['mitsuba']['paths_per_s'] * 1e9:.0f} (per thread)")
        results["ns_per_path"] = per_path
        blocks["pathtracer.py#breakdown"] = breakdown_markdown(per_path, first["mitsuba"]["paths_per_s"], threads)
    if not {"d", "e"} & parts:
        if args.json:
            print(json.dumps(results, indent=1))
        markdown_blocks.write_blocks(args.markdown, {k: "\n".join(v) for k, v in blocks.items()}, COMMAND)
        return
    ref = np.asarray(load_reference(base).image, dtype=np.float64)
    eff = efficiency(base, ref, args.efficiency_spp, args.seeds)  # (e) picks each side's best sampler from it
    print(f"--- (d) efficiency 1/(MSE·time) at {args.efficiency_spp} spp, median of {args.seeds} seeds")
    baseline = eff["mitsuba multijitter"][2]
    for label, (mse, t, e) in eff.items():
        print(f"{label:22s} RMSE {mse ** 0.5:.5f}  time {t:6.2f} s  efficiency {e:9.1f}  "
              f"/ mitsuba multijitter {e / baseline:.2f}")
    best_ours = max((k for k in eff if k.startswith("ours")), key=lambda k: eff[k][2]).split(maxsplit=1)[1]
    best_mi = max((k for k in eff if k.startswith("mitsuba")), key=lambda k: eff[k][2]).split()[1]
    labels = list(dict.fromkeys((SAMPLER_SETTING.default, best_ours)))  # the default, and the most efficient
    times = time_to_delta_e(base, ref, labels, best_mi, args.target, args.seeds, args.max_spp)
    mi_t = times["mitsuba"]
    print(f"--- (e) time to ΔE mean <= {args.target:g}, median of {args.seeds} seeds")
    for label in labels:
        print(f"ours ({label}) {times[label]:.2f} s   mitsuba ({best_mi}) {mi_t:.2f} s   "
              f"ours/mitsuba {times[label] / mi_t:.2f}")
    results.update(efficiency={k: dict(zip(("mse", "time_s", "efficiency"), v)) for k, v in eff.items()},
                   time_to_delta_e={"target": args.target, "ours": {k: times[k] for k in labels},
                                    "mitsuba": [best_mi, mi_t],
                                    "ours_over_mitsuba": {k: times[k] / mi_t for k in labels}})
    blocks["pathtracer.py#efficiency"] = efficiency_markdown(eff)
    blocks["pathtracer.py#time-to-target"] = [
        f"**(e) Time to ΔE mean ≤ {args.target:g}**, Mitsuba (`{best_mi}`) **{mi_t:.2f} s**; ours: " + "; ".join(
            f"`{label}` **{times[label]:.2f} s**, **ours / Mitsuba {times[label] / mi_t:.2f}**" for label in labels)
        + "."]
    if args.json:
        print(json.dumps(results, indent=1))
    markdown_blocks.write_blocks(args.markdown, {k: "\n".join(v) for k, v in blocks.items()}, COMMAND)


if __name__ == "__main__":
    main()
