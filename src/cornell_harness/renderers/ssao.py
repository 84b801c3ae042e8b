"""Screen-space ambient occlusion (SSAO): three real-time estimates of a scene's AO from its G-buffer.

The image is the ``ambient_occlusion`` quantity of :mod:`cornell_harness.scenes.quantities`
(A in all three channels; ``miss_value`` where the camera ray hits nothing),
estimated the way a game engine does: from the depth and normal buffers of
one frame (:mod:`cornell_harness.renderers.core.gbuffer`, one ray through each pixel centre),
never from the scene itself. What the depth buffer does not show cannot
occlude: surfaces off screen (the **screen border** artefact: a wall just
outside the frame leaves A = 1 where it should darken) and anything behind
the first visible surface. All lengths are in scene units and all maths in
view space (x right, y up, z forward = depth; camera at the origin).

Variants (setting ``variant``)
------------------------------
- ``crytek``: Mittring 2007, "Finding Next Gen: CryEngine 2" (SIGGRAPH 2007
  course "Advanced Real-Time Rendering in 3D Graphics and Games", its section
  "Screen-Space Ambient Occlusion"): ``samples`` points in the ball of radius
  ``radius`` around the pixel's point, each projected to the screen and compared with the depth
  buffer there; A is the fraction of points in front of the buffer's surface.
  The sphere ignores the normal, so half of it lies inside the surface and
  **a flat surface reads 1/2** (the known artefact; the kernel is made of
  antipodal pairs, so an open plane reads exactly 1/2 wherever the whole
  ball projects inside the screen). The scene's ``weighting`` is not used.
- ``hemisphere``: the normal-oriented hemisphere that fixes it (Chapman 2013,
  "SSAO Tutorial"; de Vries, LearnOpenGL, "SSAO"): points in the hemisphere
  of radius ``radius`` around the normal, a point counting as occluded when
  it lies behind the depth buffer's surface and that surface passes the
  **range check** (its depth within ``radius`` of the pixel's: a far
  foreground object does not darken the background). Directions follow the
  scene's weighting (cosine: Malley's method; uniform: uniform in the
  hemisphere), lengths Chapman's ``lerp(0.1, 1, s²)``; A = 1 − occluded fraction.
  It counts occluded *points*, not blocked rays: a volumetric estimate, not
  the AO integral. LearnOpenGL's range check is a smoothstep; ours is a step
  at ``radius``, the scene's maximum distance.
- ``gtao``: ground-truth-based AO, Jimenez, Wu, Pesce and Jarabo 2016,
  "Practical Realtime Strategies for Accurate Indirect Occlusion" (Activision
  technical memo ATVI-TR-16-01, §4 and its Algorithm 1). The hemisphere is
  cut into ``slices`` planes through the view vector v (slice angles
  φ_k = (k + ½)·π/slices about v). In each, ``steps`` depth-buffer samples per
  side give the two horizon angles h1 ≤ 0 ≤ h2 from v (Algorithm 1 lines
  17-24): samples spread over the radius's length on screen (the part of it
  that is on screen), and one farther than ``radius`` in 3D does not count
  (a step falloff at the scene's maximum distance). The cosine-weighted
  visible arc between the horizons is integrated in closed form: the memo's
  horizon-based AO integral
  A = (1/π) ∫₀^π ∫_{h1(φ)}^{h2(φ)} cos(θ − γ)⁺ |sin θ| dθ dφ, with γ the
  angle of the normal projected onto the slice and ‖n_p‖ its length, has the
  inner integral ‖n_p‖·¼ Σ_{i=1,2} (−cos(2h_i − γ) + cos γ + 2 h_i sin γ)
  (Algorithm 1 line 27). So it estimates the same cosine-weighted integral
  as ray-traced AO, up to the screen-space approximations (only what the
  depth buffer shows occludes, which it treats as a height field; ``steps``
  samples find the horizon; ``slices`` planes sample φ). For a ``uniform``
  scene the inner integral is ∫ |sin θ| dθ = 2 − cos h1 − cos h2 with weight
  1/(2π) (no ‖n_p‖: no cosine), so ``gtao`` renders both weightings. The
  horizons are clamped to the normal's hemisphere, γ ± π/2, as in
  Algorithm 1. Two departures, both exact where the original is
  approximate: the slices are uniform in angle about v (Algorithm 1 takes
  them uniform in screen angle, which perspective skews off the image
  centre), and A is the visible sum divided by the slices' unoccluded sum
  (Σ ‖n_p‖(cos γ + γ sin γ), the same with both horizons at the tangent,
  whose mean over φ is exactly 1), so that the slice quadrature does not
  bias flat surfaces: an open plane reads 1 with any ``slices``.

Shared choices
--------------
- **Depth reconstruction.** A sample reads the pixel it falls in, and the
  depth along the sample's own view ray is taken from that pixel's tangent
  plane (its position and normal): exact on flat surfaces, so a plane never
  occludes itself and no depth bias is needed (implementations that read the
  depth buffer's texel need one, e.g. LearnOpenGL's 0.025).
- **Thickness heuristic** (setting ``thickness``, scene units; 0: off). A
  depth buffer shows each surface as an infinitely thick slab, so a thin
  foreground object darkens the background behind it (the **halo**
  artefact). With ``thickness`` t > 0 every visible surface is taken to be t
  thick: for ``crytek`` and ``hemisphere`` a point more than t behind the
  buffer's surface is not occluded (so points behind a thin foreground
  object are free, and crytek's dark halo turns light); for ``gtao`` a
  horizon sample more than t
  in front of the pixel's own depth is ignored (a horizon claims that every
  direction below it is blocked, which needs matter from the sample back to
  about the pixel's depth: the all-or-nothing form of Therrien et al. 2023's
  visibility bitmask; Jimenez et al. 2016 §4.3, "Height-field assumption
  considerations", relax the horizon instead, with a weight that has no
  length unit).
- **Radius** (setting ``radius``, scene units; 0: the scene's AO
  ``max_distance``). For a scene whose maximum distance is infinite, 0 means
  the scene's size (its bounding-box diagonal, :meth:`Scene.extent`), the
  farthest any occluder can be; gtao's ``steps`` samples then spread over the
  whole frame and small occluders are missed, and crytek's and hemisphere's
  points mostly land off screen, where nothing occludes.
- **Fixed kernels, no noise, no blur.** Real-time implementations rotate the
  kernel per pixel with a noise texture and blur the result (Chapman's 4×4);
  here every pixel uses the same kernel (low-discrepancy points; slice
  angles at fixed offsets), so the image is deterministic
  (``deterministic = True``: it does not depend on the seed) and shows
  banding where a real-time one would show noise before its blur.
- **spp** is ignored beyond being recorded: the estimate has no samples per
  pixel to add (its cost is set by ``samples`` or ``slices`` × ``steps``).

Time
----
``RenderResult.time_s`` is the wall time of the screen-space pass alone, one
frame at the scene's resolution, after a warm-up frame that compiles the
numba kernels (and fills caches). The G-buffer is not included: a game has
it from its geometry pass; its time, the Embree scene's build and one ray per
pixel, is ``info["gbuffer_s"]``, and ``info["screen_space_ms"]`` is ``time_s`` in
milliseconds. The pass runs on the toolkit's threads (row bands, each pixel
independent, so the image does not depend on the thread count).
"""

