"""A compiled path-tracer kernel: what it would buy. Our estimator in C, against ours in numba and Mitsuba 3.

Our path tracer reaches about half of Mitsuba 3's paths/s on ``cornell-box`` (BENCHMARKS.md), with its ray
queries at the floor of Embree's own calls from C (``benchmarks/embree_floor.py``): the rest is shading,
sampling and buffers. Whether numba's code generation is to blame, and so whether a compiled kernel would
close the gap, is measured here with a prototype: ``benchmarks/pathtracer_c.c``, our estimator written in C
(the same work unit wavefront, the same 8-wide incoherent packets, robust scene, float64 maths and
counter-based random numbers), built with ``cc`` against the ``libembree4`` embreex bundles.

Before any timing, two checks that it renders what ours renders:

- **Bit for bit**: the scene is exported from the toolkit's own tables
  (:class:`cornell_harness.renderers.core.geometry.SceneGeometry`, the camera basis, the sampler's dimensions),
  and the estimates of a work unit of paths must equal those of our kernel
  (:func:`cornell_harness.renderers.pathtracer.trace_paths`, ``sampler = independent``) exactly
  (:func:`check_estimates`);
- **Against the reference**: its ``--spp`` render must agree with the stored reference
  (``references/cornell-box/reference.exr`` and its variance) region by region, by the harness's own test
  (:func:`cornell_harness.evaluate.reference_agreement.reference_agreement`: z on each region's mean with both
  variances, Šidák-corrected at a family-wise false-alarm rate of 1%), its variance of the mean from the C
  program's per-pixel sums (:class:`cornell_harness.renderers.core.film.Film`).

Then ``--repeats`` rounds, each timing one after another, at 256², ``--spp``, on 1 and 2 threads: the C
prototype; ours (:class:`cornell_harness.renderers.pathtracer.PathTracer`) with ``sampler = independent`` (the
C program's numbers) and with the default; Mitsuba's ``path`` (``llvm_ad_rgb``, independent sampler, its
kernels compiled beforehand: ``benchmarks/pathtracer.py``'s scene, ``benchmarks/embree_floor.py``'s CPU
timing). Then on one thread, to split a path's time into Embree's queries and the rest: the C prototype with
each batch query timed on its thread's CPU clock, once with the toolkit's queries and once with Mitsuba's
(:data:`QUERIES`: what the queries' configuration costs), and ours split by ``benchmarks/pathtracer.py``'s
breakdown (f) (work units of 2^15 paths, on the thread's CPU clock). Every figure is CPU time per path (the
machine is shared: the wall clock adds the waits for a core), the median of the rounds; the ratios to Mitsuba
are medians of each round's ratio. ``--markdown FILE`` writes the block ``pathtracer_c.py``.

Run (about 5 minutes on 2 busy cores):

    .venv/bin/python -m benchmarks.pathtracer_c --repeats 3 --markdown BENCHMARKS.md
"""

from __future__ import annotations

import argparse
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import markdown_blocks
from benchmarks.embree_floor import mitsuba_render_s
from cornell_harness.adapters.api import spp_passes
from cornell_harness.cli.allocator import keep_freed_memory
from cornell_harness.evaluate.reference_agreement import reference_agreement
from cornell_harness.evaluate.regions import region_masks
from cornell_harness.renderers.core import sampler as smp
from cornell_harness.renderers.core.adapter import warmed_geometry
from cornell_harness.renderers.core.bsdf import LAMBERT
from cornell_harness.renderers.core.camera import camera_basis
from cornell_harness.renderers.core.embree import library_path
from cornell_harness.renderers.core.film import Film
from cornell_harness.renderers.core.geometry import SceneGeometry
from cornell_harness.renderers.core.rays import SHADOW_TFAR_REL
from cornell_harness.renderers.core.roulette import Q_MAX, RR_DEPTH
from cornell_harness.renderers.core.schedule import _NO_CAP, MAX_UNIT_PATHS, MIN_UNIT_PATHS
from cornell_harness.renderers.mitsuba3 import Mitsuba3
from cornell_harness.renderers.pathtracer import PathTracer, trace_paths
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.model import Scene, triangle_arrays
from cornell_harness.store.references import load_reference
from cornell_harness.workflows.timing import machine_load

