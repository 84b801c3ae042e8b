"""Unidirectional path tracing with next-event estimation and MIS, on Embree.

The estimator is the standard one of Veach 1997 (thesis §9.2) as in
pbrt-v4 §13.4 (``PathIntegrator``), for the materials of
:mod:`cornell_harness.renderers.core.bsdf` (Lambert, smooth mirror, smooth glass), triangles
and spheres, and one-sided diffuse area emitters. This module is the integrator only:
cameras, rays, geometry, emitters, BSDFs, sample dimensions, threads and
the film are the shared toolkit's (``src/cornell_harness/renderers/core/``).

- **Next-event estimation** (pbrt's ``SampleLd``, the toolkit's
  :func:`cornell_harness.renderers.core.direct.light_sample`): at each surface vertex an emitter
  triangle is picked in proportion to its power and a point on it uniformly
  by area (:func:`cornell_harness.renderers.core.lights.sample_emitter`); the area pdf is
  converted to solid angle, ``p_ω = p_A · r² / cos θ_y``.
- **BSDF sampling** (:func:`cornell_harness.renderers.core.bsdf.bsdf_sample`): for a
  Lambertian BRDF ρ/π, cosine-weighted directions (pdf cos θ / π), which make
  the throughput update exactly ρ.
- **MIS**: both strategies are weighted by the power heuristic (β = 2,
  Veach eq. 9.13). Emission found by a BSDF-sampled ray is weighted against
  the NEE pdf of that point; emission seen by the camera ray is not weighted.
- **Delta BSDFs** (mirror, glass) are only sampled: no NEE at such a
  vertex (light sampling cannot hit a delta lobe), and the emission the
  sampled ray finds counts with weight 1 (the ray carries pdf 0, as camera
  rays do). Caustics (light → glass → diffuse → camera) therefore come only
  from BSDF-sampled rays that happen to reach the light: unbiased, slow, as
  expected of path tracing; the photon mapper exists for them.
- **Russian roulette** from the ``rr_depth``-th vertex on (setting, default
  :data:`RR_DEPTH`), by the toolkit's rule
  (:func:`cornell_harness.renderers.core.roulette.continue_path`): unbiased, ends every path,
  and discounts the refraction scaling that β contains.
- **AOVs** (``render(..., aovs=AOVS)``, for the denoisers of
  :mod:`cornell_harness.renderers.oidn`): each path writes the albedo and normal of its first
  non-delta hit, following mirrors and glass, as Open Image Denoise's
  documentation recommends; the film averages them like the image. They
  come from the paths already traced (no extra rays) and do not change the
  image by a bit.
- ``max_depth`` is the harness's convention (segments from the camera;
  -1 unbounded): emission at vertex k counts if k ≤ max_depth, NEE at vertex
  k adds a segment and counts if k + 1 ≤ max_depth.

Spectral rendering (the ``spectral`` setting): ``rgb`` (the default) renders
the scene's RGB values, as above; ``hero`` renders a spectral scene's spectra
(``Scene.spectral``) by hero-wavelength sampling, 4 wavelengths per path
(Wilkie et al. 2014; :mod:`cornell_harness.renderers.hero_wavelength`), with the same sampling
decisions, film, variance and determinism, on the scene model's linear-sRGB
scale (a spectral emitter seen directly is ``emission_rgb`` of its
spectrum). A scene with RGB-only reflectances or emitters is refused in
``hero`` mode, with the field named. Both modes run the same kernels
(:func:`_trace`, :func:`_shade`), written once over a channel type as
pbrt-v4's ``PathIntegrator`` is over ``SampledSpectrum``: what differs is
the path state (:class:`Paths`, or the hero module's ``HeroPaths``) and the
few channel functions of :class:`RGB` and the hero module's ``Hero``, which
numba picks by the state's type when it compiles the kernels
(:mod:`cornell_harness.renderers.core.channels` says how, and why not a
kernel factory).

Random numbers: vertex k of a path uses the named dimensions of
:mod:`cornell_harness.renderers.core.sampler` (emitter pick and point, BSDF direction,
roulette), drawn by the ``sampler`` setting's sampler (default ``pmj02``,
the best efficiency measured: docs/sampling.md); the ``variance`` setting
(:data:`cornell_harness.renderers.core.sampler.VARIANCE_SETTING`) trades the reported
variance for one randomisation's stratification, for timing runs. Robustness: maths in
float64; every pdf division is guarded (a zero pdf gives a zero
contribution, never NaN or Inf); a one-sided surface
hit from its back side reflects and emits nothing and ends the path (glass
is two-sided).
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from cornell_harness.adapters.api import AOVS, RenderResult, Setting
from cornell_harness.scenes.model import Scene
from cornell_harness.scenes.spectral_scene import SPECTRAL_INFO
from cornell_harness.renderers.core.adapter import ToolkitRenderer, warmed_geometry
from cornell_harness.renderers.core.bsdf import bsdf_sample, faces, is_delta, refraction_scale
from cornell_harness.renderers.core.camera import camera_rays, image_plane
from cornell_harness.renderers.core.channels import channel_functions
from cornell_harness.renderers.core.direct import emission_weight, light_sample, unoccluded_rgb
from cornell_harness.renderers.core.geometry import SceneGeometry, add_unoccluded_light, offset_origin, ray_hit, wavefront_hits
from cornell_harness.renderers.core.roulette import Q_MAX, RR_DEPTH, continue_path
from cornell_harness.renderers.core.rays import RayBuffer, ShadowBuffer, set_path, set_ray, set_shadow, wavefront
from cornell_harness.renderers.core.sampler import (BSDF_U, EMITTER_PICK, EMITTER_U, ROULETTE, SAMPLER_SETTING, VARIANCE_SETTING,
                                    Stream, independent, path_point, vertex_1d, vertex_2d)
from cornell_harness.renderers.core.sampling import jit
from cornell_harness.renderers.core.wavelengths import N_WAVELENGTHS
from cornell_harness.renderers.hero_wavelength import Hero, HeroPaths, SpectralTables, spectral_tables, start_paths
from cornell_harness.renderers.core.schedule import render_image
from cornell_harness.renderers.core.settings import with_defaults


class Paths(NamedTuple):
    """The state of a work unit's RGB paths, per path: radiance ``L`` (m, 3) and the AOVs (``aux``, rows while
    ``aux_open``); the throughput is the ray's (``RayBuffer.beta``)."""

    L: np.ndarray  # (m, 3) float64
    aux: np.ndarray  # (m, 6) or (0, 6): albedo, normal
    aux_open: np.ndarray  # (m,) bool: the path has not written its AOVs yet


