"""Photon mapping: Jensen's two-pass method with a caustic map, a global map and final gathering.

Jensen 1996 ("Global Illumination using Photon Maps", EGWR) and Jensen 2001
("Realistic Image Synthesis Using Photon Mapping", ch. 9, "A Practical
Two-Pass Algorithm"), on the shared toolkit:

**Pass 1** (:mod:`cornell_harness.renderers.core.photons`): photons from the emitters by
power, stored in two maps (:class:`cornell_harness.renderers.core.photon_map.PhotonMap`,
a cKDTree each): the **caustic map** of L S+ D photons (``caustic_photons``
stored) and the **global map** of every diffuse hit (``global_photons``
stored), as Mitsuba 0.6's ``photonmapper``, whose defaults (250 000 each) are ours.

**Pass 2**, per camera sample (:mod:`cornell_harness.renderers.core.visible_points`): the
camera ray follows mirrors and glass to its first diffuse point x. The
radiance there is split by the path's history, each part estimated once:

- emission, and direct light by next-event estimation (L D): the toolkit's;
- caustics (L S+ D): ρ/π · E from the caustic map, k nearest photons
  within ``max_radius``, with the ``kernel`` and the normal test
  (:meth:`PhotonMap.irradiance`);
- the rest of indirect light, **final gathering**: ``gather_rays``
  cosine-weighted rays from x follow specular bounces to a diffuse point y
  and take the global map's radiance there, ρ_y/π · E(y), every photon
  counted (emission found by gather rays is not: NEE and the caustic map
  have it). E(y) is Christensen's precomputed irradiance
  (:class:`cornell_harness.renderers.core.photon_map.PrecomputedIrradiance`, at every
  :data:`PRECOMPUTE_STRIDE`-th photon). With ``gather_rays = 0`` the global
  map is seen directly: E at x from its photons that are neither direct nor
  caustic (the "blotchy" variant).

Lookup sizes. Mitsuba 0.6 gathers 120 photons per lookup and sets the
lookup radii relative to the scene's bounding sphere (caustic 0.0125,
global 0.05). We keep the radii (the global one is
:data:`GLOBAL_RADIUS_FACTOR` times ``max_radius``) but default to k = 30:
every camera sample does its own lookup and spp of them average a pixel,
so a smaller k shrinks the radius, hence the blur (bias), at no cost in
pixel noise, and costs a quarter of the time (cKDTree: 15 µs against 45 µs
per query, BENCHMARKS.md).

The estimator is biased (the density estimate blurs over radius r) and
consistent as the photon counts grow and r shrinks: the harness measures
it with bias/variance splits and a consistency check, never a z-test
(``estimator = "consistent"``). spp is the render pass's samples per pixel;
the photon maps are built once per render, deterministically from the seed
(:func:`cornell_harness.adapters.api.pass_key` streams :data:`GLOBAL_STREAM`,
:data:`CAUSTIC_STREAM`), so images are bit-identical for any thread count.
The ``sampler`` setting (:mod:`cornell_harness.renderers.core.sampler`) draws every number:
each map's photons are one sequence, camera paths and gather rays one per
pixel (default ``independent``, the numbers the gate's budgets were measured with);
gather ray g draws its direction and its walk from the sampler's blocks
:data:`cornell_harness.renderers.core.sampler.GATHER` and ``GATHER_WALKS``.
"""

from __future__ import annotations

import math
import threading
from typing import Sequence

import numpy as np

from cornell_harness.adapters.api import RenderResult, Setting, Stopwatch, default_threads, pass_key
from cornell_harness.scenes.model import Scene
from cornell_harness.renderers.core.adapter import ToolkitRenderer, warmed_geometry
from cornell_harness.renderers.core.bsdf import LAMBERT
from cornell_harness.renderers.core.geometry import SceneGeometry
from cornell_harness.renderers.core.photon_map import KERNELS, UNBOUNDED, PhotonMap, PrecomputedIrradiance, depth_budget
from cornell_harness.renderers.core.photons import STORE_ALL, STORE_CAUSTIC, empty_photons, shoot, subset
from cornell_harness.renderers.core.rays import head, ray_buffer
from cornell_harness.renderers.core.sampler import GATHER, Stream, gather_walk_base, independent, sampler_setting
from cornell_harness.renderers.core.schedule import render_image
from cornell_harness.renderers.core.settings import with_defaults
from cornell_harness.renderers.core.visible_points import camera_visible_points, gather_rays, walk_to_diffuse

