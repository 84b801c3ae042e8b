"""The floor of a closest-hit ray query on this machine, and ours and Mitsuba's per ray against it.

A ray query can cost no less than Embree's own call from C on the same rays and scene: that is the floor
for any renderer here. ``benchmarks/embree_floor.c`` (built here with ``cc -O2`` against the ``libembree4``
that embreex bundles) traces a batch with ``rtcIntersect1``, ``rtcIntersect8`` and ``rtcIntersect16`` (the
packets without and with Embree's coherent-rays flag), in the scene as the toolkit builds it (robust) and
as Mitsuba 3 builds its own (fast), on 1 and 2 threads, and prints ns per ray (:data:`CONFIGS`). The
batches are rays our path tracer traces, on the stored ``cornell-box``'s triangles: ``--rays`` camera rays
(neighbouring pixels one after another, so packets are coherent) and the first-bounce rays the path
tracer's shading kernel writes from their hits (cosine-sampled directions, incoherent), with the default
sampler, seed 0. Before any timing, :func:`check_agreement` checks that the C program hits what ours hits.

In the same run, on the same batches and thread counts:

- ours: the toolkit's query (:func:`cornell_harness.renderers.core.embree.closest_triangles`, numba), as
  the path tracer asks it (camera rays: ``rtcIntersect16`` with the coherent flag; bounce rays:
  ``rtcIntersect8``), each thread a contiguous half of the batch;
- Mitsuba: ``Scene.ray_intersect_preliminary`` (its query alone, no surface interaction) on the same rays
  moved into its unit frame (:func:`cornell_harness.scenes.transforms.unit_frame`), Dr.Jit's pool set to
  the thread count, the coherent flag on camera rays as Mitsuba's camera passes it;
- whole renders: our path tracer's time over the rays it counts (closest-hit and shadow rays) at
  ``--spp``, and Mitsuba's ``path`` render's time over its paths times *our* rays per path (Mitsuba
  counts no rays; both trace one closest-hit and one shadow ray per bounce), each against the floor of
  the first-bounce batch.

Every figure is taken on two clocks: the wall clock (2 threads halve it at best), and CPU time (the
process's, or for our query its threads' own), which on this shared machine is the cost of the work while
the wall clock adds the waits for a core. Each figure is the median of ``--repeats`` rounds, and each ratio
the median of its rounds' ratios: a round runs every measurement once, one after another, so a ratio pairs
two timings taken seconds apart. The machine's load (runnable threads,
:func:`cornell_harness.workflows.timing.machine_load`) is read before and after. ``--markdown FILE`` writes
the block ``embree_floor.py``.

Run (about 4 minutes on 2 busy cores):

    .venv/bin/python -m benchmarks.embree_floor --repeats 5 --markdown BENCHMARKS.md
"""

from __future__ import annotations

import argparse
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from benchmarks import markdown_blocks
from cornell_harness.adapters.api import process_cpu_s
from cornell_harness.renderers import pathtracer
from cornell_harness.renderers.core.adapter import warmed_geometry
from cornell_harness.renderers.core.camera import camera_basis, camera_rays
from cornell_harness.renderers.core.embree import EmbreeScene, closest_triangles, library_path, ray_record
from cornell_harness.renderers.core.geometry import Hits
from cornell_harness.renderers.core.rays import wavefront
from cornell_harness.renderers.core.roulette import RR_DEPTH
from cornell_harness.renderers.core.sampler import SAMPLER_SETTING, independent, pass_stream
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.model import Scene, triangle_arrays
from cornell_harness.scenes.transforms import unit_frame
from cornell_harness.workflows.timing import machine_load

SOURCE = Path(__file__).with_suffix(".c")
BLOCK = "embree_floor.py"
#: The C program's configurations, in the order it runs them: (scene, packet width, coherent flag); "robust" is
#: the toolkit's scene (the floor of our work), "fast" Mitsuba 3's (no scene flags, high build quality).
CONFIGS = tuple((scene, w, c) for scene in ("robust", "fast") for w, c in ((1, 0), (8, 0), (8, 1), (16, 0), (16, 1)))
THREADS = (1, 2)
BATCHES = ("camera", "bounce")
#: The calls our query makes, as the path tracer asks it: camera rays coherent, bounce rays not.
OURS_CALLS = "camera rays `rtcIntersect16`, coherent; bounce rays `rtcIntersect8`"
#: tfar of a ray that hits nothing, in the C program's answers (the toolkit's closest-hit tfar).
NO_HIT_TFAR = np.float32(1e37)