class Bounce(NamedTuple):
    """What one bounce of :func:`_shade` writes besides the path state: NEE shadow segments and continuation
    rays, as the wavefront's buffers."""

    shadow: ShadowBuffer
    nxt: RayBuffer


@jit
def _write_aovs(aux, q, geo, p, beta, scale, n):
    """Path ``q``'s albedo (the surface's reflectance times the delta chain's tint) and normal (on the side the
    ray came from) into ``aux[q]``. The tint is β without refraction's radiance scaling, capped at 1: Russian
    roulette's 1/q on a surviving path is a Monte Carlo weight, not a colour, and OIDN wants albedo in [0, 1]."""
    for c in range(3):
        aux[q, c] = geo.reflectance[p, c] * min(beta[c] / scale, 1.0)
        aux[q, 3 + c] = n[c]


class RGB:
    """The RGB channel type (:mod:`cornell_harness.renderers.core.channels`): 3 channels, the scene's RGB
    values (``geo.reflectance``, ``geo.radiance``), path state :class:`Paths`, throughput in the ray buffer."""

    @jit
    def throughput(paths, rays, i, q):
        """β of ray ``i`` (of path ``q``)."""
        return rays.beta[i, 0], rays.beta[i, 1], rays.beta[i, 2]

    @jit
    def reflectance(paths, geo, p, q):
        """ρ of primitive ``p`` for path ``q``."""
        return geo.reflectance[p, 0], geo.reflectance[p, 1], geo.reflectance[p, 2]

    @jit
    def add_emission(paths, q, beta, geo, p, w):
        """Path ``q``'s estimate += β · Le(p) · w."""
        for c in range(3):
            paths.L[q, c] += beta[c] * geo.radiance[p, c] * w

    @jit
    def light_rgb(paths, q, mat, beta, rho, cos_x, g, geo, e):
        """The RGB that a light sample (emitter triangle ``e``, ``cos_x``, ``g``) adds to path ``q`` if
        unoccluded: :func:`cornell_harness.renderers.core.direct.unoccluded_rgb` of β·ρ."""
        return unoccluded_rgb(mat, (beta[0] * rho[0], beta[1] * rho[1], beta[2] * rho[2]), cos_x, g, geo, e)

    @jit
    def sample_bsdf(paths, mat, n, wo, cos_o, rho, eta, u1, u2):
        """:func:`cornell_harness.renderers.core.bsdf.bsdf_sample`: (ωi, cos θi, weight per channel, valid)."""
        return bsdf_sample(mat, n, wo, cos_o, rho, eta, u1, u2)

    @jit
    def next_throughput(paths, mat, valid, cos_w, f, beta, scale, u_rr, roulette):
        """:func:`cornell_harness.renderers.core.roulette.continue_path`: (alive, β', pdf)."""
        return continue_path(mat, valid, cos_w, f, beta, scale, u_rr, roulette)

    @jit
    def set_throughput(paths, nxt, k, q, beta, pdf, scale):
        """Ray ``k`` of ``nxt`` continues path ``q`` with throughput ``beta``."""
        set_path(nxt, k, q, beta, pdf, scale)


