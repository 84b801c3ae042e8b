"""Hero-wavelength spectral path tracing: the path tracer's ``spectral = "hero"`` mode.

Wilkie, Nawaz, Droske, Weidlich and Hanika 2014, "Hero Wavelength Spectral
Sampling" (EGSR), as pbrt-v4 does it (§4.6.5 ``SampledWavelengths``, §13.4
``PathIntegrator`` on ``SampledSpectrum``): each camera path carries 4
wavelengths, the hero λ_0 and three rotations of it
(:func:`cornell_harness.renderers.core.wavelengths.hero_wavelengths`, pbrt-v4's visible-wavelength
pdf), and a throughput per wavelength. Every sampling decision of the path
(pixel jitter, NEE, BSDF direction, Russian roulette on the largest of the
four throughputs) is the RGB path tracer's (:mod:`cornell_harness.renderers.pathtracer`, same
named dimensions, same toolkit), because none of our materials makes a
direction depend on wavelength: a constant-index dielectric refracts every
wavelength alike, so no secondary wavelength is ever terminated (Wilkie §4's
dispersion case does not arise), and the hero's balance-heuristic weights
over the 4 wavelengths are 1/4 each: the estimate is the mean of the four
single-wavelength estimates. Each wavelength's radiance enters the pixel's
linear sRGB at once, through the observer's matching functions divided by
that wavelength's pdf (:func:`cornell_harness.renderers.core.wavelengths.sensor_rgb`), so the
film, its variance, the batches of the low-discrepancy samplers, and the
determinism (a pure function of the seed, whatever the thread count) are the
RGB path tracer's. The scale is the scene model's: a spectral emitter seen
directly converges to :func:`cornell_harness.scenes.spectra.emission_rgb` of its
spectrum (:mod:`cornell_harness.renderers.core.wavelengths` says why exactly).

What a hero render reads (:func:`spectral_tables`): each diffuse or mirror
material's reflectance spectrum and each emitter's emission spectrum, as the
scene binds them (``Scene.spectral``: :mod:`cornell_harness.scenes.spectral_scene`);
glass is 1 at every wavelength. A field that is RGB only is refused with a
one-line reason (upsampling RGB to a spectrum would be an arbitrary choice
that a spectral reference does not make), except a black reflectance (0, 0,
0), which is 0 at every wavelength in any model. AOVs come from the RGB mode.

The wavelength's number is the sampler's dimension
:data:`cornell_harness.renderers.core.sampler.WAVELENGTH`, outside every vertex's, so the
hero render of a scene uses the RGB render's numbers for everything else.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from cornell_harness.scenes.materials import Dielectric
from cornell_harness.scenes.model import Scene
from cornell_harness.renderers.core.bsdf import bsdf_eval, bsdf_sample, faces, is_delta, refraction_scale
from cornell_harness.renderers.core.camera import camera_rays, image_plane
from cornell_harness.renderers.core.direct import emission_weight, light_sample
from cornell_harness.renderers.core.geometry import SceneGeometry, add_unoccluded_light, offset_origin, ray_hit, wavefront_hits
from cornell_harness.renderers.core.rays import RayBuffer, ShadowBuffer, set_path, set_ray, set_shadow, wavefront
from cornell_harness.renderers.core.roulette import RR_DEPTH, continue_spectral_path
from cornell_harness.renderers.core.sampler import (BSDF_U, EMITTER_PICK, EMITTER_U, ROULETTE, WAVELENGTH, Stream, path_point,
                                    sample_1d, vertex_1d, vertex_2d)
from cornell_harness.renderers.core.sampling import jit
from cornell_harness.renderers.core.wavelengths import N_WAVELENGTHS, hero_wavelengths, on_grid, sensor_rgb


class SpectralTables(NamedTuple):
    """What the kernels read about a scene's spectra, besides the geometry's tables (one numba argument)."""

    cmf_rgb: np.ndarray  # (N_BINS, 3) cornell_harness.renderers.core.wavelengths.sensor_rgb
    rho: np.ndarray  # (K, N_BINS) reflectance spectra on the table's nodes
    rho_row: np.ndarray  # (N,) int64 per primitive: its row of rho
    le: np.ndarray  # (K', N_BINS) emission spectra on the nodes
    le_row: np.ndarray  # (N,) int64 per primitive: its row of le, -1 for a non-emitter


class HeroPaths(NamedTuple):
    """A work unit's per-path state: linear-sRGB radiance, and per wavelength the table nodes, sensor weights and
    throughput (as :class:`HeroBounce` names them)."""

    L: np.ndarray
    lam: np.ndarray
    sensor: np.ndarray
    beta: np.ndarray


class HeroBounce(NamedTuple):
    """What one bounce of :func:`_shade` writes. Per path of the unit (indexed by the path, not the ray: a path
    has one live ray) its wavelengths' table nodes, their linear-sRGB weights cmf_rgb / (4 p), and its
    throughput per wavelength, updated in place; per ray, NEE segments and continuation rays."""

    L: np.ndarray  # (m, 3) float64 linear sRGB
    shadow: ShadowBuffer
    nxt: RayBuffer  # its beta column is unused: the throughput is ``beta`` here
    lam: np.ndarray  # (m, 4) int64 table nodes
    sensor: np.ndarray  # (m, 4, 3) float64
    beta: np.ndarray  # (m, 4) float64


def _refuse(scene: Scene, what: str) -> ValueError:
    return ValueError(f"scene {scene.name!r}: {what} is RGB only; spectral=hero renders spectra only "
                      "(bind it to a [spectra] table) or use spectral=rgb")


def spectral_tables(scene: Scene, geom: SceneGeometry) -> SpectralTables:
    """The scene's spectra resampled for the kernels, per primitive (module docstring: what is refused)."""
    spectral = scene.spectral
    if spectral is None:
        raise ValueError(f"scene {scene.name!r} has no spectra (no [colour] table); spectral=hero needs a "
                         "spectral scene, spectral=rgb renders it")
    rows_rho: dict = {}
    rows_le: dict = {}
    rho_of, le_of = [], []
    for obj in scene.meshes + scene.spheres:
        mat = scene.materials[obj.material]
        if isinstance(mat, Dielectric):
            key = "one"
        else:
            key = spectral.reflectance(obj.material, "reflectance")
            if key is None:
                if any(mat.reflectance):
                    raise _refuse(scene, f"material {obj.material!r}'s reflectance")
                key = "zero"
        rho_of.append(rows_rho.setdefault(key, len(rows_rho)))
        radiance = getattr(obj, "radiance", None)
        if radiance is None or not any(radiance):
            le_of.append(-1)
            continue
        s = spectral.emission(obj.name)
        if s is None:
            raise _refuse(scene, f"mesh {obj.name!r}'s emission")
        le_of.append(rows_le.setdefault(s, len(rows_le)))
    const = {"one": 1.0, "zero": 0.0}
    rho = np.array([np.full(sensor_rgb().shape[0], const[k]) if isinstance(k, str) else on_grid(k)
                    for k in rows_rho]).reshape(len(rows_rho), -1)
    le = np.array([on_grid(s) for s in rows_le]).reshape(len(rows_le), -1) if rows_le else np.zeros((1, rho.shape[1]))
    return SpectralTables(sensor_rgb(), rho, np.asarray(rho_of, np.int64)[geom.object],
                          le, np.asarray(le_of, np.int64)[geom.object])


