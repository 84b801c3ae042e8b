"""Shading across the wavefront as structure-of-arrays loops: what LLVM's vectoriser buys the path tracer.

One bounce of :func:`cornell_harness.renderers.pathtracer._shade` on a wavefront of 2^15 Lambertian
cornell-box paths (real rays and hits: the camera rays of a render's first work unit and their closest hits,
then the rays the kernel continues them with and theirs), done four ways (``benchmarks/shading_soa_kernels.py``),
each timed in CPU ns per ray of the wavefront:

(a) the kernel itself, with the random numbers it draws (``independent`` and ``pmj02``);
(b) the draws alone: each lane's six numbers of the vertex (emitter pick and point, BSDF direction, roulette)
    by the real sampler, into arrays, one path at a time; for ``independent`` also as one array loop;
(c) the kernel's shading with those numbers, one path at a time (its work written out for Lambertian
    triangles): what (a) costs without its draws; and the same with cos and sin of the BSDF sample from
    polynomials instead of libm;
(d) the same shading as a sequence of loops over float64 arrays, each simple enough for LLVM to vectorise: the
    hit's tables fetched, the surface point and emission, the emission added, the emitter picked and its
    tables fetched, the light sample (point, geometry term, MIS, shadow segment), the BSDF sample and roulette,
    and the survivors written into the kernel's buffers; over chunks of lanes (the whole wavefront, or 2048
    or 256 at a time, so that the arrays stay in cache). First with LLVM's defaults, under which none of them
    vectorises (a loop over 20-30 arrays needs more run-time alias checks than the vectoriser adds), then with
    that limit raised (:func:`raise_alias_check_limit`), with LLVM's fast-math flags off, ``{contract}``,
    ``{contract, arcp}`` and all of them, and with the polynomial cos and sin.

(c) and (d) must write what (a) writes, bit for bit without fast-math and with libm's cos and sin (estimates,
shadow segments, next rays); otherwise the largest relative difference is reported. Which loops vectorised is
read from their assembly (packed double or 64-bit integer operations on zmm/ymm registers), and each loop of
(d) is also timed alone. Times: medians over interleaved rounds of the calling thread's CPU time
(``time.thread_time``; the machine is shared), each variant run ``--reps`` times inside one call, less a call
that runs it none (numba's typing of the scene's tables). Run (about 10 minutes on 2 cores):

    .venv/bin/python -m benchmarks.shading_soa --markdown BENCHMARKS.md
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shlex
import statistics
import sys
import time
from collections import Counter
from pathlib import Path
from typing import NamedTuple

import numpy as np

from benchmarks import markdown_blocks
from benchmarks.shading_soa_kernels import (ALL_LOOPS, LOOPS, draw_independent_soa, draw_per_path, draws, lanes,
                                            shade_kernel, shade_per_path, soa_kernels)
from cornell_harness.renderers import pathtracer
from cornell_harness.renderers.core.adapter import warmed_geometry
from cornell_harness.renderers.core.bsdf import LAMBERT
from cornell_harness.renderers.core.camera import camera_basis, camera_rays
from cornell_harness.renderers.core.embree import closest_triangles, segments_clear
from cornell_harness.renderers.core.geometry import Hits
from cornell_harness.renderers.core.rays import add_unoccluded, ray_buffer, shadow_buffer, wavefront
from cornell_harness.renderers.core.roulette import RR_DEPTH
from cornell_harness.renderers.core.sampler import independent, pass_stream
from cornell_harness.renderers.pathtracer import trace_paths
from cornell_harness.scenes.library import resolve_scene

COMMAND = " ".join([".venv/bin/python -m benchmarks.shading_soa", *map(shlex.quote, sys.argv[1:])])
WAVEFRONT = 1 << 15
#: The fast-math flag sets tried on the vector loops (numba's ``fastmath``).
FASTMATH = {"off": False, "{contract}": {"contract"}, "{contract, arcp}": {"contract", "arcp"}, "all": True}
CHUNKS = (WAVEFRONT, 2048, 256)
#: Run-time alias checks the loop vectoriser may add to a loop once its limit is raised (:func:`raise_alias_check_limit`).
ALIAS_CHECKS = 4096
#: (d) with the BSDF sample's cos and sin by polynomials.
POLY = "fast-math off, polynomial sin/cos"
#: The variants of (d) whose loops are timed one by one.
LOOP_CONFIGS = ("LLVM's defaults", "fast-math off", POLY)
#: The chunk the loops are timed one by one at.
LOOP_CHUNK = 2048

# -- the wavefronts, the checks and the clock ----------------------------------------------------------------

class Bounce(NamedTuple):
    """A wavefront's rays and their closest hits, as the kernel's bounce ``depth`` gets them."""

    depth: int
    rays: object  # RayBuffer, n rays
    prim: np.ndarray


def wavefronts(scene, geom, stream, bounces: int) -> tuple[list[Bounce], float]:
    """Bounces 1 .. ``bounces`` of the first work unit of a pass: :func:`benchmarks.pathtracer._replay_queries`'s
    loop, keeping copies of each bounce's rays and hits; and the rays shaded a path, every bounce counted."""
    cam, geo, m = scene.camera, geom.tables(), WAVEFRONT
    wf, L = wavefront(m, False), np.zeros((m, 3))
    paths = pathtracer.Paths(L, np.zeros((0, 6)), np.ones(0, np.bool_))
    cur, nxt = wf.cur, wf.nxt
    camera_rays(camera_basis(cam), cam.width, cam.height, 0, cam.width * cam.height, stream, cur)
    n, depth, shaded, out = m, 1, 0, []
    while n:
        prim = wf.prim[:n]
        closest_triangles(geo.embree, cur.o32, cur.d32, prim, wf.record, depth == 1)
        if depth <= bounces:
            out.append(Bounce(depth, type(cur)(*(a[:n].copy() for a in cur)), prim.copy()))
        shaded += n
        ns, n = pathtracer._shade(Hits(prim, wf.t_sphere[:n]), cur, stream, 0, depth, True, depth >= RR_DEPTH, geo,
                                  paths, pathtracer.Bounce(wf.shadow, nxt))
        visible = wf.visible[:ns]
        segments_clear(geo.embree, wf.shadow.o, wf.shadow.d, wf.shadow.t, visible, wf.record)
        add_unoccluded(L, wf.shadow, visible)
        cur, nxt = nxt, cur
        depth += 1
    return out, shaded / m


