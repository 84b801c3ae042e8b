"""Irradiance probes (DDGI): direct light exact, indirect light from a grid of ray-traced probes.

The renderer ``probes``: :mod:`cornell_harness.renderers.ddgi`'s volume (Majercik et al. 2019)
on the shared toolkit. A render is

1. **probe updates** (no progress bar of their own: the command running
   the renderer reports progress, and ``--quiet`` must silence it): each
   traces ``rays_per_probe`` rays from every probe, lights their hits with
   next-event estimation plus the previous update's irradiance, and blends
   them into the probes' maps (:func:`update_probes`). The first ``bounces``
   updates replace the probes (the seed's "repeat for more bounces": after k
   of them the probes carry k bounces); the next ``iterations`` are blended
   with what the probes hold (:func:`history_weight`): RTXGI's exponential
   moving average with ``hysteresis``, whose noise settles at a floor, or
   the ``exact`` running mean a static scene allows. Probes of a work unit
   are traced and blended on one thread; the volume an update reads is the
   previous one, so the result does not depend on the thread count;
2. **the camera pass**, ``spp`` samples per pixel
   (:mod:`cornell_harness.renderers.core.visible_points`): each camera path follows mirrors
   and glass to its first diffuse point x, collecting emission and direct
   light by next-event estimation exactly as the path tracer's first
   vertices do, then adds ρ/π · E(x) with E the probes' indirect irradiance
   (:func:`cornell_harness.renderers.ddgi.probe_irradiance`, normal and view bias, 8 probes
   with trilinear, wrap and Chebyshev visibility weights). With a bounded
   ``max_depth`` the indirect term is added where at least one bounce fits
   (depth + 2 ≤ max_depth); the probes' own bounce count is ``bounces`` and
   more (each blended update adds one).

The probe grid spans the scene's bounding box shrunk by ``margin`` of its
size on every side (or the box ``bounds`` gives), ``grid`` probes per axis.
Normal and view bias are given in units of the smallest probe spacing, so
they scale with the grid and the scene (RTXGI's Cornell box sample:
spacing 0.3, normal bias 0.02, view bias 0.1).

The estimate is biased (probe resolution, interpolation, visibility
heuristics, finite updates) and does not converge to the reference as spp
grows: ``estimator = "biased"``; the harness measures its bias per region.
Time includes the probe updates (``info["probes_s"]``). Random numbers come
from the ``sampler`` setting (:mod:`cornell_harness.renderers.core.sampler`; default
``independent``, the sampler the gate's expectations were measured with):
update k's probe rays draw from its key (:func:`cornell_harness.adapters.seeds.pass_key`
stream :data:`PROBE_STREAM`, index k), one sequence per probe over its rays
(:func:`update_stream`), and its rotation from :func:`update_rotation`; the
camera pass uses the toolkit's per-vertex layout
(:func:`cornell_harness.renderers.core.visible_points.camera_visible_points`), drawn from the pass's stream.
Images are bit-identical for any thread count.

**Sequences** (:meth:`IrradianceProbes.render_sequence`, an animated scene):
DDGI's temporal update (Majercik et al. 2019, §4: the probes are updated once
per frame, and "bounces accumulate frame after frame"). Frame i makes **one**
probe update, its rays lit by frame i − 1's volume, blended with hysteresis h
(:func:`sequence_weight`; ``bounces`` and ``iterations`` are for still images
only): E_i = h · E_{i−1} + (1 − h) · T(E_{i−1}) per texel (``gamma_blending``
off; on, the same lerp of E^(1/5)), T the one-bounce gather of their §4.1
(irradiance texels from the rays' radiance, the reflected part of which
reads E_{i−1}). With ``warm_start`` (the default) frame 0's probes are a
still render's, as if the scene had rested before the sequence; without,
frame 0's black probes give one bounce and the infinite-bounce result is
reached over frames. After a step change of the light, in a scene
where T is E ↦ T₀ + ρ·E (a furnace of albedo ρ), the error left after k
frames is λ^k of the step's with λ = h + (1 − h)·ρ: the hysteresis's h^k when
nothing is reflected twice, slower with interreflection
(``tests/renderers/test_probe_sequences.py``).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from cornell_harness.adapters.api import (RenderResult, SequenceResult, Setting, SettingsError, Stopwatch, default_threads,
                                          frame_seed, pass_key)
from cornell_harness.scenes.model import Scene
from cornell_harness.renderers import ddgi
from cornell_harness.renderers.core.adapter import ToolkitRenderer, warmed_geometry
from cornell_harness.renderers.core.frames import frames_to_render, still_frame
from cornell_harness.renderers.core.geometry import SceneGeometry
from cornell_harness.renderers.core.sampler import (ROTATION_U1, ROTATION_U2, Stream, independent, path_point,
                                                    sample_1d, sample_2d, sampler_setting, sequence_stream)
from cornell_harness.renderers.core.sampling import INV_PI, jit, random_rotation, spherical_fibonacci
from cornell_harness.renderers.core.schedule import render_image, run_units
from cornell_harness.renderers.core.settings import with_defaults
from cornell_harness.renderers.core.visible_points import camera_visible_points

PROBE_STREAM = 3
#: ``independent``: the update's rotation draws its numbers (the sampler's ``PROBE_ROTATION``) from this path of
#: its key, above any probe ray's index. A low-discrepancy sampler: update k's rotation is point k of one
#: sequence of this stream's key.
ROTATION_PATH = (1 << 40) - 1
ROTATION_STREAM = 4
#: Most probe rays per work unit (whole probes), as the camera pass's unit sizes.
UNIT_RAYS = 1 << 14
AVERAGING = ("ema", "exact")


class IrradianceProbes(ToolkitRenderer):
    """DDGI irradiance probes on Embree (module docstring): multithreaded, biased."""

    name = "probes"
    citations = (
        'Majercik, Guertin, Nowrouzezahrai and McGuire 2019, "Dynamic Diffuse Global Illumination with '
        'Ray-Traced Irradiance Fields" (JCGT 8(2))',
        "NVIDIA RTXGI SDK (its defaults)")
    estimator = "biased"
    sequences = True
    approximations = ("indirect light is interpolated from a grid of irradiance probes (DDGI): blurred "
                      "between probes, visibility by a Chebyshev bound, RTXGI's energy heuristics; biased",
                      "mirrors and glass seen by probe rays reflect nothing into the probes")
    settings = (
        sampler_setting("the camera paths (one sequence per pixel) and the probe rays (one sequence per probe "
                        "over its rays)"),
        Setting("grid", int, 8, "probes per axis (RTXGI's Cornell box: 9 at spacing 0.3 for a box of 2.4)",
                low=2, high=64),
        Setting("margin", float, 0.05, "the probe grid spans the scene's bounding box shrunk by this fraction "
                "of its size on each side", low=0.0, high=0.49),
        Setting("bounds", str, "", "the probe grid's corners 'x0,y0,z0,x1,y1,z1' instead of the shrunk bounding "
                "box (empty: the default)"),
        Setting("rays_per_probe", int, 256, "rays per probe per update (RTXGI probeNumRays 256)", low=8,
                high=8192),
        Setting("bounces", int, 8, "first probe updates, each replacing the probes (no history): after k of "
                "them the probes carry k bounces", low=1, high=1000),
        Setting("iterations", int, 16, "probe updates after the bounces, blended into the probes over time "
                "(RTXGI's per-frame updates)", low=0, high=100_000),
        Setting("hysteresis", float, 0.97, "weight of a texel's old value in an 'ema' update (RTXGI "
                "probeHysteresis 0.97)", low=0.0, high=0.999),
        Setting("warm_start", bool, True, "sequences: frame 0's probes are a still render's (bounces, then "
                "iterations), the scene at rest before it starts; false: black probes, one bounce in frame 0"),
        Setting("averaging", str, "ema", "temporal blend of the iterations: ema (RTXGI: lerp with the "
                "hysteresis) or exact (the running mean, for a static scene)", choices=AVERAGING),
        Setting("irradiance_texels", int, 6, "octahedral irradiance texels per side, border excluded (RTXGI 6)",
                low=2, high=64),
        Setting("depth_texels", int, 14, "octahedral distance texels per side, border excluded (RTXGI 14)",
                low=2, high=128),
        Setting("sharpness", float, 50.0, "exponent of the cosine weight of distances (RTXGI "
                "probeDistanceExponent 50)", low=1.0, high=1000.0),
        Setting("normal_bias", float, 0.067, "lookup offset along the normal, in probe spacings (RTXGI Cornell "
                "box: 0.02 at spacing 0.3)", low=0.0, high=1.0),
        Setting("view_bias", float, 0.333, "lookup offset towards the viewer, in probe spacings (RTXGI Cornell "
                "box: 0.1 at spacing 0.3)", low=0.0, high=1.0),
        Setting("visibility", bool, True, "weight probes by Chebyshev visibility from their distance moments"),
        Setting("gamma_blending", bool, True, "blend irradiance in gamma 5 over time and gamma 2 in space "
                "(RTXGI probeIrradianceEncodingGamma 5); false: linear"),
        Setting("half_normalisation", bool, True, "texel = pi * sum(L w) / sum(w) (RTXGI's 1/(2 sum w), times "
                "2 pi); false: the Monte Carlo estimate 4 pi / N * sum(L w)"),
        Setting("weight_floor", bool, True, "visibility weight at least 0.05 (RTXGI); false: 0"),
        Setting("crush", bool, True, "weights under 0.2 scaled by (w / 0.2)^2 (RTXGI); false: left alone"),
    )

    def render(self, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = (),
               settings: dict | None = None) -> RenderResult:
        s = with_defaults(self.settings, settings)
        threads = self.threads or default_threads()
        grid = grid_of(scene, s)
        geom, setup_s = warmed_geometry(scene, lambda g: _warm_up(g, scene, grid, s))
        clock = Stopwatch()
        volume = update_probes(geom, grid, seed, s, threads)
        probes_s, probes_cpu = clock.read()
        result = render_image(scene, spp, seed, CameraPass(geom, scene, volume).trace, checkpoints, threads,
                              sampler=s["sampler"])
        result.time_s += probes_s
        result.cpu_time_s += probes_cpu
        for c in result.checkpoints:
            c.time_s += probes_s
            c.cpu_time_s += probes_cpu
        result.info.update(s, probes=int(np.prod(grid.counts)), probe_spacing=grid.spacing.tolist(),
                           probe_origin=grid.origin.tolist(), probes_s=round(probes_s, 3),
                           setup_s=round(setup_s, 3), rays=geom.rays)
        return result


    def render_sequence(self, scene, spp: int, seed: int, settings: dict | None = None,
                        frames: Sequence[int] | None = None) -> SequenceResult:
        """The frames of an animated ``scene`` (all, or ``frames``): one probe update per frame, then the camera
        pass (module docstring, "Sequences"); frame i's camera pass is seeded with ``frame_seed(seed, i)``."""
        s = with_defaults(self.settings, settings)
        threads = self.threads or default_threads()
        count, wanted = frames_to_render(scene, frames)
        out = []
        for i, still, geom, volume, update_s, update_cpu in probe_frames(scene, seed, s, threads, count):
            if i not in wanted:
                continue
            result = render_image(still, spp, frame_seed(seed, i), CameraPass(geom, still, volume).trace, (),
                                  threads, sampler=s["sampler"])
            result.time_s += update_s
            result.cpu_time_s += update_cpu
            result.info.update(frame=i, probes_s=round(update_s, 3), rays=geom.rays,
                               hysteresis=s["hysteresis"], averaging=s["averaging"])
            out.append(result)
        return SequenceResult(out, {"hysteresis": s["hysteresis"], "averaging": s["averaging"],
                                    "updates_per_frame": 1})


