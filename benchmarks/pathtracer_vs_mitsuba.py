"""Our path tracer against Mitsuba 3, from one run: paths/s, ns per ray against the Embree floor, efficiency.

On ``cornell-box`` at 256×256 and 256 spp, 2 threads, every figure of one comparison is taken in the same
run, in rounds: each round measures everything once, one after another, so that a ratio pairs timings taken
seconds apart on this shared machine, and round k renders seed k. In a round:

- the Embree floor (``benchmarks/embree_floor.py``'s C program: Embree's own calls from C) on the camera and
  first-bounce rays of our path tracer, and ours and Mitsuba's closest-hit queries on the same rays, ours as
  the path tracer asks them (camera rays coherent), Mitsuba's with its camera's coherent flag;
- whole renders at 256 spp: ours with the default sampler and with ``pmj02table`` (each with its default
  variance), Mitsuba 3's ``path`` with ``multijitter`` and ``independent``, alternated, then ours again with
  ``variance = none`` (one randomisation a pixel and no variance reported, as Mitsuba's samplers: the
  like-for-like efficiency; the default's 8 randomisations are the price of the gate's z-test); each renderer was
  warmed first (numba's kernels loaded, Mitsuba's compiled). Each gives paths/s, ns per ray traced (ours:
  the closest-hit and shadow rays it counts; Mitsuba counts none, so its paths times our rays per path)
  and its squared error against the stored reference;
- where one thread's time per path goes in our bounce loop (``benchmarks/pathtracer.py``'s replay: the
  loop per work unit, and Embree's queries in it), on the thread's CPU clock.

Figures are medians over the rounds (MSE: the mean over the seeds; efficiency 1/(MSE·t) with the median
time), on two clocks: CPU time (the process's; on a shared machine the cost of the work) and wall time
(which adds the waits for a core). The machine's load is read before and after. ``--markdown FILE`` writes
the block ``pathtracer_vs_mitsuba.py``.

Run (about 5 minutes of CPU time; 9 minutes on 2 cores shared with other jobs):

    .venv/bin/python -m benchmarks.pathtracer_vs_mitsuba --markdown BENCHMARKS.md
"""

from __future__ import annotations

import argparse
import os
import shlex
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import embree_floor as floor
from benchmarks import markdown_blocks
from benchmarks import pathtracer as pt_bench
from cornell_harness.cli.allocator import keep_freed_memory
from cornell_harness.renderers.core.embree import EmbreeScene
from cornell_harness.renderers.core.sampler import SAMPLER_SETTING
from cornell_harness.renderers.pathtracer import PathTracer
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.model import Scene
from cornell_harness.store.references import load_reference
from cornell_harness.workflows.timing import machine_load

BLOCK = "pathtracer_vs_mitsuba.py"
THREADS = 2
#: Our samplers (each with its default variance), the default first; Mitsuba's, its best first.
OURS = (SAMPLER_SETTING.default, "pmj02table")
MITSUBA = ("multijitter", "independent")
#: The label of our renders with ``variance = none`` (after the sampler's name).
NO_VARIANCE = "variance=none"
#: Work units of 2^15 paths per round in the breakdown of our bounce loop.
UNITS = 6


def setup(scene: Scene, spp: int, rays: int, tmp: Path) -> dict:
    """Everything a round uses, built and warmed: the C program and its batches (checked to answer what ours
    answers), Embree's scene, Mitsuba's queries and its scenes per sampler, our renderer."""
    ctx = {"scene": scene, "spp": spp, "program": floor.build(tmp), "rays": floor.ray_batches(scene, rays),
           "reference": np.asarray(load_reference(scene).image, dtype=np.float64)}
    ctx["files"] = {b: tmp / f"{b}.bin" for b in floor.BATCHES}
    for b in floor.BATCHES:
        floor.write_batch(ctx["files"][b], scene, *ctx["rays"][b])
    ctx["embree"] = EmbreeScene(*floor.scene_arrays(scene))
    ctx["handle"] = ctx["embree"].handle
    ctx["mitsuba"] = {b: floor.MitsubaQuery(scene, *ctx["rays"][b], coherent=b == "camera") for b in floor.BATCHES}
    ctx["variant"] = ctx["mitsuba"]["camera"].variant
    floor.check_before_timing(ctx, tmp)
    ctx["ours"] = PathTracer(threads=THREADS)
    for sampler in OURS:
        for variance in ("batches", "none"):  # numba's kernels
            ctx["ours"].render(scene.with_resolution(8, 8), 1, 0, settings={"sampler": sampler, "variance": variance})
    ctx["mitsuba_scenes"] = {s: pt_bench.mitsuba_scene(scene, spp, s) for s in MITSUBA}  # Mitsuba's kernels
    return ctx