from __future__ import annotations

import math
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable, Mapping, NamedTuple, Sequence

import numpy as np

from cornell_harness.adapters.api import RenderResult, Setting, Stopwatch, default_threads
from cornell_harness.scenes.model import Scene
from cornell_harness.renderers.core.adapter import ToolkitRenderer
from cornell_harness.renderers.core.gbuffer import gbuffer, view_space
from cornell_harness.renderers.core.geometry import SceneGeometry
from cornell_harness.renderers.core.sampling import jit, orthonormal_basis
from cornell_harness.renderers.core.settings import with_defaults
from cornell_harness.renderers.gtao import gtao_pass
from cornell_harness.renderers.core.screen_space import on_screen, plane_depth, project

VARIANTS = ("crytek", "hemisphere", "gtao")
#: Defaults of the cost settings. At 256² on cornell-box-ao (2 CPU cores, numba, float64) a frame takes
#: about 10 ms (crytek, hemisphere: 16 points per pixel) and 45-75 ms (gtao: 4 slices × 2 sides × 8
#: steps = 64 depth reads per pixel); 8 slices × 12 steps take 3-4x as long for less banding (on the
#: floor beside a wall, |error| ≤ 0.015 instead of 0.035: tests/renderers/test_ssao.py).
SAMPLES, SLICES, STEPS = 16, 4, 8
#: 1/φ, the golden ratio's fractional part: the Kronecker sequence frac(i/φ) of the kernels.
_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0
#: 1/ρ, ρ the plastic number: the R2 sequence's first constant (Roberts 2018), a coordinate independent of 1/φ's.
_R2 = 0.7548776662466927