SOURCE = Path(__file__).with_suffix(".c")
BLOCK = "pathtracer_c.py"
THREADS = (1, 2)
#: Ours: the sampler the C program draws like, and the default.
SAMPLERS = ("independent", smp.SAMPLER_SETTING.default)
#: How the C program asks Embree: as the toolkit does (robust scene, default arguments), or as Mitsuba 3 does
#: (no scene flags, high build quality, the coherent flag on camera rays).
QUERIES = ("toolkit", "mitsuba")


def build(directory: Path) -> Path:
    """The C program, compiled into ``directory`` (``cc -O2``, as a wheel's extension would be: no
    ``-march=native``) against embreex's libembree4, found again at run time."""
    cc = shutil.which("cc")
    if cc is None:
        raise RuntimeError("no C compiler (cc) on PATH: scripts/setup.sh --tests installs one")
    lib = Path(library_path())
    program = directory / "pathtracer_c"
    subprocess.run([cc, "-O2", "-Wall", "-Werror", "-o", str(program), str(SOURCE), str(lib), "-lm", "-lpthread",
                    f"-Wl,-rpath,{lib.parent}"], check=True, capture_output=True, text=True, timeout=120)
    return program


def pass_keys(spp: int, seed: int) -> list[tuple[int, np.uint64]]:
    """(samples per pixel, key) of each pass of an ``independent`` render of ours at ``spp``, ``seed``: the passes
    of :func:`cornell_harness.renderers.core.schedule.render_image` and their streams' keys."""
    return [(n, smp.pass_stream("independent", seed, k, 1, 0).key) for k, n in enumerate(spp_passes(spp, _NO_CAP))]


def write_scene(path: Path, scene: Scene, passes: list[tuple[int, np.uint64]]) -> None:
    """The C program's input: the toolkit's tables of ``scene`` (as its kernels read them), the camera, the
    sample dimensions and constants of the estimator, and the passes (see ``load`` in the C program)."""
    g = SceneGeometry(scene).tables()
    if g.sphere_radius.size or np.any(g.material != LAMBERT):
        raise ValueError(f"{scene.name}: the C program renders Lambertian triangles only")
    tri = triangle_arrays(scene)
    cam = scene.camera
    header = [len(tri["vertices"]), len(tri["triangles"]), len(g.emitter_ids), cam.width, cam.height,
              scene.max_depth, RR_DEPTH, len(passes), MIN_UNIT_PATHS, MAX_UNIT_PATHS, smp.CAMERA_U,
              smp.VERTICES.base, smp.VERTICES.stride, smp.EMITTER_PICK, smp.EMITTER_U, smp.BSDF_U, smp.ROULETTE]
    constants = [g.offset, Q_MAX, SHADOW_TFAR_REL, *camera_basis(cam).ravel()]
    arrays = [(header, np.int32), (constants, np.float64), (tri["vertices"], np.float32),
              (tri["triangles"], np.uint32), *((a, np.float64) for a in (g.v0, g.e1, g.e2, g.normal,
                                                                        g.reflectance, g.radiance, g.light_pdf_area)),
              (g.emitter_ids, np.int64), (g.emitter_cdf, np.float64), ([k for _, k in passes], np.uint64),
              ([n * cam.width * cam.height for n, _ in passes], np.int64)]
    with open(path, "wb") as f:
        for a, kind in arrays:
            f.write(np.ascontiguousarray(a, kind).tobytes())


