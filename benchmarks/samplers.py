"""Our samplers' cost per path and error at equal spp, in one run.

(a) ns of sample decisions per path: a numba kernel draws, per path, what the
    path tracer draws on ``cornell-box`` (the camera jitter, then at each of
    three vertices the emitter's point (2D), the emitter pick, the BSDF
    direction (2D) and roulette: 13 decisions) with the path's sampler state
    (:func:`cornell_harness.renderers.core.sampler.path_point`) recomputed at
    each vertex, as the bounce kernel does; the same loop without decisions
    is subtracted. Thread CPU time (the machine is shared: wall time is
    not), ``--rounds`` interleaved rounds of 2^16 paths, medians.
(b) MSE at ``--spp`` against the stored reference on ``--scene``, over
    seeds 0 .. ``--seeds`` - 1 (mean and range), with each sampler's batches
    (its reported variance) and with ``variance = none`` (one randomisation).
(c) what that is for the whole path tracer: ns of CPU per path of a render of
    ``--scene`` at ``--tracer-spp`` on one thread (process CPU time), median
    of ``--tracer-rounds`` interleaved rounds, for the samplers of (b).

``--markdown FILE`` writes all three into the file's block ``samplers.py#cost``.
Run (about 10 minutes on 2 cores):

    .venv/bin/python benchmarks/samplers.py --markdown BENCHMARKS.md
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numba
import numpy as np

import markdown_blocks

from cornell_harness.cli.allocator import keep_freed_memory
from cornell_harness.renderers.core.sampler import (BSDF_U, EMITTER_PICK, EMITTER_U, ROULETTE, SAMPLERS,
                                                    camera_sample, pass_stream, path_point, vertex_1d, vertex_2d)
from cornell_harness.renderers.pathtracer import PathTracer
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.references import load_reference

VERTICES = 3
DECISIONS = 1 + 4 * VERTICES


@numba.njit(nogil=True)
def _decisions(st, first, n, draw):
    acc = 0.0
    for q in range(n):
        pt = path_point(st, first + q)
        if draw:
            u, v = camera_sample(st, pt)
            acc += u + v
        for depth in range(1, VERTICES + 1):
            pt = path_point(st, first + q)
            acc += float(pt[1]) + float(pt[0] >> np.uint64(40))  # keeps the state when nothing is drawn
            if draw:
                a, b = vertex_2d(st, pt, depth, EMITTER_U)
                d, e = vertex_2d(st, pt, depth, BSDF_U)
                acc += a + b + d + e + vertex_1d(st, pt, depth, EMITTER_PICK) + vertex_1d(st, pt, depth, ROULETTE)
    return acc


def decision_cost(rounds: int, paths: int = 1 << 16) -> dict[str, dict[str, float]]:
    """{sampler: {"total", "state", "decisions"}}: ns per path of the kernel, of its loop and sampler state
    without decisions, and their difference; medians over ``rounds`` interleaved rounds."""
    streams = {s: pass_stream(s, 0, 0, 256 * 256, 0) for s in SAMPLERS}
    times = {(s, d): [] for s in SAMPLERS for d in (True, False)}
    for st in streams.values():
        _decisions(st, 0, 16, True), _decisions(st, 0, 16, False)  # compile
    for r in range(rounds):
        for (s, draw), ts in times.items():
            t0 = time.thread_time()
            _decisions(streams[s], r * paths, paths, draw)
            ts.append((time.thread_time() - t0) / paths * 1e9)
    out = {}
    for s in SAMPLERS:
        total, state = statistics.median(times[s, True]), statistics.median(times[s, False])
        out[s] = {"total": total, "state": state, "decisions": total - state}
    return out


def errors(scene_name: str, spp: int, seeds: int, samplers: list[str]) -> dict[tuple[str, str], list[float]]:
    """{(sampler, variance mode): MSE of each seed} at ``spp`` against the stored reference."""
    scene = resolve_scene(scene_name)
    ref = np.asarray(load_reference(scene).image, dtype=np.float64)
    pt = PathTracer()
    out = {}
    for variance in ("batches", "none"):
        for sampler in samplers:
            settings = {"sampler": sampler, "variance": variance}
            pt.render(scene.with_resolution(8, 8), 1, 0, settings=settings)  # compile
            out[sampler, variance] = [float(np.mean((pt.render(scene, spp, seed, settings=settings).image - ref) ** 2))
                                      for seed in range(seeds)]
    return out


def tracer_cost(scene_name: str, spp: int, rounds: int, samplers: list[str]) -> dict[str, float]:
    """{sampler: ns of CPU per path of the whole path tracer}: renders of ``scene_name`` at ``spp`` on one thread,
    process CPU time, median over ``rounds`` interleaved rounds (seed = round)."""
    scene = resolve_scene(scene_name)
    pt = PathTracer(threads=1)
    paths = scene.camera.width * scene.camera.height * spp
    times = {s: [] for s in samplers}
    for s in samplers:
        pt.render(scene.with_resolution(8, 8), 1, 0, settings={"sampler": s})  # compile
    for r in range(rounds):
        for s, ts in times.items():
            t0 = time.process_time()
            pt.render(scene, spp, r, settings={"sampler": s})
            ts.append((time.process_time() - t0) / paths * 1e9)
    return {s: statistics.median(ts) for s, ts in times.items()}


def markdown(cost: dict, mse: dict, tracer: dict, spp: int, seeds: int, tracer_spp: int) -> list[str]:
    lines = [f"| sampler | ns per path: decisions ({DECISIONS}) | state ({VERTICES + 1}×) | total "
             f"| MSE ×1e5, {spp} spp, 8 batches: mean [min, max] of {seeds} seeds | the same, `variance = none` "
             f"| path tracer, ns of CPU per path ({tracer_spp} spp, one thread) |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for s, c in cost.items():
        if (s, "none") not in mse:
            continue
        cells = [f"{np.mean(v) * 1e5:.3f} [{min(v) * 1e5:.3f}, {max(v) * 1e5:.3f}]"
                 for v in (mse[s, "batches"], mse[s, "none"])]
        lines.append(f"| `{s}` | {c['decisions']:.0f} | {c['state']:.0f} | {c['total']:.0f} | " + " | ".join(cells)
                     + f" | {tracer[s]:.0f} |")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="cornell-box")
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--rounds", type=int, default=31)
    ap.add_argument("--samplers", default="independent,pmj02,pmj02table", help="samplers of (b) and (c), comma-separated")
    ap.add_argument("--tracer-spp", type=int, default=64)
    ap.add_argument("--tracer-rounds", type=int, default=5)
    ap.add_argument("--markdown", type=Path, action="append", default=[],
                    help="write the table into this file's block samplers.py#cost (repeatable)")
    args = ap.parse_args()
    keep_freed_memory()
    cost = decision_cost(args.rounds)
    for s, c in cost.items():
        print(f"{s:12s} decisions {c['decisions']:6.1f}  state {c['state']:6.1f}  total {c['total']:6.1f} ns/path")
    samplers = args.samplers.split(",")
    tracer = tracer_cost(args.scene, args.tracer_spp, args.tracer_rounds, samplers)
    for s, ns in tracer.items():
        print(f"{s:12s} path tracer {ns:7.1f} ns of CPU per path")
    mse = errors(args.scene, args.spp, args.seeds, samplers)
    for (s, variance), v in mse.items():
        print(f"{s:12s} variance={variance:8s} MSE {np.mean(v):.4e}  seeds {' '.join(f'{x:.3e}' for x in v)}")
    lines = markdown(cost, mse, tracer, args.spp, args.seeds, args.tracer_spp)
    markdown_blocks.write_blocks(args.markdown, {"samplers.py#cost": "\n".join(lines)})


if __name__ == "__main__":
    main()