def _set_mitsuba_threads(n: int) -> None:
    import drjit as dr

    dr.set_thread_count(n)


def one_round(ctx: dict, seed: int) -> dict:
    """Every measurement once. Keys: ("floor", batch, scene, width, coherent), ("ours"|"mitsuba", batch): CPU
    ns per ray; ("render", who, sampler): (wall s, CPU s, MSE, rays or None); ("loop", sampler): one thread's
    ns per path in our bounce loop (whole, embree, rest)."""
    out = {}
    for batch in floor.BATCHES:
        c = floor.run_floor(ctx["program"], ctx["files"][batch], THREADS)
        ctx["device"] = c.pop("device")
        out |= {("floor", batch, *config): ns[1] for (*config, t), ns in c.items() if t == THREADS}
        o, d = ctx["rays"][batch]
        out["ours", batch] = floor.ours_query_ns(ctx["handle"], o, d, THREADS, coherent=batch == "camera")[1]
        out["mitsuba", batch] = ctx["mitsuba"][batch].ns(THREADS)[1]
    scene, spp, ref = ctx["scene"], ctx["spp"], ctx["reference"]
    _set_mitsuba_threads(THREADS)
    for ours, theirs in zip(OURS, MITSUBA):  # alternated: ours, Mitsuba, ours, Mitsuba
        r = ctx["ours"].render(scene, spp, seed, settings={"sampler": ours})
        out["render", "ours", ours] = (r.time_s, r.cpu_time_s, float(np.mean((r.image - ref) ** 2)), r.info["rays"])
        img, wall, cpu = pt_bench.mitsuba_render(ctx["mitsuba_scenes"][theirs], spp, seed)
        out["render", "mitsuba", theirs] = (wall, cpu, float(np.mean((img - ref) ** 2)), None)
    for ours in OURS:
        r = ctx["ours"].render(scene, spp, seed, settings={"sampler": ours, "variance": "none"})
        out["render", "ours", f"{ours} {NO_VARIANCE}"] = (r.time_s, r.cpu_time_s, float(np.mean((r.image - ref) ** 2)),
                                                         r.info["rays"])
    for sampler in OURS:
        out["loop", sampler] = pt_bench.time_per_path(scene, sampler, UNITS, clock=time.thread_time)
    return out


def summarise(rounds: list[dict], paths: int) -> dict:
    """Medians over the rounds (MSE: the mean), and the derived figures every table reads."""
    med = {k: statistics.median(r[k] for r in rounds) for k in rounds[0] if k[0] in ("floor", "ours", "mitsuba")}
    renders = {}
    for key in (k for k in rounds[0] if k[0] == "render"):
        wall, cpu = (statistics.median(r[key][i] for r in rounds) for i in (0, 1))
        mse = statistics.fmean(r[key][2] for r in rounds)
        rays = statistics.median(r[key][3] for r in rounds) if key[1] == "ours" else None
        renders[key[1:]] = {"wall": wall, "cpu": cpu, "mse": mse, "rays": rays, "paths_cpu": paths / cpu,
                            "paths_wall": paths / wall, "ns_path": cpu / paths * 1e9,
                            "eff_cpu": 1 / (mse * cpu), "eff_wall": 1 / (mse * wall)}
    loops = {k[1]: {part: statistics.median(r[k][part] for r in rounds) for part in ("whole", "embree", "rest")}
             for k in rounds[0] if k[0] == "loop"}
    rays_per_path = renders["ours", OURS[0]]["rays"] / paths
    floors = {(b, s): min(v for k, v in med.items() if k[:3] == ("floor", b, s))
              for b in floor.BATCHES for s in ("robust", "fast")}
    return {"query": med, "renders": renders, "loops": loops, "rays_per_path": rays_per_path, "floors": floors}