def render_c(program: Path, scene_file: Path, scene: Scene, spp: int, threads: int, clock_queries: bool,
             sums: Path, queries: str = "toolkit") -> dict:
    """One render by the C program, its queries configured as ``queries`` (:data:`QUERIES`): its timings
    (seconds), rays, image and variance of the mean (the film's)."""
    proc = subprocess.run([str(program), str(scene_file), queries, "render", str(threads), str(int(clock_queries)),
                           str(sums)], check=True, capture_output=True, text=True, timeout=600)
    device, line = proc.stdout.splitlines()
    _, paths, rays, wall, cpu, query = line.split()
    cam = scene.camera
    film = Film(cam.width, cam.height)
    film.acc, film.acc2 = np.fromfile(sums).reshape(2, film.pixels, 3)
    return {"device": device, "paths": int(paths), "rays": int(rays), "wall_s": float(wall), "cpu_s": float(cpu),
            "query_cpu_s": float(query), "image": film.image(spp), "variance": film.variance(spp)}


def check_estimates(program: Path, scene_file: Path, scene: Scene, passes, pass_index: int, first: int,
                    stop: int, tmp: Path) -> int:
    """Asserts that the C program's estimates of paths ``first .. stop-1`` of a pass are our kernel's, bit for
    bit, and that it counts the same rays; returns the paths compared."""
    out = tmp / "estimates.bin"
    proc = subprocess.run([str(program), str(scene_file), "toolkit", "paths", str(pass_index), str(first), str(stop),
                           str(out)], check=True, capture_output=True, text=True, timeout=600)
    rays = int(proc.stdout.splitlines()[-1].split()[1])
    cam = scene.camera
    geom, _ = warmed_geometry(scene, lambda g: None)
    ours = trace_paths(geom, scene, first, stop, cam.width * cam.height, smp.independent(passes[pass_index][1]))
    c = np.fromfile(out).reshape(-1, 3)
    differ = int(np.sum(np.any(c != ours, axis=1)))
    assert differ == 0, f"{differ} of {stop - first} paths' estimates differ from our kernel's"
    assert rays == geom.rays, f"the C program traced {rays} rays, ours {geom.rays}"
    return stop - first


def against_reference(scene: Scene, render: dict):
    """The harness's region test of a render of the C program (:func:`render_c`) against the stored reference."""
    ref = load_reference(scene)
    return reference_agreement(ref.image, ref.variance, render["image"], render["variance"], region_masks(scene))


def _pathtracer_benchmark():
    """``benchmarks/pathtracer.py``, a script that imports its neighbour ``markdown_blocks`` by bare name."""
    sys.path.insert(0, str(Path(__file__).parent))
    import pathtracer as bench

    return bench


def ours_ns(scene: Scene, spp: int, threads: int, sampler: str, seed: int) -> tuple[float, np.ndarray]:
    """Our path tracer's CPU ns per path at ``spp`` on ``threads`` threads, and its image."""
    r = PathTracer(threads=threads).render(scene, spp, seed, settings={"sampler": sampler})
    return r.cpu_time_s / (scene.camera.width * scene.camera.height * spp) * 1e9, r.image


def one_round(ctx: dict, k: int) -> dict:
    """Every measurement once, CPU ns per path: {(who, threads): ns}, who "c" (the C program, the toolkit's
    queries), our samplers, "mitsuba"; on one thread, the C program with its queries clocked, {("c clocked",
    queries): (whole, queries)} for each of :data:`QUERIES`; ours split by ``benchmarks/pathtracer.py`` (f),
    {(sampler, "split"): its dict}."""
    scene, spp, paths = ctx["scene"], ctx["spp"], ctx["paths"]
    out = {}
    for t in THREADS:
        r = render_c(ctx["program"], ctx["scene_file"], scene, spp, t, False, ctx["sums"])
        out["c", t] = r["cpu_s"] / paths * 1e9
        for sampler in SAMPLERS:
            out[sampler, t], image = ours_ns(scene, spp, t, sampler, ctx["seed"])
            if sampler == "independent":  # same seed, same estimates: the images differ by the sums' order only
                ctx["image_difference"] = max(ctx["image_difference"], float(np.abs(image - r["image"]).max()))
        out["mitsuba", t] = mitsuba_render_s(ctx["mitsuba"], spp, t, k)[1] / paths * 1e9
    for queries in QUERIES:
        r = render_c(ctx["program"], ctx["scene_file"], scene, spp, 1, True, ctx["sums"], queries)
        out["c clocked", queries] = (r["cpu_s"] / paths * 1e9, r["query_cpu_s"] / paths * 1e9)
        ctx["rays_per_path", queries] = r["rays"] / paths
    for sampler in SAMPLERS:
        out[sampler, "split"] = ctx["bench"].time_per_path(scene, sampler, ctx["units"], time.thread_time)
    return out