#: The channel functions :func:`_shade` calls, each :class:`RGB`'s or :class:`cornell_harness.renderers.hero_wavelength.Hero`'s
#: by the type of the path state it is given.
throughput, reflectance, add_emission, light_rgb, sample_bsdf, next_throughput, set_throughput = channel_functions(
    {Paths: RGB, HeroPaths: Hero},
    ("throughput", "reflectance", "add_emission", "light_rgb", "sample_bsdf", "next_throughput", "set_throughput"))


# The kernel is the algorithm of one bounce (emission, NEE, continuation) and
# reads/writes the buffers itself: helpers that take arrays and branch cost
# reference counting and inlining (src/cornell_harness/renderers/core/rays.py), so they stay here; the channel
# functions it calls are inlined into it.
@jit
def _shade(hits, rays, stream, first, depth, extend, roulette, geo, paths, out):
    """Shade one bounce of a wavefront: ray i of ``rays`` hit primitive ``hits.prim[i]`` (-1: missed).

    Adds the emission each ray found into ``paths.L``; then, if ``extend``
    (max_depth allows another segment), writes one NEE shadow segment
    (``light_sample``, MIS-weighted) into ``out.shadow`` and one
    continuation ray into ``out.nxt`` per path, with Russian roulette if
    ``roulette``. Ray paths are indices local to the unit; random numbers
    are drawn from ``stream`` for path ``first + path``, its index in the
    pass. Returns (shadow segments, next rays). When ``paths.aux`` has rows,
    a path whose ``aux_open`` is set and that reaches a non-delta surface
    writes its albedo and normal there (:data:`cornell_harness.adapters.api.AOVS`)
    and closes. Written once over the channel type of ``paths``
    (:class:`RGB` or :class:`cornell_harness.renderers.hero_wavelength.Hero`).
    """
    ns = 0
    nn = 0
    for i in range(hits.prim.size):
        p = hits.prim[i]
        if p < 0:
            continue
        d, x, n, cos_o, t, mat = ray_hit(geo, rays, i, p, hits.t_sphere)
        if not faces(mat, cos_o):
            continue  # back side (or grazing): one-sided emitters and BSDFs give nothing, the path ends
        q = rays.path[i]
        beta = throughput(paths, rays, i, q)
        if paths.aux.shape[0] > 0 and paths.aux_open[q] and not is_delta(mat):
            _write_aovs(paths.aux, q, geo, p, beta, rays.scale[i], n)
            paths.aux_open[q] = False
        pa = geo.light_pdf_area[p]
        if pa > 0.0 and cos_o > 0.0:
            w = emission_weight(rays.pdf[i], pa, t, cos_o)
            add_emission(paths, q, beta, geo, p, w)
        if not extend:
            continue
        pt = path_point(stream, first + q)
        rho = reflectance(paths, geo, p, q)
        if geo.emitter_ids.size > 0 and not is_delta(mat):
            u = vertex_2d(stream, pt, depth, EMITTER_U)
            found, a, sd, tfar, e, cos_x, g = light_sample(x, n, mat, (vertex_1d(stream, pt, depth, EMITTER_PICK),
                                                                        u[0], u[1]), geo, True)
            if found:
                set_shadow(out.shadow, ns, a, sd, tfar, q, light_rgb(paths, q, mat, beta, rho, cos_x, g, geo, e))
                ns += 1
        u = vertex_2d(stream, pt, depth, BSDF_U)
        wi, cos_w, f, valid = sample_bsdf(paths, mat, n, (-d[0], -d[1], -d[2]), cos_o, rho, geo.eta[p], u[0], u[1])
        scale = rays.scale[i] * refraction_scale(mat, cos_o, cos_w, geo.eta[p])
        alive, b, pdf = next_throughput(paths, mat, valid, cos_w, f, beta, scale,
                                        vertex_1d(stream, pt, depth, ROULETTE) if roulette else 1.0, roulette)
        if alive:
            side = n if cos_w > 0.0 else (-n[0], -n[1], -n[2])  # the new ray leaves on the side it travels to
            set_ray(out.nxt, nn, offset_origin(x, side, geo.offset), wi)
            set_throughput(paths, out.nxt, nn, q, b, pdf, scale)
            nn += 1
    return ns, nn