def probe_frames(scene, seed: int, settings: dict, threads: int, count: int):
    """Frames 0 .. count-1 of ``scene`` with the volume after each frame's one update: (i, still scene of frame
    i, its geometry, the volume, the update's wall and CPU seconds, the scene's Embree build included).

    The grid is frame 0's, fixed in the world as a DDGI volume is; frame i's update (old texels' weight
    :func:`sequence_weight`) draws from ``frame_seed(seed, i)``'s update 0 and lights its rays with frame i − 1's
    volume: one bounce per frame (Majercik et al. 2019, §4). With ``warm_start`` frame 0's volume is instead a
    still render's (:func:`update_probes` of frame 0's scene, from ``frame_seed(seed, 0)``), the scene having
    rested before the sequence starts, and its update time is 0 (a pre-roll, not a frame's work): otherwise
    a hysteresis of 0.97 takes about 1/(1 − λ) ≈ 50 frames to climb from black probes, longer than a short
    sequence, and its lag after a change cannot be told from its warm-up.
    """
    grid, volume = None, None
    for i in range(count):
        still = still_frame(scene, i)
        if grid is None:
            grid = grid_of(still, settings)
            geom, _ = warmed_geometry(still, lambda g, still=still: _warm_up(g, still, grid, settings))
            volume = volume_of(grid, settings)
            if settings["warm_start"]:  # before the sequence starts, as a level's loading: no frame's time
                volume = update_probes(geom, grid, frame_seed(seed, 0), settings, threads)
                yield i, still, geom, volume, 0.0, 0.0
                continue
        clock = Stopwatch()
        if i:
            geom = SceneGeometry(still)
        volume = update_once(geom, volume, frame_seed(seed, i), 0, sequence_weight(i, settings), settings, threads)
        yield i, still, geom, volume, *clock.read()