@jit
def _start_paths(stream, first, spec, lam, sensor, beta):
    """Each path's wavelengths (its number at dimension WAVELENGTH), their sRGB weights, and throughput 1."""
    for q in range(lam.shape[0]):
        nodes, pdf = hero_wavelengths(sample_1d(stream, path_point(stream, first + q), WAVELENGTH))
        for j in range(N_WAVELENGTHS):
            lam[q, j] = nodes[j]
            beta[q, j] = 1.0
            p = pdf[j]
            inv = 1.0 / (N_WAVELENGTHS * p) if p > 0.0 else 0.0
            for c in range(3):
                sensor[q, j, c] = spec.cmf_rgb[nodes[j], c] * inv


# The kernel is the algorithm of one bounce, as src/cornell_harness/renderers/pathtracer.py's _shade; see src/cornell_harness/renderers/core/rays.py
# for why the buffer writes stay in it.
@jit
def _shade(hits, rays, stream, first, depth, extend, roulette, geo, spec, out):
    """One bounce of a wavefront, per wavelength (cornell_harness.renderers.pathtracer._shade's algorithm): emission found,
    then, if ``extend``, one NEE segment and one continuation ray per path. Returns (segments, rays)."""
    ns = 0
    nn = 0
    for i in range(hits.prim.size):
        p = hits.prim[i]
        if p < 0:
            continue
        d, x, n, cos_o, t, mat = ray_hit(geo, rays, i, p, hits.t_sphere)
        if not faces(mat, cos_o):
            continue  # back side (or grazing): nothing reflected or emitted, the path ends
        q = rays.path[i]
        b = (out.beta[q, 0], out.beta[q, 1], out.beta[q, 2], out.beta[q, 3])
        lam = (out.lam[q, 0], out.lam[q, 1], out.lam[q, 2], out.lam[q, 3])
        pa = geo.light_pdf_area[p]
        if pa > 0.0 and cos_o > 0.0:
            w = emission_weight(rays.pdf[i], pa, t, cos_o)
            r = spec.le_row[p]
            for j in range(N_WAVELENGTHS):
                s = b[j] * spec.le[r, lam[j]] * w
                for c in range(3):
                    out.L[q, c] += s * out.sensor[q, j, c]
        if not extend:
            continue
        pt = path_point(stream, first + q)
        k = spec.rho_row[p]
        rho = (spec.rho[k, lam[0]], spec.rho[k, lam[1]], spec.rho[k, lam[2]], spec.rho[k, lam[3]])
        if geo.emitter_ids.size > 0 and not is_delta(mat):
            u = vertex_2d(stream, pt, depth, EMITTER_U)
            found, a, sd, tfar, e, cos_x, g = light_sample(x, n, mat, (vertex_1d(stream, pt, depth, EMITTER_PICK),
                                                                        u[0], u[1]), geo, True)
            if found:
                r = spec.le_row[e]
                c0 = c1 = c2 = 0.0
                for j in range(N_WAVELENGTHS):
                    s = bsdf_eval(mat, b[j] * rho[j], cos_x) * spec.le[r, lam[j]] * g
                    c0 += s * out.sensor[q, j, 0]
                    c1 += s * out.sensor[q, j, 1]
                    c2 += s * out.sensor[q, j, 2]
                set_shadow(out.shadow, ns, a, sd, tfar, q, (c0, c1, c2))
                ns += 1
        u = vertex_2d(stream, pt, depth, BSDF_U)
        # The direction and its weight at unit reflectance: for our materials f·cos/pdf is ρ(λ) times that.
        wi, cos_w, f, valid = bsdf_sample(mat, n, (-d[0], -d[1], -d[2]), cos_o, (1.0, 1.0, 1.0), geo.eta[p],
                                          u[0], u[1])
        scale = rays.scale[i] * refraction_scale(mat, cos_o, cos_w, geo.eta[p])
        alive, bn, pdf = continue_spectral_path(
            mat, valid, cos_w, (f[0] * rho[0], f[0] * rho[1], f[0] * rho[2], f[0] * rho[3]), b, scale,
            vertex_1d(stream, pt, depth, ROULETTE) if roulette else 1.0, roulette)
        if alive:
            side = n if cos_w > 0.0 else (-n[0], -n[1], -n[2])
            set_ray(out.nxt, nn, offset_origin(x, side, geo.offset), wi)
            set_path(out.nxt, nn, q, (1.0, 1.0, 1.0), pdf, scale)
            out.beta[q, 0], out.beta[q, 1], out.beta[q, 2], out.beta[q, 3] = bn
            nn += 1
    return ns, nn