# -- kernels (numpy, built once per frame setting) --------------------------------------------

def sphere_kernel(samples: int) -> np.ndarray:
    """(samples, 3) points in the unit ball, uniform in volume, in antipodal pairs (±k): Crytek's kernel.

    Directions on a Fibonacci sphere (z = 1 − 2(i + ½)/m, azimuth 2π·frac(i/φ)),
    radii r = u^(1/3) with u = frac((i + ½)·R2) (uniform in volume); with an
    odd count the last point has no partner.
    """
    m = (samples + 1) // 2
    i = np.arange(m, dtype=np.float64)
    z = 1.0 - 2.0 * (i + 0.5) / m
    ring = np.sqrt(1.0 - z * z)
    phi = 2.0 * math.pi * ((i * _GOLDEN) % 1.0)
    r = (((i + 0.5) * _R2) % 1.0) ** (1.0 / 3.0)
    half = np.stack([ring * np.cos(phi), ring * np.sin(phi), z], axis=1) * r[:, None]
    return np.ascontiguousarray(np.concatenate([half, -half])[:samples])


def hemisphere_kernel(samples: int, weighting: str) -> np.ndarray:
    """(samples, 3) points in the unit hemisphere about +z (tangent space): Chapman's kernel.

    Directions: cosine-weighted (Malley's method) or uniform in solid angle,
    from the points ((i + ½)/n, frac(i/φ)); lengths lerp(0.1, 1, s²) with
    s = frac((i + ½)·R2) (Chapman 2013: more points near the centre, where
    occluders matter most).
    """
    i = np.arange(samples, dtype=np.float64)
    u1 = (i + 0.5) / samples
    phi = 2.0 * math.pi * ((i * _GOLDEN) % 1.0)
    cos_t = np.sqrt(1.0 - u1) if weighting == "cosine" else 1.0 - u1
    sin_t = np.sqrt(1.0 - cos_t * cos_t)
    s = ((i + 0.5) * _R2) % 1.0
    length = 0.1 + 0.9 * s * s
    return np.ascontiguousarray(np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=1) * length[:, None])


# -- reading the depth buffer ----------------------------------------------------------------
class Screen(NamedTuple):
    """The frame a pass works on (scalars only: kernels unpack it at once)."""

    width: int  # pixels
    height: int
    tx: float  # tan of the half field of view, horizontally
    ty: float  # and vertically


# The kernels read the G-buffer arrays themselves and every helper takes scalars
# (src/cornell_harness/renderers/core/screen_space.py says why: an array-taking helper made crytek's pass 2x slower).

@jit
def _occludes(behind, thickness) -> bool:
    """Whether a point ``behind`` (its depth minus the buffer's) lies inside what the buffer shows, t thick (0: ∞)."""
    return behind > 0.0 and (thickness <= 0.0 or behind <= thickness)


# -- the three passes (rows row0 .. row1-1; NaN where the pixel saw nothing) ----------------
# A point q's depth-buffer depth is read where q projects, along q's own view ray; a q behind
# the camera or off screen finds nothing there (inf): what the screen does not show never occludes.

@jit
def _crytek(gb, kernel, radius, thickness, screen, row0, row1, out):
    """Mittring 2007: fraction of the ball's points in front of the depth buffer."""
    width, height, tx, ty = screen
    n = kernel.shape[0]
    cx, cy, cu, cv = width / (2.0 * tx), height / (2.0 * ty), 0.5 * width, 0.5 * height
    for row in range(row0, row1):
        for col in range(width):
            pz = gb[row, col, 2]
            if not pz < np.inf:
                out[row, col] = np.nan
                continue
            px, py = gb[row, col, 0], gb[row, col, 1]
            free = 0
            for k in range(n):
                qx, qy, qz = px + radius * kernel[k, 0], py + radius * kernel[k, 1], pz + radius * kernel[k, 2]
                zb = np.inf
                if qz > 0.0:
                    u, v, dx, dy = project(qx, qy, qz, cx, cy, cu, cv)
                    if on_screen(u, v, width, height):
                        i, j = int(v), int(u)
                        zb = plane_depth(gb[i, j, 0], gb[i, j, 1], gb[i, j, 2], gb[i, j, 3], gb[i, j, 4],
                                          gb[i, j, 5], dx, dy)
                if not _occludes(qz - zb, thickness):
                    free += 1
            out[row, col] = free / n