def sequence_weight(i: int, settings: dict) -> float:
    """The old texels' weight in frame i's update: none in frame 0 (black probes), then the hysteresis (``ema``)
    or the running mean's i/(i + 1) (``exact``) (:func:`history_weight` of update i − 1 without bounces)."""
    return 0.0 if i == 0 else history_weight(i - 1, 0, settings["hysteresis"], settings["averaging"])


def grid_of(scene: Scene, settings: dict) -> ddgi.ProbeGrid:
    """The probe grid the settings ask for (raises SettingsError naming ``bounds`` if it is malformed)."""
    counts = np.full(3, settings["grid"], np.int64)
    if settings["bounds"]:
        try:
            corners = [float(v) for v in settings["bounds"].split(",")]
        except ValueError:
            corners = []
        lo, hi = np.asarray(corners[:3]), np.asarray(corners[3:])
        with np.errstate(over="ignore"):
            size = float(np.linalg.norm(hi - lo)) if len(corners) == 6 else 0.0
        # A size that overflows (1e300) would make the clamp distance inf: refused with the infinite ones.
        if len(corners) != 6 or not np.all(hi > lo) or not math.isfinite(size):
            raise SettingsError(f"renderer 'probes': setting bounds={settings['bounds']!r}: expected "
                                "'x0,y0,z0,x1,y1,z1', finite, with x1 > x0, y1 > y0, z1 > z0")
        return ddgi.probe_grid(lo, hi, counts)
    lo, hi = scene.bounds()
    inset = settings["margin"] * (hi - lo)
    lo, hi = lo + inset, hi - inset
    hi = np.where(hi > lo, hi, lo + 1e-6 * scene.extent())  # a flat scene: a flat grid still needs a spacing
    return ddgi.probe_grid(lo, hi, counts)