class Outputs(NamedTuple):
    L: np.ndarray
    shadow: object
    nxt: object


def outputs(m: int) -> Outputs:
    """A bounce's outputs for ``m`` rays: the estimates of the unit's paths (their indices, not the rays'), the
    shadow segments and the next rays."""
    return Outputs(np.zeros((WAVEFRONT, 3)), shadow_buffer(m), ray_buffer(m))


def written(out: Outputs, counts) -> list[np.ndarray]:
    """What a bounce wrote: the estimates, the shadow segments and the next rays (the counts' heads)."""
    ns, nn = counts
    return [out.L, *(a[:ns] for a in out.shadow), *(a[:nn] for a in out.nxt)]


def largest_difference(got: list, want: list) -> float:
    """The largest relative difference of two bounces' outputs (inf: they differ in shape or in an integer)."""
    worst = 0.0
    for a, b in zip(got, want):
        if a.shape != b.shape or (a.dtype.kind != "f" and not np.array_equal(a, b)):
            return math.inf
        if a.dtype.kind == "f" and a.size:
            d = np.abs(a.astype(np.float64) - b) / np.maximum(np.abs(b), 1e-300)
            worst = max(worst, float(np.max(np.where(a == b, 0.0, d))))
    return worst


def packed_ops(kernel) -> Counter:
    """The packed operations of a kernel's assembly on doubles or 64-bit integers (moves and shuffles left
    out), by register width (``zmm``: 8 lanes, ``ymm``: 4), and whether it calls libm's sin or cos (``call``)."""
    asm = kernel.inspect_asm(kernel.signatures[0])
    found = Counter()
    for line in asm.splitlines():
        m = re.match(r"\s+(v\w+)\s+(.*)", line)
        if (m and (reg := re.search(r"%([yz]mm)", m[2])) and re.search(r"(pd|q|gather\w*)$", m[1])
                and not m[1].startswith(("vmov", "vpbroadcast", "vbroadcast", "vextract", "vinsert", "vperm"))):
            found[reg[1]] += 1
        if re.search(r"\$(sin|cos|sincos)\b", line):
            found["call"] += 1
    return found