GLOBAL_STREAM, CAUSTIC_STREAM = 1, 2
#: The global map's lookup radius relative to the caustic map's (Mitsuba 0.6: 0.05 / 0.0125).
GLOBAL_RADIUS_FACTOR = 4.0
#: Final gathering's irradiance is precomputed at one global photon in this many (Christensen 1999).
PRECOMPUTE_STRIDE = 4


class PhotonMapper(ToolkitRenderer):
    """Our photon mapper (Jensen's two passes on Embree and cKDTree, multithreaded)."""

    name = "photonmap"
    citations = (
        'Jensen 1996, "Global Illumination using Photon Maps" (EGWR)',
        'Jensen 2001, "Realistic Image Synthesis Using Photon Mapping", ch. 9',
        'Christensen 1999, "Faster Photon Map Global Illumination" (JGT)')
    estimator = "consistent"
    approximations = ("caustics and indirect light are photon density estimates: blurred over the lookup "
                      "radius (biased), consistent as photons grow",)
    settings = (
        Setting("global_photons", int, 250_000, "photons stored in the global map (Mitsuba 0.6: globalPhotons)",
                low=0, high=100_000_000),
        Setting("caustic_photons", int, 250_000, "photons stored in the caustic map (Mitsuba 0.6: causticPhotons)",
                low=0, high=100_000_000),
        Setting("k", int, 30, "photons per density estimate, nearest first (Mitsuba 0.6's lookupSize is 120: "
                "see the module docstring)", low=1, high=1000),
        Setting("max_radius", float, 0.0125, "caustic lookup radius, relative to the scene's bounding-sphere "
                "radius (Mitsuba 0.6: causticLookupRadius); the global map's is 4 times it", low=1e-6, high=1.0),
        Setting("kernel", str, "cone", "density-estimation kernel (Jensen's cone filter, Epanechnikov, uniform)",
                choices=KERNELS),
        Setting("gather_rays", int, 1, "final-gathering rays per camera sample; 0 shows the global map directly",
                low=0, high=GATHER.count),
        sampler_setting("the photons (one sequence per map), the camera paths and the gather rays (one sequence "
                        "per pixel)"),
    )

    def render(self, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = (),
               settings: dict | None = None) -> RenderResult:
        s = with_defaults(self.settings, settings)
        threads = self.threads or default_threads()
        geom, setup_s = warmed_geometry(scene, lambda g: _warm_up(g, scene))
        clock = Stopwatch()
        pass2 = build_pass2(geom, scene, seed, s, threads)
        photons_s, photons_cpu = clock.read()
        result = render_image(scene, spp, seed, pass2.shade, checkpoints, threads, sampler=s["sampler"])
        result.time_s += photons_s
        result.cpu_time_s += photons_cpu
        for c in result.checkpoints:
            c.time_s += photons_s
            c.cpu_time_s += photons_cpu
        result.info.update(s, photons_s=round(photons_s, 3), setup_s=round(setup_s, 3), rays=geom.rays,
                           global_stored=len(pass2.global_map), global_emitted=pass2.global_map.emitted,
                           caustic_stored=len(pass2.caustic_map), caustic_emitted=pass2.caustic_map.emitted)
        return result


def lookup_radius(geom: SceneGeometry, relative: float) -> float:
    """A lookup radius given relative to the scene's bounding-sphere radius (half its bounds' diagonal)."""
    return relative * 0.5 * geom.extent