def _readable(values: dict) -> str:
    """A round's figures, rounded, for the log."""
    def num(v):
        return {k: round(x) for k, x in v.items()} if isinstance(v, dict) else tuple(map(round, v)) \
            if isinstance(v, tuple) else round(v)
    return ", ".join(f"{'/'.join(map(str, key))} {num(v)}" for key, v in values.items())


def median(rounds: list[dict], key, part: int | None = None) -> float:
    return statistics.median(r[key] if part is None else r[key][part] for r in rounds)


def ratio(rounds: list[dict], key, threads: int) -> float:
    """The median over rounds of each round's ns per path of ``key`` over Mitsuba's."""
    return statistics.median(r[key] / r["mitsuba", threads] for r in rounds)


def markdown(rounds: list[dict], ctx: dict) -> list[str]:
    cam, agreement, other = ctx["scene"].camera, ctx["agreement", "toolkit"], ctx["agreement", "mitsuba"]
    names = {"c": "C prototype (`benchmarks/pathtracer_c.c`, `cc -O2`)",
             "independent": "ours, `sampler = independent` (the C program's numbers)",
             SAMPLERS[1]: f"ours, `sampler = {SAMPLERS[1]}` (the default)",
             "mitsuba": f"Mitsuba 3 `{ctx['variant']}` `path`"}
    lines = [f"`{ctx['scene'].name}` {cam.width}×{cam.height}, {ctx['spp']} spp, median of {len(rounds)} rounds "
             f"(each measures everything once, one after another); ns per path: CPU time ÷ paths. Load "
             f"{ctx['loads'][0]:.1f} → {ctx['loads'][1]:.1f} runnable threads on {ctx['cpus']} cores. C program: "
             f"`{ctx['device']}`. Checked first: its estimates of {ctx['paths_checked']} paths are our kernel's bit "
             f"for bit, with the same rays ({ctx['rays_per_path', 'toolkit']:.2f} a path); its image and ours at the "
             f"same seed differ by at most {ctx['image_difference']:.1g}; against the stored reference, "
             f"{agreement.tests} region-channel tests, largest |z| {agreement.max_abs_z:.2f}, χ² {agreement.chi2:.1f} "
             f"on {agreement.dof} (passed at a family-wise 1%); with Mitsuba's queries (hits may differ at grazing "
             f"edges), largest |z| {other.max_abs_z:.2f}, χ² {other.chi2:.1f}, "
             f"{'passed' if other.passed else 'failed'}.", "",
             "| CPU ns per path (÷ Mitsuba's) | 1 thread | 2 threads | paths/s on 2 cores (2 threads) |",
             "| --- | --- | --- | --- |"]
    for who, name in names.items():
        cells = [f"{median(rounds, (who, t)):.0f} (**{ratio(rounds, (who, t), t):.2f}×**)" for t in THREADS]
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {2e9 / median(rounds, (who, 2)) / 1e6:.2f} M |")
    lines += ["", "| one thread, ns per path | whole path | Embree's queries | the rest (shading, sampling, buffers) |",
              "| --- | --- | --- | --- |"]
    for queries in QUERIES:
        whole, query = (median(rounds, ("c clocked", queries), part) for part in (0, 1))
        label = {"toolkit": "the toolkit's queries (robust scene)",
                 "mitsuba": "Mitsuba's queries (fast scene, coherent camera rays)"}[queries]
        lines.append(f"| C prototype, {label}: the whole render, CPU | {whole:.0f} | {query:.0f} | "
                     f"{whole - query:.0f} |")
    for sampler in SAMPLERS:
        split = [statistics.median(r[sampler, "split"][key] for r in rounds) for key in ("whole", "embree", "rest")]
        lines.append(f"| ours, `{sampler}`: the bounce loop of a work unit (`benchmarks/pathtracer.py` (f)), CPU | "
                     + " | ".join(f"{v:.0f}" for v in split) + " |")
    lines.append(f"| Mitsuba 3 `path`, CPU | {median(rounds, ('mitsuba', 1)):.0f} | | |")
    return lines


