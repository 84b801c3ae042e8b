"""Photon mapping's speed: photon throughput, the kd-tree, and time to error against the path tracer.

Three measurements on ``cornell-box-caustics``, each a median over
``--repeats`` runs in one process (the machine is noisy: ratios and medians,
not single times):

1. **Throughput**: photons traced per second (global-map photons, every
   diffuse hit stored), against our path tracer's camera paths and rays per
   second on the same scene.
2. **kd-tree**: cKDTree build time over 1 M stored photons and the time of
   a k = 30 nearest-neighbour query (the photon mapper's default) per
   point; and the issue's target, 1 M photons traced and indexed in ≤ 2 s.
3. **Time to error**: ``pathtracer``, ``photonmap`` and ``sppm`` through the
   harness's convergence workflow (:func:`cornell_harness.workflows.converge.run_experiment`,
   what ``cbox converge`` runs; resumable in ``--out``), and the median
   time over seeds at which each reaches a caustic-region relMSE of 0.05 and
   0.01 and an image-wide ΔE mean of 2 (:func:`cornell_harness.evaluate.convergence.time_to_target`).
   photonmap's budget is its photon counts as well as spp (its error stops
   falling with spp at its bias): it runs at spp 1..64 for 250k and 1M
   stored photons per map; SPPM also from a larger initial radius, with 1
   and 4 photons per pixel per iteration.

Each table is printed, and with ``--markdown BENCHMARKS.md`` written into that file's blocks
``photons.py#throughput``, ``photons.py#kd-tree`` and ``photons.py#time-to-error`` (``benchmarks/markdown_blocks.py``).

Run: ``.venv/bin/python benchmarks/photons.py --seeds 3 --markdown BENCHMARKS.md`` (about 25 minutes on 2 cores).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

import markdown_blocks

from cornell_harness.adapters.registry import resolve
from cornell_harness.adapters.seeds import pass_key
from cornell_harness.evaluate.convergence import time_to_target
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.references import load_reference
from cornell_harness.workflows.converge import run_experiment
from cornell_harness.workflows.spp_list import parse_spp_list
from cornell_harness.renderers.core.geometry import SceneGeometry
from cornell_harness.renderers.core.photons import STORE_ALL, shoot
from cornell_harness.adapters.api import default_threads
from cornell_harness.renderers.pathtracer import PathTracer

TARGETS = (("region.caustic.rel_mse", 0.05), ("region.caustic.rel_mse", 0.01), ("delta_e2000_mean", 2.0))
METRIC_LABELS = {"region.caustic.rel_mse": "caustic relMSE", "delta_e2000_mean": "ΔE mean"}
#: How the time-to-error table names each run (by the renderer's canonical name).
LABELS = {"sppm": "**sppm** (initial radius 2 footprints, the default)",
          "sppm[initial_radius=4.0]": "sppm, initial radius 4",
          "sppm[initial_radius=4.0,photons_per_iteration=262144]":
              "sppm, initial radius 4, 4 photons per pixel per iteration",
          "photonmap": "photonmap (250k + 250k photons)",
          "photonmap[caustic_photons=1000000,global_photons=1000000]": "photonmap (1M + 1M photons)"}


def throughput(scene, repeats: int, threads: int) -> list[str]:
    geom = SceneGeometry(scene)
    shoot(geom, scene, pass_key(0, 0, 1), 1 << 14, STORE_ALL, threads)  # compile
    rates, ray_rates, stored = [], [], 0
    for r in range(repeats):
        geom.rays = 0
        t = time.perf_counter()
        ph, emitted = shoot(geom, scene, pass_key(r, 0, 1), 1_000_000, STORE_ALL, threads)
        dt = time.perf_counter() - t
        rates.append(emitted / dt)
        ray_rates.append(geom.rays / dt)
        stored = len(ph)
    pt = [PathTracer(threads).render(scene, 16, r) for r in range(repeats)]
    pixels = scene.camera.width * scene.camera.height
    paths = statistics.median(16 * pixels / p.time_s for p in pt)
    pt_rays = statistics.median(p.info["rays"] / p.time_s for p in pt)
    print(f"## Throughput ({threads} threads, median of {repeats})\n")
    table = ["| | per second | ratio to the path tracer |", "|---|---|---|",
             f"| photons emitted (1 M; {stored / 1e6:.2f} M stored: every diffuse hit) | "
             f"{statistics.median(rates) / 1e6:.2f} M | {statistics.median(rates) / paths:.2f} (per camera path) |",
             f"| photon rays (Embree queries) | {statistics.median(ray_rates) / 1e6:.2f} M | "
             f"{statistics.median(ray_rates) / pt_rays:.2f} (per ray) |",
             f"| path tracer camera paths (16 spp) | {paths / 1e6:.2f} M | 1 |",
             f"| path tracer rays (closest-hit and shadow) | {pt_rays / 1e6:.2f} M | 1 |"]
    print("\n".join(table) + "\n")
    return table


def kd_tree(scene, repeats: int, threads: int) -> list[str]:
    geom = SceneGeometry(scene)
    builds, queries, traced = [], [], []
    for r in range(repeats):
        t = time.perf_counter()
        ph, emitted = shoot(geom, scene, pass_key(r, 0, 1), 1_000_000, STORE_ALL, threads, stored=True)
        t_trace = time.perf_counter() - t
        t = time.perf_counter()
        tree = cKDTree(ph.position, balanced_tree=False, compact_nodes=False)
        builds.append(time.perf_counter() - t)
        traced.append(t_trace + builds[-1])
        pts = ph.position[:: max(1, len(ph) // 100_000)].astype(np.float64)
        t = time.perf_counter()
        tree.query(pts, k=30, distance_upper_bound=0.1, workers=threads)
        queries.append((time.perf_counter() - t) / len(pts))
    print(f"## kd-tree over 1 M stored photons ({threads} threads, median of {repeats})\n")
    table = ["| | time |", "|---|---|",
             f"| trace until 1 M are stored, then build the tree | **{statistics.median(traced):.2f} s** "
             f"(target ≤ 2 s) |",
             f"| cKDTree build | {statistics.median(builds):.2f} s |",
             f"| k = 30 query, per point ({threads} workers) | {statistics.median(queries) * 1e6:.1f} µs |"]
    print("\n".join(table) + "\n")
    return table


def time_to_error(scene, seeds: int, out: Path) -> list[str]:
    reference = load_reference(scene)
    runs = [(["pathtracer"], "1,2,4,...,1024"), (["sppm"], "1,2,4,...,256"),
            (["sppm[initial_radius=4]"], "1,2,4,...,256"),
            (["sppm[initial_radius=4,photons_per_iteration=262144]"], "1,2,4,...,64"),
            (["photonmap", "photonmap[global_photons=1000000,caustic_photons=1000000]"], "1,2,4,...,64")]
    print(f"## Time to error on cornell-box-caustics (median over seeds 0-{seeds - 1})\n")
    lines = ["| renderer | " + " | ".join(f"{METRIC_LABELS[m]} ≤ {v:g}" for m, v in TARGETS)
             + " | best caustic relMSE (time) |", "|---|" + "---|" * (len(TARGETS) + 1)]
    times = {}
    for specs, spp in runs:
        entries = resolve(specs)
        spps = parse_spp_list(spp)
        folder = out / specs[0].replace("[", "_").replace("]", "").replace("=", "_").replace(",", "_")
        table = run_experiment(folder, scene, reference, entries, spps, list(range(seeds)))
        for name, g in table[table["status"] == "ok"].groupby("renderer", sort=False):
            t = [time_to_target(g, m, v) for m, v in TARGETS]
            times[name] = t
            per_spp = g.groupby("spp")[["region.caustic.rel_mse", "time_s"]].median()
            best = per_spp["region.caustic.rel_mse"].idxmin()
            lines.append(f"| {LABELS.get(name, name)} | "
                         + " | ".join(f"{x:.1f} s" if np.isfinite(x) else "not reached" for x in t)
                         + f" | {per_spp.loc[best, 'region.caustic.rel_mse']:.4f} "
                           f"({per_spp.loc[best, 'time_s']:.0f} s) |")
    for other, bold in (("sppm", True), ("photonmap", False)):
        if "pathtracer" in times and other in times:
            ratios = [a / b if np.isfinite(a) and np.isfinite(b) else float("nan")
                      for a, b in zip(times["pathtracer"], times[other])]
            b = "**" if bold else ""
            lines.append(f"| {b}pathtracer / {other}{b} | " + " | ".join(f"{b}{r:.1f}×{b}" for r in ratios) + " | |")
    print("\n".join(lines) + "\n")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=3, help="repeats of the throughput and kd-tree figures")
    ap.add_argument("--seeds", type=int, default=3, help="seeds of the time-to-error runs")
    ap.add_argument("--out", type=Path, default=Path("out/bench-photons"), help="experiment folders (resumable)")
    ap.add_argument("--skip-time-to-error", action="store_true", help="only the throughput and kd-tree figures")
    ap.add_argument("--markdown", type=Path, action="append", default=[],
                    help="write the tables into this file's blocks photons.py#... (repeatable)")
    args = ap.parse_args()
    scene = resolve_scene("cornell-box-caustics")
    threads = default_threads()
    blocks = {"photons.py#throughput": "\n".join(throughput(scene, args.repeats, threads)),
              "photons.py#kd-tree": "\n".join(kd_tree(scene, args.repeats, threads))}
    if not args.skip_time_to_error:
        blocks["photons.py#time-to-error"] = "\n".join(time_to_error(scene, args.seeds, args.out))
    markdown_blocks.write_blocks(args.markdown, blocks)


if __name__ == "__main__":
    main()