def volume_of(grid: ddgi.ProbeGrid, settings: dict) -> ddgi.Volume:
    """Black probes with the lookup parameters the settings ask for (biases in scene units)."""
    spacing = float(grid.spacing.min())
    return ddgi.empty_volume(grid, settings["irradiance_texels"], settings["depth_texels"],
                             settings["normal_bias"] * spacing, settings["view_bias"] * spacing,
                             ddgi.ENCODING_GAMMA if settings["gamma_blending"] else 1.0, settings["visibility"],
                             ddgi.WEIGHT_FLOOR if settings["weight_floor"] else 0.0,
                             ddgi.CRUSH_THRESHOLD if settings["crush"] else 0.0)


def update_probes(geom: SceneGeometry, grid: ddgi.ProbeGrid, seed: int, settings: dict, threads: int,
                  on_update=None) -> ddgi.Volume:
    """The volume after ``bounces`` updates without history, then ``iterations`` blended ones, from black.

    ``on_update(k, volume)``, if given, sees the volume after each update k = 1, 2, ...
    """
    volume = volume_of(grid, settings)
    for k in range(settings["bounces"] + settings["iterations"]):
        h = history_weight(k, settings["bounces"], settings["hysteresis"], settings["averaging"])
        volume = update_once(geom, volume, seed, k, h, settings, threads)
        if on_update is not None:
            on_update(k + 1, volume)
    return volume


def update_once(geom: SceneGeometry, volume: ddgi.Volume, seed: int, k: int, h: float, settings: dict,
                threads: int) -> ddgi.Volume:
    """``volume`` after update k (its rays keyed by ``seed`` and k): every probe's new maps blended with its old
    ones, old weight ``h``. Its rays are lit with ``volume`` itself: one more bounce."""
    grid = ddgi.ProbeGrid(volume.origin, volume.spacing, volume.counts)
    positions = ddgi.probe_positions(grid)
    fibonacci = spherical_fibonacci(settings["rays_per_probe"])
    probes, n = len(positions), len(fibonacci)
    per_unit = probes_per_unit(probes, n, threads)
    ni, nd = settings["irradiance_texels"], settings["depth_texels"]
    stream = update_stream(settings["sampler"], seed, k, probes)
    directions = np.ascontiguousarray(fibonacci @ update_rotation(settings["sampler"], seed, k).T)
    irradiance, moments = np.empty((probes, ni, ni, 3)), np.empty((probes, nd, nd, 2))

    def work(p0: int):
        count = min(per_unit, probes - p0)
        radiance, distance = ddgi.trace_probe_rays(geom, volume, positions, directions, p0, count, stream)
        return ddgi.blend(volume, p0, radiance, distance, directions, h, settings["half_normalisation"],
                          settings["sharpness"])

    def reduce(p0: int, maps) -> None:
        irradiance[p0:p0 + len(maps[0])], moments[p0:p0 + len(maps[1])] = maps

    run_units(range(0, probes, per_unit), work, reduce, threads)
    return ddgi.with_maps(volume, irradiance, moments)