def trace_hero_paths(geom: SceneGeometry, spec: SpectralTables, scene: Scene, first: int, stop: int, pixels: int,
                     stream: Stream, rr_depth: int = RR_DEPTH) -> np.ndarray:
    """Linear-sRGB estimates (m, 3) of paths ``first .. stop-1`` (path j sees pixel j mod ``pixels``), as
    :func:`cornell_harness.renderers.pathtracer.trace_paths` but per wavelength (module docstring)."""
    m = stop - first
    cam = scene.camera
    L = np.zeros((m, 3))
    lam, sensor, beta = np.empty((m, N_WAVELENGTHS), np.int64), np.empty((m, N_WAVELENGTHS, 3)), \
        np.empty((m, N_WAVELENGTHS))
    _start_paths(stream, first, spec, lam, sensor, beta)
    geom.count(_trace(geom.tables(), spec, image_plane(cam), first, pixels, stream, (scene.max_depth, rr_depth),
                      wavefront(m, geom.has_spheres), HeroPaths(L, lam, sensor, beta)))
    return L


@jit
def _trace(geo, spec, plane, first, pixels, stream, depths, wf, paths):
    """The bounce loop of :func:`trace_hero_paths` as one kernel, as :func:`cornell_harness.renderers.pathtracer._trace` (why
    there); returns the rays traced."""
    max_depth, rr_depth = depths
    L, lam, sensor, beta = paths
    cur, nxt = wf.cur, wf.nxt
    camera_rays(plane.basis, plane.width, plane.height, first, pixels, stream, cur)
    n, depth, traced = L.shape[0], 1, 0
    while n:
        hits = wavefront_hits(geo, wf, cur, n)
        extend = max_depth < 0 or depth + 1 <= max_depth
        ns, n_next = _shade(hits, cur, stream, first, depth, extend, depth >= rr_depth, geo, spec,
                            HeroBounce(L, wf.shadow, nxt, lam, sensor, beta))
        traced += n + ns
        add_unoccluded_light(geo, L, wf.shadow, wf.visible[:ns], wf.record)
        cur, nxt = nxt, cur
        n = n_next
        depth += 1
    return traced