@jit
def _hemisphere(gb, kernel, radius, thickness, screen, row0, row1, out):
    """Chapman / LearnOpenGL: 1 − the fraction of the normal hemisphere's points behind the depth buffer
    (range-checked)."""
    width, height, tx, ty = screen
    n = kernel.shape[0]
    cx, cy, cu, cv = width / (2.0 * tx), height / (2.0 * ty), 0.5 * width, 0.5 * height
    for row in range(row0, row1):
        for col in range(width):
            pz = gb[row, col, 2]
            if not pz < np.inf:
                out[row, col] = np.nan
                continue
            px, py = gb[row, col, 0], gb[row, col, 1]
            nx, ny, nz = gb[row, col, 3], gb[row, col, 4], gb[row, col, 5]
            s, t = orthonormal_basis(nx, ny, nz)
            occluded = 0
            for k in range(n):
                a, b, c = radius * kernel[k, 0], radius * kernel[k, 1], radius * kernel[k, 2]
                qx = px + a * s[0] + b * t[0] + c * nx
                qy = py + a * s[1] + b * t[1] + c * ny
                qz = pz + a * s[2] + b * t[2] + c * nz
                if not qz > 0.0:
                    continue
                u, v, dx, dy = project(qx, qy, qz, cx, cy, cu, cv)
                if not on_screen(u, v, width, height):
                    continue
                i, j = int(v), int(u)
                zb = plane_depth(gb[i, j, 0], gb[i, j, 1], gb[i, j, 2], gb[i, j, 3], gb[i, j, 4], gb[i, j, 5],
                                  dx, dy)
                if _occludes(qz - zb, thickness) and abs(pz - zb) <= radius:  # the range check
                    occluded += 1
            out[row, col] = 1.0 - occluded / n


# -- the pass as a whole -----------------------------------------------------------------------

def screen_space_pass(variant: str, pos: np.ndarray, nrm: np.ndarray, scene: Scene, radius: float,
                      thickness: float, samples: int, slices: int, steps: int,
                      pool: ThreadPoolExecutor | None = None, threads: int = 1) -> Callable[[], np.ndarray]:
    """A function that computes one frame of ``variant`` from view-space ``pos``, ``nrm`` (H, W, 3).

    It returns A (H, W) float64, NaN where the pixel saw nothing. Kernels are
    built here, so calling it times the pass alone. With ``pool`` (of
    ``threads`` workers) the rows are cut into bands, computed on its threads.
    """
    cam = scene.camera
    w, h = cam.width, cam.height
    tx, ty = cam.tan_half_fov()
    screen = Screen(int(w), int(h), float(tx), float(ty))
    # One array of (x, y, z, nx, ny, nz) per pixel: a depth-buffer read touches one place in memory, not two.
    gb = np.ascontiguousarray(np.concatenate([pos, nrm], axis=2))
    cosine = scene.ambient_occlusion.weighting == "cosine"
    if variant == "crytek":
        kernel = sphere_kernel(samples)
        def band(r0, r1, out):
            _crytek(gb, kernel, radius, thickness, screen, r0, r1, out)
    elif variant == "hemisphere":
        kernel = hemisphere_kernel(samples, "cosine" if cosine else "uniform")
        def band(r0, r1, out):
            _hemisphere(gb, kernel, radius, thickness, screen, r0, r1, out)
    elif variant == "gtao":
        def band(r0, r1, out):
            gtao_pass(gb, radius, thickness, slices, steps, cosine, screen, r0, r1, out)
    else:
        raise ValueError(f"unknown SSAO variant {variant!r}; known: {', '.join(VARIANTS)}")
    # A few bands per thread even out rows of unequal cost (misses are free).
    cuts = np.linspace(0, h, min(h, 4 * threads) + 1).astype(int)
    bands = [(int(a), int(b)) for a, b in zip(cuts[:-1], cuts[1:]) if b > a]

    def frame() -> np.ndarray:
        out = np.empty((h, w))
        if pool is None:
            band(0, h, out)
        else:
            list(pool.map(lambda rows: band(rows[0], rows[1], out), bands))
        return out

    return frame