def evidence(found: Counter) -> str:
    """``packed_ops`` in words: the widest packed maths, and the libm calls."""
    width = "8 lanes (zmm)" if found["zmm"] else "4 lanes (ymm)" if found["ymm"] else "scalar"
    text = f"{width}: {found['zmm'] + found['ymm']} packed ops"
    return text + (", libm's sin/cos called lane by lane" if found["call"] else "")


def timed(variants: dict, reps: int, rounds: int) -> dict[str, float]:
    """Median seconds of one run of each variant (``variants[name](reps)`` runs it ``reps`` times in one call),
    on the thread's CPU clock, over ``rounds`` interleaved rounds after one untimed run each, less a call that runs
    it 0 times."""
    spent = {name: [] for name in variants}
    for run in variants.values():
        run(1)  # compiles what has not run yet
    for _ in range(rounds):
        for name, run in variants.items():
            t0 = time.thread_time()
            run(0)
            t1 = time.thread_time()
            run(reps)
            t2 = time.thread_time()
            spent[name].append(((t2 - t1) - (t1 - t0)) / reps)
    return {name: statistics.median(s) for name, s in spent.items()}


def raise_alias_check_limit() -> None:
    """Let LLVM's loop vectoriser add as many run-time alias checks as a loop needs (its default caps them at
    128 pointer pairs, and a loop over 20-30 numba arrays needs more: "loop not vectorized: too many memory
    checks needed"). A process-wide LLVM option, read when a kernel is compiled."""
    import llvmlite.binding as llvm

    llvm.set_option("", f"-vectorize-memory-check-threshold={ALIAS_CHECKS}")