def update_stream(sampler: str, seed: int, k: int, probes: int) -> Stream:
    """The numbers of update k's probe rays: its own key (:data:`PROBE_STREAM`), one sequence per probe."""
    return sequence_stream(sampler, pass_key(seed, k, PROBE_STREAM), probes)


def update_rotation(sampler: str, seed: int, k: int) -> np.ndarray:
    """Update k's random rotation of the Fibonacci directions (3, 3): ``independent``, from path
    :data:`ROTATION_PATH` of the update's key; otherwise point k of one sequence over the updates."""
    if sampler == "independent":
        stream, path = update_stream(sampler, seed, k, 1), ROTATION_PATH
    else:
        stream, path = sequence_stream(sampler, pass_key(seed, 0, ROTATION_STREAM), 1), k
    u0, (u1, u2) = _rotation_numbers(stream, path)
    return random_rotation(u0, u1, u2)


@jit
def _rotation_numbers(stream, path):
    """The rotation's numbers of ``path`` (the sampler's ``PROBE_ROTATION``: 1D, then 2D); in a kernel, since a
    point's uint64 seed does not survive a round trip through Python ints."""
    point = path_point(stream, path)
    return sample_1d(stream, point, ROTATION_U1), sample_2d(stream, point, ROTATION_U2)


def probes_per_unit(probes: int, rays: int, threads: int) -> int:
    """Probes per work unit of an update: at most :data:`UNIT_RAYS` rays, and enough units to keep every thread
    busy (a small grid was one unit, on one thread). The cut cannot change the volume: a probe ray's numbers
    are keyed by its index, each probe is blended alone, and every unit reads the previous volume."""
    return max(1, min(UNIT_RAYS // rays, -(-probes // (2 * threads))))


def history_weight(k: int, bounces: int, hysteresis: float, averaging: str) -> float:
    """The old texel's weight h in update k (from 0): 0 during the bounces; then the hysteresis (``ema``), or
    j/(j + 1) at the j-th blended update (``exact``: the running mean, the bounces' result counting once)."""
    if k < bounces:
        return 0.0
    if averaging == "ema":
        return hysteresis
    j = k - bounces + 1
    return j / (j + 1.0)


@jit
def _add_indirect(found, vp, vol, max_depth, L):
    """L += ρ/π · E at each found visible point where a bounce fits (``weight`` is β·ρ)."""
    for j in range(found.size):
        q = found[j]
        if max_depth >= 0 and vp.depth[q] + 2 > max_depth:
            continue
        e = ddgi.probe_irradiance(vol, (vp.position[q, 0], vp.position[q, 1], vp.position[q, 2]),
                                  (vp.normal[q, 0], vp.normal[q, 1], vp.normal[q, 2]),
                                  (vp.incoming[q, 0], vp.incoming[q, 1], vp.incoming[q, 2]))
        for c in range(3):
            L[q, c] += vp.weight[q, c] * INV_PI * e[c]


class CameraPass:
    """One render's trace function: the toolkit's visible points plus the probes' indirect light."""

    def __init__(self, geom: SceneGeometry, scene: Scene, volume: ddgi.Volume):
        self.geom, self.scene, self.volume = geom, scene, volume

    def trace(self, first: int, stop: int, pixels: int, stream: Stream) -> np.ndarray:
        L, vp = camera_visible_points(self.geom, self.scene, first, stop, pixels, stream)
        _add_indirect(np.flatnonzero(vp.found), vp, self.volume, self.scene.max_depth, L)
        return L


def _warm_up(geom: SceneGeometry, scene: Scene, grid: ddgi.ProbeGrid, settings: dict) -> None:
    """Compile (or load from numba's cache) every kernel before the clock starts: one tiny update and pass."""
    small = dict(settings, bounces=1, iterations=0, rays_per_probe=8)
    tiny = ddgi.ProbeGrid(grid.origin, grid.spacing * (grid.counts - 1), np.full(3, 2, np.int64))
    volume = update_probes(geom, tiny, 0, small, 1)
    CameraPass(geom, scene, volume).trace(0, 1, 1, independent(0))
