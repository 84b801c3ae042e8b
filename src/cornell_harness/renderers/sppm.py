"""Stochastic progressive photon mapping (Hachisuka & Jensen 2009), radii shrinking as Knaus & Zwicker 2011.

Each iteration, on the shared toolkit:

1. **Camera pass** (:mod:`cornell_harness.renderers.core.visible_points`): one jittered
   camera path per pixel through mirrors and glass to its first diffuse
   point, the pixel's visible point of this iteration; emission on the way
   and direct light at the point (next-event estimation) go into the
   pixel's sum Ld, as pbrt-v4's ``SPPMIntegrator`` does (§16.2), so photons
   carry indirect light only.
2. **Photon pass** (:mod:`cornell_harness.renderers.core.photons`, ``STORE_INDIRECT``):
   ``photons_per_iteration`` photons (default: one per pixel, as pbrt-v4);
   each one stored at a diffuse surface is gathered by every visible point
   within that pixel's radius r_i (a cKDTree over the visible points,
   :meth:`scipy.spatial.cKDTree.sparse_distance_matrix`), passing the photon
   maps' normal test and depth budget (:mod:`cornell_harness.renderers.core.photon_map`):
   Φ_i += β·ρ/π · Φ_p, M_i += 1.
3. **Update** (Hachisuka & Jensen 2009 eqs. 5-7; pbrt-v4 §16.2.3): with
   α (``alpha``) the fraction of new photons kept,
   N' = N + α·M, r' = r·sqrt(N'/(N + M)), τ' = (τ + Φ)·r'²/r².

After n iterations a pixel's radiance is Ld/n + τ/(n·π·r²) (the photons of
each pass carry the scene's flux divided by that pass's count). With
α < 1 the radius shrinks to 0 while N grows without bound, so bias and
variance both vanish: the estimator is consistent, and Knaus & Zwicker 2011
(§4) show its MSE falls as n^(-2/3) at best, for α = 2/3 (against n^(-1) for an
unbiased one); α = 1 keeps the first radius forever and converges to a blurred image.

The initial radius of a pixel is ``initial_radius`` (default 2) **pixel
footprints at its visible point**, in scene units
(:func:`footprints`): the width of the pixel's cone, √Ω_pixel, times the
camera path's length to the point, where Ω_pixel = (2 tan_x/W)(2 tan_y/H)
cos³θ is the pinhole's solid angle of the pixel at angle θ off the axis
(the spread of the camera ray's differentials, Igehy 1999; pbrt-v4 §10.1.1,
``CameraBase::Approximate_dp_dxy``, estimates texture footprints the same
way). Through mirrors and glass the path's whole length counts: a
flat mirror keeps the cone's angle, so the footprint grows with the
distance travelled; a curved one focuses or spreads it, which this rule
ignores (the footprint is a first guess: the radius shrinks from it). The
foreshortening on the surface (1/cos at the point) is ignored too: the disc's
radius is the footprint's narrow width. A pixel's radius is set the first
iteration its camera path finds a visible point, and shrinks from there.
This follows the geometry the camera sees, as Hachisuka's reference code
(smallppm: 2 pixel widths over the visible points' bounding box) and not
the scene's bounds (Mitsuba 0.6's ``sppm``: 5 pixel widths of the bounding
sphere; ours once: 2 at the scene's centre), which an off-screen
mirror or wall inflates: a small patch lit through a mirror reaching far
off-screen started at 19 pixel widths and read -14.8% after 64 iterations,
against -1.8% with the mirror cut to what lights it; from its own
footprint -2.1% in both (tests/renderers/test_photons.py,
``test_sppm_radius_ignores_geometry_the_camera_does_not_see``).
``initial_radius_world`` > 0 overrides it with one radius in scene units for
every pixel (pbrt-v4's ``radius`` parameter, whose default is 1).

The default, 2 footprints, is for caustics, what SPPM is for: on
cornell-box-caustics (seed 0) from 2 footprints at the scene's centre the
caustic's relMSE reached 0.05 in 1.0 s and 0.01 in 5.5 s, against 5.2 s
and about 80 s from 4, whose larger discs smooth the image-wide noise
sooner (ΔE mean ≤ 2 in 2.8 s against about 5 s) but blur the caustic's edge
for longer; the per-point footprint's figures are in BENCHMARKS.md
(``benchmarks/photons_before_after.py``). More photons per iteration do
not make up for a large start: the radius shrinks by the ratio of photons
kept to photons gathered, so per iteration, not per photon.

spp is iterations. The render is progressive: the checkpoints 1, 2, 4, ...
come from one run. Every pass is keyed from the seed
(:func:`cornell_harness.adapters.api.pass_key`: iteration i's camera pass is
stream 0, its photons :data:`PHOTON_STREAM`), and work is reduced in order,
so an image is bit-identical for any thread count. The ``sampler`` setting
draws the numbers (:mod:`cornell_harness.renderers.core.sampler`): with ``pmj02`` or
``sobol`` iteration i is sample i of each pixel's sequence, and each photon
pass is one sequence over its photons.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from scipy.spatial import cKDTree

from cornell_harness.adapters.api import Checkpoint, RenderResult, Setting, Stopwatch, default_threads, pass_key
from cornell_harness.scenes.model import Scene
from cornell_harness.renderers.core.adapter import ToolkitRenderer, warmed_geometry
from cornell_harness.renderers.core.camera import pixel_cone_widths
from cornell_harness.renderers.core.geometry import SceneGeometry
from cornell_harness.renderers.core.photon_map import depth_budget, pairs_that_count
from cornell_harness.renderers.core.photons import BATCH, STORE_INDIRECT, trace_photons
from cornell_harness.renderers.core.sampler import Stream, independent, pass_stream, sampler_setting, sequence_stream
from cornell_harness.renderers.core.schedule import pass_units, run_units
from cornell_harness.renderers.core.settings import with_defaults
from cornell_harness.renderers.core.visible_points import VisiblePoints, camera_visible_points, visible_buffer

PHOTON_STREAM = 1


class SPPM(ToolkitRenderer):
    """Our SPPM renderer (progressive: one checkpoint per power-of-two iteration count, from one run)."""

    name = "sppm"
    citations = (
        'Hachisuka and Jensen 2009, "Stochastic Progressive Photon Mapping" (SIGGRAPH Asia)',
        'Knaus and Zwicker 2011, "Progressive Photon Mapping: A Probabilistic Approach" (ACM TOG)',
        'Pharr, Jakob and Humphreys 2023, "Physically Based Rendering", 4th ed. (pbrt-v4), SPPMIntegrator')
    estimator = "consistent"
    approximations = ("indirect light and caustics are density estimates over shrinking radii: biased at any "
                      "finite iteration count, consistent",)
    settings = (
        Setting("photons_per_iteration", int, 0, "photons shot per iteration; 0: one per pixel (pbrt-v4's default)",
                low=0, high=100_000_000),
        Setting("alpha", float, 2 / 3, "fraction of each iteration's photons kept; the radius shrinks with it "
                "(Hachisuka & Jensen 2009; 2/3 is Knaus & Zwicker 2011's optimum, 1 never shrinks)",
                low=0.01, high=1.0),
        Setting("initial_radius", float, 2.0, "starting gather radius, in pixel footprints at each pixel's visible "
                "point (the pixel's cone width times the camera path's length; 2: see the module docstring)",
                low=1e-3, high=1000.0),
        Setting("initial_radius_world", float, 0.0, "starting gather radius in scene units for every pixel, "
                "overriding initial_radius (pbrt-v4's radius); 0: from the pixel footprints",
                low=0.0, high=1e6),
        sampler_setting("the camera passes (one sequence per pixel over the iterations) and of each photon pass "
                        "(one sequence over its photons)", batches=False),
    )

    def render(self, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = (),
               settings: dict | None = None) -> RenderResult:
        if spp < 1:
            raise ValueError(f"spp must be >= 1, got {spp}")
        s = with_defaults(self.settings, settings)
        threads = self.threads or default_threads()
        # A warm-up iteration with enough photons that some land near a visible point (with one, none did,
        # and a process's first render compiled the photon tests inside its time).
        geom, setup_s = warmed_geometry(scene, lambda g: Progress(g, scene, s).iterate(independent(0), independent(0),
                                                                                       1, photons=256))
        state = Progress(geom, scene, s)
        photons = s["photons_per_iteration"] or state.pixels
        shots, clock = [], Stopwatch()
        for i in range(spp):
            # Iteration i is sample i of each pixel's camera sequence (no batches: SPPM reports no variance).
            state.iterate(pass_stream(s["sampler"], seed, i, state.pixels, i, batches=1),
                          sequence_stream(s["sampler"], pass_key(seed, i, PHOTON_STREAM)), threads, photons)
            if i + 1 in checkpoints and i + 1 < spp:
                shot = state.image(i + 1)
                wall, cpu = clock.read()
                shots.append(Checkpoint(i + 1, shot, wall, cpu_time_s=cpu))
        elapsed, cpu = clock.read()
        image = state.image(spp)
        if spp in checkpoints:
            shots.append(Checkpoint(spp, image, elapsed, cpu_time_s=cpu))
        seen = state.r0 > 0
        info = dict(s, threads=threads, setup_s=round(setup_s, 3), rays=geom.rays, photons_per_iteration=photons,
                    initial_radius_median=float(np.median(state.r0[seen])) if seen.any() else 0.0,
                    final_radius_median=float(np.median(state.radius[seen])) if seen.any() else 0.0)
        return RenderResult(image, elapsed, spp, seed, shots, info, None, cpu_time_s=cpu)


def footprints(cone_width: np.ndarray, distance: np.ndarray) -> np.ndarray:
    """A pixel's footprint at its visible point, in scene units: its cone's width times the camera path's
    length (mirrors and glass included: see the module docstring)."""
    return cone_width * distance


class Progress:
    """Per-pixel SPPM statistics (Ld, N, r, τ) after the iterations so far."""

    def __init__(self, geom: SceneGeometry, scene: Scene, settings: dict):
        self.geom, self.scene, self.s = geom, scene, settings
        cam = scene.camera
        self.pixels = cam.width * cam.height
        self.cone = pixel_cone_widths(cam)  # cornell_harness.renderers.core.camera: the pixel convention
        self.ld = np.zeros((self.pixels, 3))
        self.n = np.zeros(self.pixels)
        # 0: not set yet (the pixel has not found a visible point); r0 keeps each pixel's start for the record.
        self.radius = np.zeros(self.pixels)
        self.r0 = np.zeros(self.pixels)
        self.tau = np.zeros((self.pixels, 3))

    def image(self, iterations: int) -> np.ndarray:
        """The estimate after ``iterations``: Ld/n + τ/(n·π·r²), float32 (height, width, 3).

        A pixel whose radius is not set has gathered nothing (τ = 0): Ld/n alone.
        """
        cam = self.scene.camera
        area = iterations * math.pi * self.radius ** 2
        photons = np.divide(self.tau, area[:, None], out=np.zeros_like(self.tau), where=area[:, None] > 0)
        L = self.ld / iterations + photons
        return L.reshape(cam.height, cam.width, 3).astype(np.float32)

    def _start_radii(self, vp: VisiblePoints) -> None:
        """Set the radius of every pixel that found its first visible point this iteration."""
        new = vp.found & (self.radius == 0.0)
        if self.s["initial_radius_world"] > 0:
            self.radius[new] = self.s["initial_radius_world"]
        else:
            self.radius[new] = self.s["initial_radius"] * footprints(self.cone[new], vp.distance[new])
        self.r0[new] = self.radius[new]

    def iterate(self, camera: Stream, photon: Stream, threads: int, photons: int) -> None:
        """One iteration: the camera pass drawing from ``camera``, ``photons`` photons from ``photon``."""
        vp = self._camera_pass(camera, threads)
        self._start_radii(vp)
        found = np.flatnonzero(vp.found)
        phi, m = np.zeros((self.pixels, 3)), np.zeros(self.pixels)
        if found.size:
            gather = _Gather(self, vp, found)

            def work(batch):
                return gather.photons(photon, batch[0], batch[1])

            def reduce(batch, result):
                phi[:] += result[0]
                m[:] += result[1]

            run_units(((b, min(b + BATCH, photons)) for b in range(0, photons, BATCH)), work, reduce, threads)
            # Each photon pass carries the scene's whole flux: divide by its photon count.
            phi /= photons
        self._update(phi, m)

    def _camera_pass(self, stream: Stream, threads: int) -> VisiblePoints:
        vp = visible_buffer(self.pixels)

        def work(unit):
            return camera_visible_points(self.geom, self.scene, unit.first, unit.stop, self.pixels, stream)

        def reduce(unit, result):
            L, points = result
            self.ld[unit.first:unit.stop] += L
            for whole, part in zip(vp, points):
                whole[unit.first:unit.stop] = part

        run_units(pass_units([1], self.pixels, threads), work, reduce, threads)
        return vp

    def _update(self, phi: np.ndarray, m: np.ndarray) -> None:
        """Hachisuka & Jensen 2009 eqs. 5-7 for every pixel that gathered a photon this iteration."""
        hit = m > 0
        alpha = self.s["alpha"]
        n_new = self.n[hit] + alpha * m[hit]
        r_new = self.radius[hit] * np.sqrt(n_new / (self.n[hit] + m[hit]))
        self.tau[hit] = (self.tau[hit] + phi[hit]) * (r_new ** 2 / self.radius[hit] ** 2)[:, None]
        self.n[hit], self.radius[hit] = n_new, r_new


class _Gather:
    """The visible points of one iteration, indexed, gathering one batch of photons at a time."""

    def __init__(self, progress: Progress, vp: VisiblePoints, found: np.ndarray):
        self.p = progress
        self.found = found
        self.position = vp.position[found]
        self.normal = vp.normal[found]
        self.weight = vp.weight[found]
        self.budget = depth_budget(progress.scene.max_depth, vp.depth[found])
        self.radius = progress.radius[found]
        self.tree = cKDTree(self.position, balanced_tree=False, compact_nodes=False)

    def photons(self, stream: Stream, first: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
        """(Φ (pixels, 3), M (pixels,)) gathered from photons first .. stop-1 of this iteration's ``stream``."""
        ph = trace_photons(self.p.geom, self.p.scene, stream, first, stop, STORE_INDIRECT)
        phi, m = np.zeros((self.p.pixels, 3)), np.zeros(self.p.pixels)
        if len(ph) == 0:
            return phi, m
        pairs = self.tree.sparse_distance_matrix(cKDTree(ph.position), float(self.radius.max()),
                                                 output_type="ndarray")
        i, j, d = pairs["i"], pairs["j"], pairs["v"]
        faces = np.empty(i.size, bool)
        pairs_that_count(self.normal, i, ph.normal, ph.direction, j, faces)  # the photon maps' tests
        ok = (d < self.radius[i]) & faces & (ph.depth[j] <= self.budget[i])
        i, j = i[ok], j[ok]
        pixel = self.found[i]
        contribution = self.weight[i] / math.pi * ph.power[j]
        for c in range(3):
            phi[:, c] = np.bincount(pixel, contribution[:, c], self.p.pixels)
        m[:] = np.bincount(pixel, minlength=self.p.pixels)
        return phi, m