def measure(scene_name: str, bounces: int, reps: int, rounds: int) -> dict:
    """Every variant on each of the first ``bounces`` bounces: ns per ray, the checks, the loops' assembly."""
    scene = resolve_scene(scene_name)
    cam = scene.camera
    pixels = cam.width * cam.height
    geom, _ = warmed_geometry(scene, lambda g: trace_paths(g, scene, 0, 1, 1, independent(0)))
    geo = geom.tables()
    assert not geom.has_spheres and np.all(geo.material == LAMBERT), "the prototype shades Lambertian triangles"
    streams = {s: pass_stream(s, 0, 0, pixels, 0) for s in ("independent", "pmj02")}
    fronts, shaded = wavefronts(scene, geom, streams["pmj02"], bounces)
    kernels = {"LLVM's defaults": soa_kernels(False)}
    b = fronts[0]
    kernels["LLVM's defaults"]["run"](1, 256, b.prim, b.rays, draws(b.prim.size), False, geo, *outputs(b.prim.size),
                                      lanes(256), ALL_LOOPS)  # compiled before the limit is raised
    raise_alias_check_limit()
    kernels.update({f"fast-math {label}": soa_kernels(flags) for label, flags in FASTMATH.items()})
    kernels[POLY] = soa_kernels(False, poly=True)
    results = {"scene": scene_name, "shaded_per_path": shaded, "bounces": []}
    for b in fronts:
        n, roulette = b.prim.size, b.depth >= RR_DEPTH
        u = {s: draws(n) for s in streams}
        for s, st in streams.items():
            draw_per_path(1, b.prim, b.rays.path, st, 0, b.depth, roulette, u[s])
        ts, ln = np.empty(0), lanes(max(CHUNKS))
        out = {name: outputs(n) for name in ("a", "c", "d")}
        want = written(out["a"], shade_kernel(1, b.prim, ts, b.rays, streams["pmj02"], 0, b.depth, roulette, geo,
                                              pathtracer.Paths(out["a"].L, np.zeros((0, 6)), np.ones(0, np.bool_)),
                                              pathtracer.Bounce(out["a"].shadow, out["a"].nxt)))
        checks = {f"(c){poly}": largest_difference(written(got, shade_per_path(
            1, b.prim, b.rays, u["pmj02"], roulette, geo, *got, bool(poly))), want)
            for poly, got in (("", out["c"]), (", polynomial sin/cos", outputs(n)))}
        for label, k in kernels.items():
            for chunk in CHUNKS:
                got = outputs(n)
                checks[f"(d) {label}, {chunk}"] = largest_difference(written(got, k["run"](
                    1, chunk, b.prim, b.rays, u["pmj02"], roulette, geo, *got, ln, ALL_LOOPS)), want)
        o = out["a"]
        variants = {f"(a) {s}": (lambda r, st=st: shade_kernel(
            r, b.prim, ts, b.rays, st, 0, b.depth, roulette, geo,
            pathtracer.Paths(o.L, np.zeros((0, 6)), np.ones(0, np.bool_)), pathtracer.Bounce(o.shadow, o.nxt)))
            for s, st in streams.items()}
        variants.update({f"(b) {s}": (lambda r, st=st, uu=u[s]: draw_per_path(
            r, b.prim, b.rays.path, st, 0, b.depth, roulette, uu)) for s, st in streams.items()})
        variants["(b) independent, array loop"] = lambda r: draw_independent_soa(
            r, b.rays.path, streams["independent"].key, 0, b.depth, roulette, u["independent"])
        for poly in (False, True):
            variants["(c), polynomial sin/cos" if poly else "(c)"] = (lambda r, poly=poly: shade_per_path(
                r, b.prim, b.rays, u["pmj02"], roulette, geo, *out["c"], poly))
        for label, k in kernels.items():
            for chunk in CHUNKS:
                variants[f"(d) {label}, {chunk}"] = (lambda r, k=k, chunk=chunk: k["run"](
                    r, chunk, b.prim, b.rays, u["pmj02"], roulette, geo, *out["d"], ln, ALL_LOOPS))
        for label in LOOP_CONFIGS:
            for j, loop in enumerate(LOOPS):
                variants[f"(d) {label}, {LOOP_CHUNK}, {loop}"] = (lambda r, k=kernels[label], j=j: k["run"](
                    r, LOOP_CHUNK, b.prim, b.rays, u["pmj02"], roulette, geo, *out["d"], ln, 1 << j))
        seconds = timed(variants, reps, rounds)
        results["bounces"].append({"depth": b.depth, "rays": n, "checks": checks,
                                   "ns_per_ray": {k: v / n * 1e9 for k, v in seconds.items()}})
    results["asm"] = {label: {name: evidence(packed_ops(f)) for name, f in k.items() if name != "run"}
                      for label, k in kernels.items()}
    results["asm_draws"] = {"independent, array loop": evidence(packed_ops(draw_independent_soa))}
    return results


def _cell(b: dict, key: str) -> str:
    return f"{b['ns_per_ray'][key]:.1f}"