def trace_paths(geom: SceneGeometry, scene: Scene, first: int, stop: int, pixels: int, stream: Stream,
                rr_depth: int = RR_DEPTH, aovs: bool = False, spectra: SpectralTables | None = None):
    """Radiance estimates (m, 3) for paths ``first .. stop-1`` (path j sees pixel j mod ``pixels``);
    with ``aovs``, (estimates, aux): aux (m, 6) holds each path's albedo and normal (:func:`_write_aovs`).
    With ``spectra`` (a hero render: :func:`cornell_harness.renderers.hero_wavelength.spectral_tables`), the
    paths carry 4 wavelengths each (:func:`cornell_harness.renderers.hero_wavelength.start_paths`); no AOVs."""
    m = stop - first
    cam = scene.camera
    if spectra is None:
        aux = np.zeros((m if aovs else 0, 6))
        paths = Paths(np.zeros((m, 3)), aux, np.ones(aux.shape[0], dtype=np.bool_))
    else:
        paths = start_paths(spectra, stream, first, m)
    traced = _trace(geom.tables(), image_plane(cam), first, pixels, stream, (scene.max_depth, rr_depth),
                    wavefront(m, geom.has_spheres), paths)
    L, aux = paths.L, paths.aux
    geom.count(traced)
    return (L, aux) if aovs else L


@jit
def _trace(geo, plane, first, pixels, stream, depths, wf, paths):
    """The bounce loop of :func:`trace_paths`, one kernel per work unit: camera rays, then per bounce the
    closest hits, :func:`_shade`, and the shadow segments' queries, until no path is left. Returns the rays
    traced. One kernel because a kernel called from Python per bounce cost ~0.3 ms of argument typing
    (:func:`cornell_harness.renderers.core.geometry.trace_closest`). ``depths``: (max_depth, rr_depth). The camera
    rays (neighbouring pixels one after another) are asked of Embree as coherent rays, the bounces' not: the
    flag is 2.5x faster on the first and ~1.4x slower on the others (BENCHMARKS.md, the Embree floor)."""
    max_depth, rr_depth = depths
    cur, nxt = wf.cur, wf.nxt  # double buffer: shade reads one wavefront, writes the next
    camera_rays(plane.basis, plane.width, plane.height, first, pixels, stream, cur)
    n, depth, traced = paths.L.shape[0], 1, 0  # live rays; segments so far, the current ray included
    while n:
        hits = wavefront_hits(geo, wf, cur, n, depth == 1)
        extend = max_depth < 0 or depth + 1 <= max_depth
        ns, n_next = _shade(hits, cur, stream, first, depth, extend, depth >= rr_depth, geo, paths,
                            Bounce(wf.shadow, nxt))
        traced += n + ns
        add_unoccluded_light(geo, paths.L, wf.shadow, wf.visible[:ns], wf.record)
        cur, nxt = nxt, cur
        n = n_next
        depth += 1
    return traced