def resolved_radius(scene: Scene, radius: float) -> float:
    """The radius a render uses: ``radius`` if > 0, else the scene's AO max distance, else (inf) its size."""
    if radius > 0.0:
        return float(radius)
    d = scene.ambient_occlusion.max_distance
    return float(d) if math.isfinite(d) else scene.extent()


class SSAO(ToolkitRenderer):
    """Screen-space ambient occlusion: Crytek's sphere, the normal hemisphere, or GTAO (module docstring)."""

    name = "ssao"
    citations = (
        'Mittring 2007, "Finding Next Gen: CryEngine 2" (SIGGRAPH course)',
        'Chapman 2013, "SSAO Tutorial"; de Vries, LearnOpenGL, "SSAO"',
        'Jimenez, Wu, Pesce and Jarabo 2016, "Practical Realtime Strategies for Accurate Indirect Occlusion" '
        '(ATVI-TR-16-01)')
    quantities = ("ambient_occlusion",)
    estimator = "biased"
    deterministic = True
    approximations = (
        "screen space: only surfaces in the depth buffer occlude (nothing off screen or behind the first surface)",
        "one sample per pixel centre (no box filter), as a rasteriser without multisampling",
        "crytek reads about 1/2 on flat surfaces; hemisphere counts occluded points, not blocked rays",
        "gtao treats the depth buffer as a height field and finds horizons from a fixed number of samples",
    )
    settings = (
        Setting("variant", str, "gtao", "crytek (Mittring 2007), hemisphere (Chapman/LearnOpenGL), "
                "gtao (Jimenez et al. 2016)", choices=VARIANTS),
        Setting("radius", float, 0.0, "occlusion radius, scene units; 0: the scene's AO max_distance "
                "(its size if that is inf)", low=0.0),
        Setting("samples", int, SAMPLES, "kernel points per pixel (crytek, hemisphere)", low=1, high=4096),
        Setting("slices", int, SLICES, "slices per pixel (gtao)", low=1, high=256),
        Setting("steps", int, STEPS, "horizon samples per slice side (gtao)", low=1, high=1024),
        Setting("thickness", float, 0.0, "assumed thickness of visible surfaces, scene units: an occluder "
                "more than this behind the depth buffer's surface does not occlude; 0: infinitely thick (off)",
                low=0.0),
    )

    def render(self, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = (),
               settings: Mapping[str, Any] | None = None) -> RenderResult:
        s = with_defaults(self.settings, settings)
        ao = scene.ambient_occlusion
        if scene.quantity != "ambient_occlusion" or ao is None:
            raise ValueError(f"ssao computes ambient occlusion; scene {scene.name!r} is of quantity {scene.quantity}")
        radius = resolved_radius(scene, s["radius"])
        t0 = time.perf_counter()
        g = gbuffer(scene, SceneGeometry(scene))
        pos, nrm = view_space(g, scene.camera)
        gbuffer_s = time.perf_counter() - t0
        threads = self.threads or default_threads()
        with ThreadPoolExecutor(threads) as pool:
            frame = screen_space_pass(s["variant"], pos, nrm, scene, radius, s["thickness"], s["samples"],
                                      s["slices"], s["steps"], pool if threads > 1 else None, threads)
            frame()  # compile (or load numba's cache) and warm up outside the clock
            setup_s = time.perf_counter() - t0  # G-buffer, compilation and the warm-up frame
            clock = Stopwatch()
            a = frame()
            elapsed, cpu = clock.read()
        image = np.repeat(np.where(g.prim >= 0, a, ao.miss_value)[:, :, None], 3, axis=2).astype(np.float32)
        info = {"variant": s["variant"], "radius": radius, "thickness": s["thickness"],
                "screen_space_ms": round(1e3 * elapsed, 3), "gbuffer_s": round(gbuffer_s, 4), "setup_s": round(setup_s, 4),
                "threads": threads, "spp_used": False}
        if s["variant"] == "gtao":
            info.update(slices=s["slices"], steps=s["steps"])
        else:
            info.update(samples=s["samples"])
        return RenderResult(image=image, time_s=elapsed, spp=int(spp), seed=int(seed), checkpoints=[], info=info,
                            cpu_time_s=cpu)