def markdown(r: dict, reps: int, rounds: int) -> list[str]:
    """The block ``shading_soa.py``: the variants per bounce, then (d)'s loops one by one with their assembly."""
    bs = r["bounces"]
    chunks = " / ".join(map(str, CHUNKS))
    lines = [f"`{r['scene']}`, the first work unit of 2^15 paths (`pmj02`); CPU ns per ray of the wavefront, one "
             f"thread, medians of {rounds} interleaved rounds of {reps} runs each; load {r['load'][0]:.1f} → "
             f"{r['load'][1]:.1f} runnable threads on {os.cpu_count()} cores. {r['shaded_per_path']:.2f} rays "
             "a path are shaded in a whole render (every bounce's closest hits). Differences: the largest relative "
             "difference of the estimates, shadow segments and next rays from (a)'s, over the bounces.", "",
             "| CPU ns per ray, one thread | " + " | ".join(
                 f"bounce {b['depth']} ({b['rays']} rays)" for b in bs) + " | largest difference from (a) |",
             "| --- |" + " --- |" * (len(bs) + 1)]

    def diff(keys):
        worst = max(b["checks"][k] for b in bs for k in keys)
        return "0 (bit for bit)" if worst == 0 else f"{worst:.1e}"

    rows = [("(a) `_shade`, `independent`", "(a) independent", None),
            ("(a) `_shade`, `pmj02`", "(a) pmj02", None),
            ("(b) the draws alone, `independent`, path by path", "(b) independent", None),
            ("(b) the draws alone, `pmj02`, path by path", "(b) pmj02", None),
            ("(b) the draws alone, `independent`, one array loop (vectorised)", "(b) independent, array loop", None),
            ("(c) the shading alone, path by path", "(c)", ["(c)"]),
            ("(c) the same, cos and sin by polynomials", "(c), polynomial sin/cos", ["(c), polynomial sin/cos"])]
    for label, key, checks in rows:
        lines.append(f"| {label} | " + " | ".join(_cell(b, key) for b in bs) + f" | {diff(checks) if checks else ''} |")
    for label in [k for k in r["asm"]]:
        keys = [f"(d) {label}, {c}" for c in CHUNKS]
        lines.append(f"| (d) array loops, {label}; chunks of {chunks} lanes | " + " | ".join(
            " / ".join(_cell(b, k) for k in keys) for b in bs) + f" | {diff(keys)} |")
    lines += ["", f"(d)'s loops one by one, chunks of {LOOP_CHUNK} lanes: CPU ns per ray (bounce 1 / bounce 2), and "
              "what their assembly does (packed double or 64-bit integer operations, moves left out).", "",
              "| loop | " + " | ".join(f"{label}" for label in LOOP_CONFIGS) + " |",
              "| --- |" + " --- |" * len(LOOP_CONFIGS)]
    for loop in LOOPS:
        lines.append(f"| {loop} | " + " | ".join(
            " / ".join(_cell(b, f"(d) {label}, {LOOP_CHUNK}, {loop}") for b in bs) + f"; {r['asm'][label][loop]}"
            for label in LOOP_CONFIGS) + " |")
    lines.append("| all of them, one after another | " + " | ".join(
        " / ".join(_cell(b, f"(d) {label}, {LOOP_CHUNK}") for b in bs) for label in LOOP_CONFIGS) + " |")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="cornell-box")
    ap.add_argument("--bounces", type=int, default=2, help="bounces of the first work unit timed")
    ap.add_argument("--reps", type=int, default=8, help="runs of a variant inside one timed call")
    ap.add_argument("--rounds", type=int, default=15, help="interleaved rounds (medians over them)")
    ap.add_argument("--markdown", type=Path, action="append", default=[],
                    help="write the table into this file's block shading_soa.py (repeatable)")
    args = ap.parse_args()
    load = os.getloadavg()[0]
    r = measure(args.scene, args.bounces, args.reps, args.rounds)
    r["load"] = (load, os.getloadavg()[0])
    print(json.dumps(r, indent=1))
    lines = markdown(r, args.reps, args.rounds)
    print("\n".join(lines))
    markdown_blocks.write_blocks(args.markdown, {"shading_soa.py": "\n".join(lines)}, COMMAND)


if __name__ == "__main__":
    main()