#: The ``spectral`` setting's values: the scene's RGB values, or its spectra by hero-wavelength sampling.
SPECTRAL_MODES = ("rgb", "hero")


class PathTracer(ToolkitRenderer):
    """Our path tracer (Embree, vectorised wavefront, multithreaded)."""

    name = "pathtracer"
    citations = (
        'Veach 1997, "Robust Monte Carlo Methods for Light Transport Simulation" (PhD thesis), §9.2',
        'Pharr, Jakob and Humphreys 2023, "Physically Based Rendering", 4th ed. (pbrt-v4), §13.4',
        'Wilkie et al. 2014, "Hero Wavelength Spectral Sampling" (EGSR)')
    aovs = AOVS
    stops_early = True
    settings = (Setting("rr_depth", int, RR_DEPTH, "path vertex from which Russian roulette may end a path",
                        low=1, high=1000), SAMPLER_SETTING, VARIANCE_SETTING,
                Setting("spectral", str, "rgb", "rgb: render the scene's RGB values; hero: render a spectral scene's "
                        "spectra by hero-wavelength sampling, 4 wavelengths per path (Wilkie et al. 2014), to the "
                        "same linear sRGB (refuses RGB-only materials and emitters)", choices=SPECTRAL_MODES))

    def render(self, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = (),
               settings: dict | None = None, aovs: Sequence[str] = (), stop=None) -> RenderResult:
        s = with_defaults(self.settings, settings)
        rr_depth, sampler = s["rr_depth"], s["sampler"]
        if unknown := set(aovs) - set(AOVS):
            raise ValueError(f"unknown AOVs {sorted(unknown)}; this renderer gives {', '.join(AOVS)}")
        info = {"rr_depth": rr_depth, "rr_q_max": Q_MAX}
        if s["spectral"] == "hero":
            if aovs:
                raise ValueError("AOVs come from spectral=rgb; spectral=hero renders the image only")
            geom, setup_s, trace = _hero_paths(scene, rr_depth)
            info.update({SPECTRAL_INFO: "hero", "wavelengths_per_path": N_WAVELENGTHS})
        else:
            aovs = AOVS if aovs else ()  # both come from one pass
            geom, setup_s = warmed_geometry(scene, lambda g: trace_paths(g, scene, 0, 1, 1, independent(0), rr_depth))

            def trace(*unit):
                return trace_paths(geom, scene, *unit, rr_depth, bool(aovs))
        result = render_image(scene, spp, seed, trace, checkpoints, self.threads, info, sampler, aovs,
                              variance=s["variance"] == "batches", stop=stop)
        result.info.update(rays=geom.rays, setup_s=round(setup_s, 3))
        return result


def _hero_paths(scene: Scene, rr_depth: int):
    """``spectral = "hero"``: the warmed geometry, its set-up seconds, and the trace function (:func:`trace_paths`
    with the scene's spectra) for :func:`cornell_harness.renderers.core.schedule.render_image`."""
    tables = []

    def warm_up(g: SceneGeometry):
        tables.append(spectral_tables(scene, g))  # refuses an RGB-only field before the kernels compile
        return trace_paths(g, scene, 0, 1, 1, independent(0), rr_depth, spectra=tables[0])

    geom, setup_s = warmed_geometry(scene, warm_up)
    return geom, setup_s, lambda *unit: trace_paths(geom, scene, *unit, rr_depth, spectra=tables[0])