def build(directory: Path) -> Path:
    """The C program, compiled into ``directory`` against embreex's libembree4 (found again at run time)."""
    cc = shutil.which("cc")
    if cc is None:
        raise RuntimeError("no C compiler (cc) on PATH: scripts/setup.sh --tests installs one")
    lib = Path(library_path())
    program = directory / "embree_floor"
    subprocess.run([cc, "-O2", "-Wall", "-Werror", "-o", str(program), str(SOURCE), str(lib), "-lpthread",
                    f"-Wl,-rpath,{lib.parent}"], check=True, capture_output=True, text=True, timeout=120)
    return program


def scene_arrays(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """The scene's triangles as Embree takes them (float32 vertices, uint32 indices), as the toolkit builds them."""
    tri = triangle_arrays(scene)
    return tri["vertices"].astype(np.float32), tri["triangles"].astype(np.uint32)


def write_batch(path: Path, scene: Scene, o: np.ndarray, d: np.ndarray) -> None:
    """The C program's input: the scene's triangles and the rays (float32 origins and directions)."""
    vertices, triangles = scene_arrays(scene)
    with open(path, "wb") as f:
        f.write(np.array([len(vertices), len(triangles), len(o)], np.int32).tobytes())
        for a, kind in ((vertices, np.float32), (triangles, np.uint32), (o, np.float32), (d, np.float32)):
            f.write(np.ascontiguousarray(a, kind).tobytes())


def run_floor(program: Path, batch: Path, threads: int = max(THREADS), hits: Path | None = None) -> dict:
    """The C program's ns per ray, {(scene, width, coherent, threads): (wall ns, CPU ns)} (see :data:`CONFIGS`),
    and its first line under ``"device"``."""
    proc = subprocess.run([str(program), str(batch), str(threads), *([str(hits)] if hits else [])],
                          check=True, capture_output=True, text=True, timeout=600)
    first, *rows = proc.stdout.splitlines()
    out: dict = {"device": first}
    for row in rows:
        scene, width, coherent, n_threads, wall, cpu = row.split()
        out[scene, int(width), int(coherent), int(n_threads)] = (float(wall), float(cpu))
    return out


def read_hits(path: Path, n: int) -> dict[tuple, tuple[np.ndarray, np.ndarray]]:
    """The C program's answers per configuration of :data:`CONFIGS`: (tfar float32, primitive id int32, -1 for
    a miss)."""
    raw = np.fromfile(path, np.uint8)
    assert raw.size == len(CONFIGS) * 8 * n, f"{path}: {raw.size} bytes, expected {len(CONFIGS) * 8 * n}"
    parts = raw.reshape(len(CONFIGS), 2, 4 * n)
    return {c: (parts[k, 0].view(np.float32), parts[k, 1].view(np.int32)) for k, c in enumerate(CONFIGS)}


def ray_batches(scene: Scene, n: int, sampler: str = SAMPLER_SETTING.default) -> dict[str, tuple]:
    """Rays our path tracer traces: the camera rays of paths 0 .. n-1 of its first pass (seed 0), and the
    first-bounce rays its shading kernel writes from their hits; float32 (origins, directions) each."""
    cam = scene.camera
    pixels = cam.width * cam.height
    geom, _ = warmed_geometry(scene, lambda g: pathtracer.trace_paths(g, scene, 0, 1, 1, independent(0)))
    assert not geom.has_spheres, "the C program builds triangles only"
    geo, stream = geom.tables(), pass_stream(sampler, 0, 0, pixels, 0)
    wf = wavefront(n, False)
    paths = pathtracer.Paths(np.zeros((n, 3)), np.zeros((0, 6)), np.ones(0, np.bool_))
    camera_rays(camera_basis(cam), cam.width, cam.height, 0, pixels, stream, wf.cur)
    closest_triangles(geo.embree, wf.cur.o32, wf.cur.d32, wf.prim, wf.record, True)  # as the path tracer's camera
    _, m = pathtracer._shade(Hits(wf.prim, wf.t_sphere), wf.cur, stream, 0, 1, True, 1 >= RR_DEPTH, geo, paths,
                             pathtracer.Bounce(wf.shadow, wf.nxt))
    return {"camera": (wf.cur.o32.copy(), wf.cur.d32.copy()), "bounce": (wf.nxt.o32[:m].copy(), wf.nxt.d32[:m].copy())}


def on_threads(n: int, threads: int, work) -> tuple[float, float]:
    """(wall, CPU) seconds of ``work(first, last)`` over 0 .. n-1 split into ``threads`` contiguous shares, one
    thread each; the CPU time is the workers' own (:func:`time.thread_time`), summed."""
    cuts = [n * k // threads for k in range(threads + 1)]
    cpu = [0.0] * threads

    def timed(k):
        c0 = time.thread_time()
        work(cuts[k], cuts[k + 1])
        cpu[k] = time.thread_time() - c0

    workers = [threading.Thread(target=timed, args=(k,)) for k in range(threads)]
    t0 = time.perf_counter()
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    return time.perf_counter() - t0, sum(cpu)


def ours_query_ns(handle: int, o: np.ndarray, d: np.ndarray, threads: int,
                  coherent: bool = False) -> tuple[float, float]:
    """(wall, CPU) ns per ray of the toolkit's closest-hit query on ``threads`` threads (a packet record each);
    ``coherent`` as the path tracer asks for its camera rays."""
    prim = np.empty(len(o), np.int32)
    wall, cpu = on_threads(len(o), threads, lambda a, b: closest_triangles(handle, o[a:b], d[a:b], prim[a:b],
                                                                           ray_record(), coherent))
    return wall / len(o) * 1e9, cpu / len(o) * 1e9


class MitsubaQuery:
    """Mitsuba's closest-hit query (``ray_intersect_preliminary``) on one batch, in its unit frame."""

    def __init__(self, scene: Scene, o: np.ndarray, d: np.ndarray, coherent: bool):
        import drjit as dr
        import mitsuba as mi

        from cornell_harness.renderers.mitsuba3 import Mitsuba3, scene_dict

        self.variant = Mitsuba3().variant()[0]
        self.mi_scene = mi.load_dict(scene_dict(scene, 1))
        centre, self.scale = unit_frame(scene)
        p = ((o.astype(np.float64) - centre) * self.scale).astype(np.float32)
        self.ray = mi.Ray3f(mi.Point3f(*(mi.Float(p[:, k]) for k in range(3))),
                            mi.Vector3f(*(mi.Float(np.ascontiguousarray(d[:, k])) for k in range(3))))
        dr.eval(self.ray)
        self.n, self.coherent = len(o), coherent
        self.t()  # traces and compiles the kernel

    def _query(self):
        import drjit as dr

        pi = self.mi_scene.ray_intersect_preliminary(self.ray, coherent=self.coherent)
        dr.eval(pi.t)
        dr.sync_thread()  # the kernel has run
        return pi

    def t(self) -> np.ndarray:
        """Hit distances in the scene's units (inf for a miss)."""
        return np.asarray(self._query().t, np.float64) / self.scale

    def ns(self, threads: int) -> tuple[float, float]:
        """(wall, CPU) ns per ray on ``threads`` of Dr.Jit's threads (the CPU time: the whole process's)."""
        import drjit as dr

        dr.set_thread_count(threads)
        t0, c0 = time.perf_counter(), process_cpu_s()
        self._query()
        return (time.perf_counter() - t0) / self.n * 1e9, (process_cpu_s() - c0) / self.n * 1e9


def pathtracer_ns(scene: Scene, spp: int, threads: int, seed: int) -> tuple[tuple[float, float], float]:
    """Our path tracer at ``spp`` on ``threads`` threads: ((wall, CPU) ns per ray it traced, rays per path)."""
    r = pathtracer.PathTracer(threads=threads).render(scene, spp, seed)
    rays, paths = r.info["rays"], scene.camera.width * scene.camera.height * spp
    return (r.time_s / rays * 1e9, r.cpu_time_s / rays * 1e9), rays / paths


def mitsuba_render_s(mi_scene, spp: int, threads: int, seed: int) -> tuple[float, float]:
    """(wall, CPU) seconds of one Mitsuba render on ``threads`` threads (its kernels compiled beforehand)."""
    import drjit as dr
    import mitsuba as mi

    dr.set_thread_count(threads)
    t0, c0 = time.perf_counter(), process_cpu_s()
    np.asarray(mi.render(mi_scene, spp=spp, seed=seed))  # asarray waits for the kernel
    return time.perf_counter() - t0, process_cpu_s() - c0


def one_round(ctx: dict, k: int) -> dict:
    """Every measurement once: {name: (wall, CPU) ns per ray}, names (who, batch or
    'render', threads[, scene, width, coherent])."""
    out = {}
    for batch in BATCHES:
        floor = run_floor(ctx["program"], ctx["files"][batch])
        ctx["device"] = floor.pop("device")
        out |= {("floor", batch, t, *config): ns for (*config, t), ns in floor.items()}
        o, d = ctx["rays"][batch]
        for t in THREADS:
            out["ours", batch, t] = ours_query_ns(ctx["handle"], o, d, t, coherent=batch == "camera")
            out["mitsuba", batch, t] = ctx["mitsuba"][batch].ns(t)
    for t in THREADS:
        out["ours", "render", t], ctx["rays_per_path"] = pathtracer_ns(ctx["scene"], ctx["spp"], t, k)
        paths = ctx["scene"].camera.width * ctx["scene"].camera.height * ctx["spp"]
        s = mitsuba_render_s(ctx["render"], ctx["spp"], t, k)
        out["mitsuba", "render", t] = tuple(x / (paths * ctx["rays_per_path"]) * 1e9 for x in s)
    return out


def floor_ns(r: dict, batch: str, threads: int, clock: int, scene: str = "robust") -> float:
    """The floor of one round on one clock (0 wall, 1 CPU): the fastest call's ns per ray in that scene."""
    return min(r["floor", batch, threads, *c][clock] for c in CONFIGS if c[0] == scene)


def summarise(rounds: list[dict], clock: int) -> dict:
    """On one clock (0 wall, 1 CPU): medians of each figure, and of each round's ratio to the floor of the same
    batch and threads (a render's: to the first-bounce batch's), ours to the robust scene's, Mitsuba's to the
    fast one's (the scene it builds)."""
    med = {key: statistics.median(r[key][clock] for r in rounds) for key in rounds[0]}
    ratio = {}
    for key in rounds[0]:
        if key[0] != "floor":
            batch = "bounce" if key[1] == "render" else key[1]
            scene = "robust" if key[0] == "ours" else "fast"
            ratio[key] = statistics.median(r[key][clock] / floor_ns(r, batch, key[2], clock, scene) for r in rounds)
    return {"ns": med, "ratio": ratio}


def table(s: dict, ctx: dict, clock: str) -> list[str]:
    """One clock's two tables: the queries on both batches, then the whole renders."""
    ns, ratio = s["ns"], s["ratio"]
    cols = [(b, t) for b in BATCHES for t in THREADS]

    def cell(key):
        return f"{ns[key]:.1f} (**{ratio[key]:.2f}×**)"

    lines = [f"| {clock} ns per ray | " + " | ".join(f"{b}, {t} thread{'s' * (t > 1)}" for b, t in cols) + " |",
             "| --- |" + " --- |" * len(cols)]
    lines += [f"| floor, {scene} scene: C, `rtcIntersect{w}`{', coherent' * c} | "
              + " | ".join(f"{ns['floor', b, t, scene, w, c]:.1f}" for b, t in cols) + " |" for scene, w, c in CONFIGS]
    lines.append(f"| ours: `closest_triangles` (numba; {OURS_CALLS}) | "
                 + " | ".join(cell(("ours", b, t)) for b, t in cols) + " |")
    lines.append(f"| Mitsuba `{ctx['variant']}` `ray_intersect_preliminary` | "
                 + " | ".join(cell(("mitsuba", b, t)) for b, t in cols) + " |")
    lines += ["", f"| {clock} ns per ray, whole render | "
              + " | ".join(f"{t} thread{'s' * (t > 1)}" for t in THREADS) + " |", "| --- |" + " --- |" * len(THREADS),
              f"| ours, path tracer (÷ its closest-hit and shadow rays, {ctx['rays_per_path']:.2f} a path) | "
              + " | ".join(cell(("ours", "render", t)) for t in THREADS) + " |",
              "| Mitsuba `path` (÷ its paths × our rays per path) | "
              + " | ".join(cell(("mitsuba", "render", t)) for t in THREADS) + " |"]
    return lines


def markdown(rounds: list[dict], ctx: dict, loads: tuple[float, float]) -> list[str]:
    sizes = {b: len(ctx["rays"][b][0]) for b in BATCHES}
    cam = ctx["scene"].camera
    lines = [f"{sizes['camera']} camera rays and {sizes['bounce']} first-bounce rays of our path tracer on "
             f"`cornell-box`; whole renders at {cam.width}×{cam.height}, {ctx['spp']} spp. ns per ray: the time ÷ "
             f"the rays, median of {len(rounds)} rounds; in brackets the ratio to the floor, median of the rounds' "
             f"ratios: the fastest call on the same batch and threads (a whole render's: on the first-bounce "
             f"batch) in the scene each builds, ours the robust one, Mitsuba the fast one. CPU time is the cost of the work on this shared machine; wall time adds the waits for a core. "
             f"Load {loads[0]:.1f} → {loads[1]:.1f} runnable threads on {ctx['cpus']} cores. "
             f"C program: `{ctx['device']}`.", ""]
    lines += table(summarise(rounds, 1), ctx, "CPU")
    lines += [""] + table(summarise(rounds, 0), ctx, "wall")
    return lines


def main() -> None:
    import os

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rays", type=int, default=1 << 20, help="camera rays (paths) of a batch")
    ap.add_argument("--spp", type=int, default=16, help="spp of the whole renders")
    ap.add_argument("--repeats", type=int, default=5, help="rounds (medians over them)")
    ap.add_argument("--markdown", type=Path, action="append", default=[], help="write the block embree_floor.py")
    a = ap.parse_args()
    scene = resolve_scene("cornell-box")
    with tempfile.TemporaryDirectory() as tmp:
        ctx = {"scene": scene, "spp": a.spp, "cpus": os.cpu_count(), "program": build(Path(tmp)),
               "rays": ray_batches(scene, a.rays)}
        ctx["files"] = {b: Path(tmp) / f"{b}.bin" for b in BATCHES}
        for b in BATCHES:
            write_batch(ctx["files"][b], scene, *ctx["rays"][b])
        embree = EmbreeScene(*scene_arrays(scene))
        ctx["handle"] = embree.handle
        ctx["mitsuba"] = {b: MitsubaQuery(scene, *ctx["rays"][b], coherent=b == "camera") for b in BATCHES}
        ctx["variant"] = ctx["mitsuba"]["camera"].variant
        check_before_timing(ctx, Path(tmp))
        ctx["render"] = _mitsuba_render_scene(scene, a.spp)
        pathtracer_ns(scene.with_resolution(8, 8), 1, 1, 0)  # numba's cache loaded before the clock
        load0 = machine_load()
        rounds = []
        for k in range(a.repeats):
            rounds.append(one_round(ctx, k))
            print(f"round {k}: " + ", ".join(f"{'/'.join(map(str, key))} {v[0]:.0f}/{v[1]:.0f}"
                                             for key, v in rounds[-1].items()), flush=True)
        load1 = machine_load()
    lines = markdown(rounds, ctx, (load0, load1))
    print("\n".join(lines))
    command = " ".join([".venv/bin/python -m benchmarks.embree_floor", *map(shlex.quote, sys.argv[1:])])
    markdown_blocks.write_blocks(a.markdown, {BLOCK: "\n".join(lines)}, command)


def _mitsuba_render_scene(scene: Scene, spp: int):
    import mitsuba as mi

    from cornell_harness.renderers.mitsuba3 import scene_dict

    mi_scene = mi.load_dict(scene_dict(scene, spp, "independent"))
    np.asarray(mi.render(mi_scene, spp=spp, seed=12345))  # JIT warm-up
    return mi_scene


def plane_distances(scene: Scene, o: np.ndarray, d: np.ndarray, prim: np.ndarray) -> np.ndarray:
    """Distance along each ray to the plane of the triangle ``prim`` names, in float64 (inf where prim is -1)."""
    vertices, triangles = scene_arrays(scene)
    v = vertices.astype(np.float64)[triangles[np.maximum(prim, 0)]]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    t = np.einsum("ij,ij->i", v[:, 0] - o, n) / np.einsum("ij,ij->i", d.astype(np.float64), n)
    return np.where(prim >= 0, t, np.inf)


def check_agreement(scene: Scene, o: np.ndarray, d: np.ndarray, prim: np.ndarray, hits: dict) -> dict:
    """That the C program answers the question ours does; returns, per configuration, the rays whose triangle
    differs from ours (ties: the same distance on a shared edge).

    Asserted: every configuration hits where ours hits; Embree's default calls in the robust scene (ours)
    name our triangles exactly; every robust call gives the same distance as ``rtcIntersect1``, and that is
    the distance to our triangle's plane (float64, relative 1e-4); the fast scene's within 1e-4 of it.
    """
    t_ours = plane_distances(scene, o, d, prim)
    t1 = hits["robust", 1, 0][0].astype(np.float64)
    hit = prim >= 0
    assert np.allclose(t1[hit], t_ours[hit], rtol=1e-4), "rtcIntersect1's distances are not our triangles'"
    differ = {}
    for config, (t, p) in hits.items():
        assert np.array_equal(p >= 0, hit), f"{config} hits where closest_triangles misses, or the reverse"
        assert np.allclose(t[hit], t1[hit], rtol=0 if config[0] == "robust" else 1e-4), f"{config}: distances"
        assert config[0] != "robust" or config[2] or np.array_equal(p, prim), f"{config}: other triangles"
        differ[config] = int(np.sum(p != prim))
    return differ


def check_coherent(handle: int, o: np.ndarray, d: np.ndarray, hits: dict) -> None:
    """That our coherent query (camera rays, :data:`OURS_CALLS`) names the triangles the C program's coherent
    ``rtcIntersect16`` names in the robust scene, on every ray: the same call on the same packets (one thread,
    packets from the batch's first ray)."""
    prim = np.empty(len(o), np.int32)
    closest_triangles(handle, o, d, prim, ray_record(), True)
    assert np.array_equal(prim, hits["robust", 16, 1][1]), "ours coherent names other triangles than C's"


def check_before_timing(ctx: dict, tmp: Path) -> None:
    """Before timing: the floor answers what ours does, and Mitsuba the same distances (printed)."""
    for b in BATCHES:
        o, d = ctx["rays"][b]
        run_floor(ctx["program"], ctx["files"][b], 1, tmp / "hits.bin")
        hits = read_hits(tmp / "hits.bin", len(o))
        prim = np.empty(len(o), np.int32)
        closest_triangles(ctx["handle"], o, d, prim, ray_record())
        differ = check_agreement(ctx["scene"], o, d, prim, hits)
        if b == "camera":
            check_coherent(ctx["handle"], o, d, hits)
        t = hits["robust", 1, 0][0].astype(np.float64)
        t[prim < 0] = np.inf
        mt = ctx["mitsuba"][b].t()
        close = np.isclose(mt, t, rtol=1e-4) | (np.isinf(mt) & np.isinf(t))
        print(f"{b}: {len(o)} rays, {np.mean(prim < 0):.4%} miss; other triangle at the same distance "
              f"{ {k: v for k, v in differ.items() if v} }; Mitsuba's distance within 1e-4 on {close.mean():.4%}")


if __name__ == "__main__":
    main()