def main() -> None:
    import os

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=3, help="rounds (medians over them)")
    ap.add_argument("--units", type=int, default=8, help="work units of 2^15 paths of ours' split, per round")
    ap.add_argument("--markdown", type=Path, action="append", default=[], help="write the block pathtracer_c.py")
    a = ap.parse_args()
    keep_freed_memory()  # as every cbox command runs: ours measured as users run it
    scene, seed = resolve_scene("cornell-box"), 0
    cam = scene.camera
    with tempfile.TemporaryDirectory(prefix="cbox-pathtracer-c-") as name:
        tmp = Path(name)
        passes = pass_keys(a.spp, seed)
        ctx = {"scene": scene, "spp": a.spp, "seed": seed, "units": a.units, "cpus": os.cpu_count(),
               "paths": cam.width * cam.height * a.spp, "program": build(tmp), "scene_file": tmp / "scene.bin",
               "sums": tmp / "sums.bin", "bench": _pathtracer_benchmark(), "image_difference": 0.0}
        write_scene(ctx["scene_file"], scene, passes)
        middle = passes[-1][0] * cam.width * cam.height // 2  # the last pass's, past path 2^24 at 64 spp
        ctx["paths_checked"] = sum(check_estimates(ctx["program"], ctx["scene_file"], scene, passes, k, first, stop, tmp)
                                   for k, first, stop in ((0, 0, MAX_UNIT_PATHS), (len(passes) - 1, middle,
                                                                                     middle + MIN_UNIT_PATHS)))
        for queries in QUERIES:  # the hits of Mitsuba's configuration may differ at grazing edges: reported
            r = render_c(ctx["program"], ctx["scene_file"], scene, a.spp, 2, False, ctx["sums"], queries)
            ctx["device"], ctx["agreement", queries] = r["device"], against_reference(scene, r)
        assert ctx["agreement", "toolkit"].passed, f"the C program's image is not the reference's: " \
                                                   f"{ctx['agreement', 'toolkit'].failures}"
        ctx["mitsuba"] = ctx["bench"]._mitsuba_scene(scene, a.spp, "independent")
        ctx["variant"] = Mitsuba3().variant()[0]
        ours_ns(scene.with_resolution(8, 8), 1, 1, SAMPLERS[1], 0)  # numba's caches loaded before the clock
        ctx["loads"] = [machine_load()]
        rounds = []
        for k in range(a.repeats):
            rounds.append(one_round(ctx, k))
            print(f"round {k}: {_readable(rounds[-1])}", flush=True)
        ctx["loads"].append(machine_load())
    lines = markdown(rounds, ctx)
    print("\n".join(lines))
    command = " ".join([".venv/bin/python -m benchmarks.pathtracer_c", *map(shlex.quote, sys.argv[1:])])
    markdown_blocks.write_blocks(a.markdown, {BLOCK: "\n".join(lines)}, command)


if __name__ == "__main__":
    main()