class Pass2:
    """The photon maps of one render and the radiance estimate of a unit of camera paths from them."""

    def __init__(self, geom: SceneGeometry, scene: Scene, settings: dict, global_map: PhotonMap,
                 caustic_map: PhotonMap):
        self.geom, self.scene, self.s = geom, scene, settings
        self.global_map, self.caustic_map = global_map, caustic_map
        self.r_caustic = lookup_radius(geom, settings["max_radius"])
        self.r_global = GLOBAL_RADIUS_FACTOR * self.r_caustic
        ph = global_map.photons
        # Seen directly (no gathering), the global map must not repeat what NEE and the caustic map give.
        self.indirect_map = PhotonMap(subset(ph, (ph.depth >= 2) & ~ph.caustic), global_map.emitted)
        self._precomputed: dict[int, PrecomputedIrradiance] = {}
        self._lock = threading.Lock()

    def precomputed(self, budget: int) -> PrecomputedIrradiance:
        """Christensen's irradiance for photons up to ``budget`` deep, computed on first use."""
        with self._lock:
            if budget not in self._precomputed:
                self._precomputed[budget] = PrecomputedIrradiance(
                    self.global_map, PRECOMPUTE_STRIDE, self.s["k"], self.r_global, self.s["kernel"], budget)
            return self._precomputed[budget]

    def shade(self, first: int, stop: int, pixels: int, stream: Stream) -> np.ndarray:
        """Radiance estimates (m, 3) of camera paths first .. stop-1 (render_image's trace function)."""
        s, geom = self.s, self.geom
        L, vp = camera_visible_points(geom, self.scene, first, stop, pixels, stream)
        f = np.flatnonzero(vp.found)
        x, n, w, budget = vp.position[f], vp.normal[f], vp.weight[f], depth_budget(self.scene.max_depth, vp.depth[f])
        E, _ = self.caustic_map.irradiance(x, n, budget, s["k"], self.r_caustic, s["kernel"])
        L[f] += w / math.pi * E
        if s["gather_rays"] == 0:
            E, _ = self.indirect_map.irradiance(x, n, budget, s["k"], self.r_global, s["kernel"])
            L[f] += w / math.pi * E
            return L
        rays = ray_buffer(len(f))
        for g in range(s["gather_rays"]):
            r = gather_rays(vp, stream, first, g, s["gather_rays"], geom.offset, rays)
            _, hit = walk_to_diffuse(geom, self.scene, head(rays, r), stream, first, dim_base=gather_walk_base(g),
                                     emission=False, nee=False, bounded=False, paths=len(L))
            h = np.flatnonzero(hit.found)
            depth = vp.depth[h] + hit.depth[h]
            hb = depth_budget(self.scene.max_depth, depth)
            E = np.zeros((len(h), 3))
            for b in np.unique(hb):
                if b >= 1:
                    sel = hb == b
                    E[sel] = self.precomputed(int(b)).lookup(hit.position[h][sel], hit.normal[h][sel])
            L[h] += hit.weight[h] / math.pi * E
        return L


def build_pass2(geom: SceneGeometry, scene: Scene, seed: int, settings: dict, threads: int) -> Pass2:
    """Pass 1: both photon maps, and the precomputed irradiance an unbounded scene's gathering needs."""
    global_ph, global_n = empty_photons(), 0
    if settings["global_photons"]:
        global_ph, global_n = shoot(geom, scene, pass_key(seed, 0, GLOBAL_STREAM), settings["global_photons"],
                                    STORE_ALL, threads, stored=True, sampler=settings["sampler"])
    caustic_ph, caustic_n = empty_photons(), 0
    if settings["caustic_photons"] and (geom.material != LAMBERT).any():  # no mirror or glass: no caustic
        caustic_ph, caustic_n = shoot(geom, scene, pass_key(seed, 0, CAUSTIC_STREAM), settings["caustic_photons"],
                                      STORE_CAUSTIC, threads, stored=True, sampler=settings["sampler"])
    p2 = Pass2(geom, scene, settings, PhotonMap(global_ph, global_n), PhotonMap(caustic_ph, caustic_n))
    if settings["gather_rays"] and scene.max_depth < 0:
        p2.precomputed(int(UNBOUNDED))
    return p2


def _warm_up(geom: SceneGeometry, scene: Scene) -> None:
    """Compile (or load from numba's cache) every kernel before the clock starts: enough photons and paths
    (64, through the middle row of the image) that the lookups run; with 64 photons and one path they did
    not, and a process's first render compiled the nearest-site kernel inside its time."""
    settings = with_defaults(PhotonMapper.settings, {"global_photons": 1024, "caustic_photons": 0})
    p2 = build_pass2(geom, scene, 0, settings, 1)
    pixels = scene.camera.width * scene.camera.height
    middle = pixels // 2 - scene.camera.width // 2
    p2.shade(middle, min(middle + 64, pixels), pixels, independent(0))
    p2.s = dict(settings, gather_rays=0)
    p2.shade(middle, min(middle + 64, pixels), pixels, independent(0))