def queries_per_path(s: dict, who: str) -> float:
    """Ray queries' CPU ns per path at the measured query costs: one camera ray, and the path's other rays
    (closest-hit and shadow) at the cost of a first-bounce closest hit."""
    return s["query"][who, "camera"] + s["query"][who, "bounce"] * (s["rays_per_path"] - 1)


def _fastest_call(s: dict, batch: str, scene: str) -> str:
    value = s["floors"][batch, scene]
    _, _, _, w, c = next(k for k, v in s["query"].items() if k[:3] == ("floor", batch, scene) and v == value)
    return f"`rtcIntersect{w}`{', coherent' * c}"


def markdown(s: dict, ctx: dict, rounds: int, loads: tuple[float, float]) -> list[str]:
    scene, spp = ctx["scene"], ctx["spp"]
    renders, base = s["renders"], s["renders"]["mitsuba", MITSUBA[0]]

    def name(who, sampler):
        default = " (default)" if who == "ours" and sampler == SAMPLER_SETTING.default else ""
        return f"{'ours' if who == 'ours' else 'Mitsuba'} `{sampler}`{default}"

    lines = [f"`{scene.name}` {scene.camera.width}×{scene.camera.height}, {spp} spp, {THREADS} threads; {rounds} rounds, round k "
             f"renders seed k, every figure measured once a round, interleaved; medians of the rounds (MSE: the "
             f"mean over the seeds). Mitsuba `{ctx['variant']}`. CPU time is the process's (the cost of the work "
             f"on this shared machine), wall time adds the waits for a core. Load {loads[0]:.1f} → {loads[1]:.1f} "
             f"runnable threads on {os.cpu_count()} cores. C program: `{ctx['device']}`.", "",
             f"| {spp} spp, {THREADS} threads | paths per CPU s | paths/s (wall) | CPU ns per path | RMSE | "
             "1/(MSE·CPU s) | 1/(MSE·wall s) | / Mitsuba `multijitter`: paths per CPU s, 1/(MSE·CPU s) |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for (who, sampler), r in renders.items():
        lines.append(f"| {name(who, sampler)} | {r['paths_cpu'] / 1e6:.3f} M | {r['paths_wall'] / 1e6:.3f} M | "
                     f"{r['ns_path']:.0f} | {r['mse'] ** 0.5:.5f} | {r['eff_cpu']:.0f} | {r['eff_wall']:.0f} | "
                     f"**{r['paths_cpu'] / base['paths_cpu']:.2f}×**, **{r['eff_cpu'] / base['eff_cpu']:.2f}×** |")

    ours, theirs = renders["ours", OURS[0]], renders["mitsuba", MITSUBA[0]]
    rpp = s["rays_per_path"]
    whole = {"ours": ours["ns_path"] / rpp, "mitsuba": theirs["ns_path"] / rpp}

    def cell(value, ref):
        return f"{value:.1f} (**{value / ref:.2f}×**)"

    lines += ["", f"| CPU ns per ray, {THREADS} threads (in brackets: ÷ the floor of the scene it builds) | camera "
              f"rays | first-bounce rays | whole render (÷ {rpp:.2f} rays a path: closest hit and shadow) |",
              "| --- | --- | --- | --- |"]
    for sc, who in (("robust", "ours"), ("fast", "Mitsuba's")):
        lines.append(f"| floor, {sc} scene ({who}): the fastest C call | "
                     + " | ".join(f"{s['floors'][b, sc]:.1f} ({_fastest_call(s, b, sc)})" for b in floor.BATCHES)
                     + f" | {s['floors']['bounce', sc]:.1f} (the first-bounce floor) |")
    for who, label, sc in (("ours", f"ours (`closest_triangles`; {floor.OURS_CALLS}); `{OURS[0]}` render",
                            "robust"),
                           ("mitsuba", f"Mitsuba (`ray_intersect_preliminary`); `{MITSUBA[0]}` render", "fast")):
        lines.append(f"| {label} | " + " | ".join(cell(s["query"][who, b], s["floors"][b, sc]) for b in floor.BATCHES)
                     + f" | {cell(whole[who], s['floors']['bounce', sc])} |")
    lines.append("| ours / Mitsuba | " + " | ".join(f"**{s['query']['ours', b] / s['query']['mitsuba', b]:.2f}×**"
                                                    for b in floor.BATCHES)
                 + f" | **{whole['ours'] / whole['mitsuba']:.2f}×** |")

    cam = {who: s["query"][who, "camera"] for who in ("ours", "mitsuba")}
    other = {who: queries_per_path(s, who) - cam[who] for who in ("ours", "mitsuba")}
    rest = {"ours": ours["ns_path"] - cam["ours"] - other["ours"],
            "mitsuba": theirs["ns_path"] - cam["mitsuba"] - other["mitsuba"]}
    per_path = (("whole path (render CPU ÷ paths)", {"ours": ours["ns_path"], "mitsuba": theirs["ns_path"]}),
                ("camera ray (its query)", cam),
                (f"the other {rpp - 1:.2f} rays of a path (closest hit and shadow), at the first-bounce query's cost",
                 other),
                ("the rest: shading, sampling, film, scheduling (the whole less the two rows above)", rest))
    lines += ["", f"| CPU ns per path | {name('ours', OURS[0])} | {name('mitsuba', MITSUBA[0])} | ours − Mitsuba |",
              "| --- | --- | --- | --- |"]
    lines += [f"| {label} | {v['ours']:.0f} | {v['mitsuba']:.0f} | **{v['ours'] - v['mitsuba']:.0f}** |"
              for label, v in per_path]

    lines += ["", "| ours, CPU ns per path | " + " | ".join(f"`{x}`" for x in OURS) + " |", "| --- |" + " --- |" * len(OURS)]
    rows = [("bounce loop, one thread (the kernel per work unit of 2^15 paths)", lambda x: s["loops"][x]["whole"]),
            ("… Embree's queries in it (closest hit and shadow, timed in a replay)", lambda x: s["loops"][x]["embree"]),
            ("… shading, sampling, buffers (the loop less its queries)", lambda x: s["loops"][x]["rest"]),
            (f"outside the loop: film, passes, threads ({THREADS}-thread render less the loop)",
             lambda x: renders["ours", x]["ns_path"] - s["loops"][x]["whole"])]
    lines += [f"| {label} | " + " | ".join(f"{f(x):.0f}" for x in OURS) + " |" for label, f in rows]
    return lines


def _short(value):
    """A round's figure, printed: numbers to 4 significant digits."""
    if isinstance(value, dict):
        return {k: _short(v) for k, v in value.items()}
    if isinstance(value, tuple):
        return tuple(_short(v) for v in value)
    return value if value is None else float(f"{value:.4g}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--spp", type=int, default=256, help="spp of every render")
    ap.add_argument("--rounds", type=int, default=5, help="rounds (medians over them); round k renders seed k")
    ap.add_argument("--rays", type=int, default=1 << 20, help="camera rays (paths) of the query batches")
    ap.add_argument("--markdown", type=Path, action="append", default=[], help=f"write the block {BLOCK}")
    a = ap.parse_args()
    keep_freed_memory()  # as every cbox command runs (cornell_harness.cli.allocator): ours measured as users run it
    scene = resolve_scene("cornell-box")
    paths = scene.camera.width * scene.camera.height * a.spp
    with tempfile.TemporaryDirectory() as tmp:
        ctx = setup(scene, a.spp, a.rays, Path(tmp))
        load0, rounds = machine_load(), []
        for k in range(a.rounds):
            rounds.append(one_round(ctx, k))
            print(f"round {k}: " + ", ".join(f"{'/'.join(map(str, key))} {_short(v)}" for key, v in rounds[-1].items()
                                             if key[0] != "floor"), flush=True)
        load1 = machine_load()
    lines = markdown(summarise(rounds, paths), ctx, len(rounds), (load0, load1))
    print("\n".join(lines))
    command = " ".join([".venv/bin/python -m benchmarks.pathtracer_vs_mitsuba", *map(shlex.quote, sys.argv[1:])])
    markdown_blocks.write_blocks(a.markdown, {BLOCK: "\n".join(lines)}, command)


if __name__ == "__main__":
    main()
