"""Photon tracing: photons shot from the emitters, followed through the scene, stored where they land.

The first pass of photon mapping (Jensen 2001, "Realistic Image Synthesis
Using Photon Mapping", ch. 5) and the photon pass of each SPPM iteration
(Hachisuka & Jensen 2009; pbrt-v4 §16.2.2):

- **Emission**: an emitter triangle is picked by power and a point on it
  uniformly by area (next-event estimation's sampling,
  :func:`cornell_harness.renderers.core.lights.sample_emitter`, area pdf p_A), a direction
  cosine-weighted about its normal (pdf cos θ/π). The photon's flux is
  Le·cos θ / (p_A · cos θ/π) = π·Le / p_A; :func:`shoot` divides it by the
  number of photons emitted, since a density estimate sums over them.
- **Scattering**: at a diffuse surface the photon is stored (below), then
  Russian roulette on the albedo decides absorption: it goes on with
  probability q = max_c ρ_c (capped at :data:`cornell_harness.renderers.core.roulette.Q_MAX`)
  and its flux is multiplied by ρ/q, in a cosine-weighted direction (Jensen
  §5.2). At a mirror or glass the BSDF is sampled (Fresnel picks reflection
  or refraction) with the same roulette on the sample's weight. Flux, unlike
  radiance, is not scaled by (η_i/η_t)² when it refracts (Veach 1997 §5.2:
  light and importance see the adjoint BSDFs of refraction), so a photon's
  weight is the radiance weight divided by
  :func:`cornell_harness.renderers.core.bsdf.refraction_scale`.
- **Storing** (``mode``): every diffuse hit (:data:`STORE_ALL`, Jensen's
  global map); only photons that came from the light through one or more
  specular bounces and nothing else (L S+ D, :data:`STORE_CAUSTIC`, Jensen's
  caustic map; the path ends there); every diffuse hit but the first
  (:data:`STORE_INDIRECT`: SPPM, whose direct light is next-event estimated
  at the visible points, pbrt-v4 §16.2). In every mode only on surfaces
  that reflect (diffuse reflectance ρ > 0 in some channel): a photon on a
  black surface can only be used by a visible point on that surface, whose
  estimate ρ/π·E is 0, or through the normal test by a coplanar neighbour's
  disc that reaches over the seam; so a map's stored count
  (``global_photons``, ``caustic_photons``) counts photons that can
  contribute (83% of a map once lay on the black top of a light). The
  seam loses the photons beyond it, as a disc at a corner does (the
  estimate's border bias, docs/photon-mapping.md). The normalisation does
  not change: each photon's flux is the emitted power over the photons
  *emitted* (:func:`shoot`), whatever is stored.
- ``max_depth`` (segments from the camera to the light): a photon stored
  after k segments from the light is only useful with at least one camera
  segment, so photons are traced while k + 1 ≤ max_depth; the estimates
  check the camera side (:class:`Photons.depth`).

Photons are stored compactly (:class:`Photons`): float32 position, flux,
incoming direction and normal, int16 depth, a caustic flag.

Determinism: photon j of a map draws its numbers from the map's sampler
stream (:func:`cornell_harness.renderers.core.sampler.sequence_stream`: with ``independent``
the counter-based numbers of (key, j, dimension), with ``pmj02`` or ``sobol``
sample j of one sequence over the map's photons) in the sampler's photon layout
(:data:`cornell_harness.renderers.core.sampler.PHOTON_EMISSION`, ``PHOTON_BOUNCES``),
so the photons do not depend on how batches are spread over threads, and
batches are joined in order (:func:`shoot`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from cornell_harness.scenes.model import Scene
from cornell_harness.renderers.core.bsdf import bsdf_sample, faces, is_delta, refraction_scale
from cornell_harness.renderers.core.geometry import SceneGeometry, offset_origin, ray_hit, wavefront_hits
from cornell_harness.renderers.core.lights import sample_emitter
from cornell_harness.renderers.core.rays import RayBuffer, set_path, set_ray, wavefront
from cornell_harness.renderers.core.roulette import Q_MAX
from cornell_harness.renderers.core.sampler import (BOUNCE_ROULETTE, BOUNCE_U, EMIT_DIR_U, EMIT_PICK, EMIT_U, Stream,
                                                    bounce_dim, path_point, sample_1d, sample_2d, sequence_stream)
from cornell_harness.renderers.core.sampling import cosine_hemisphere, jit
from cornell_harness.renderers.core.schedule import run_units

#: What a photon pass stores (see the module docstring).
STORE_ALL, STORE_CAUSTIC, STORE_INDIRECT = 0, 1, 2

#: Photons per batch (a work unit): fixed, so which photons a map holds never depends on the thread count.
BATCH = 1 << 14
#: :func:`shoot` with a stored target gives up after emitting this many times the target: a scene
#: whose caustic paths are rare would otherwise shoot for minutes (cornell-box-caustics needs 12).
MAX_EMITTED_PER_STORED = 100


class Photons(NamedTuple):
    """Stored photons, one row each."""

    position: np.ndarray  # (n, 3) float32
    power: np.ndarray  # (n, 3) float32 flux (watts per channel), divided by the photons emitted
    direction: np.ndarray  # (n, 3) float32 unit, towards where the photon came from
    normal: np.ndarray  # (n, 3) float32 unit front-side normal of the surface it landed on
    depth: np.ndarray  # (n,) int16 segments from the light to here (1: direct)
    caustic: np.ndarray  # (n,) bool: came through specular bounces only (L S+ D)

    def __len__(self) -> int:
        return len(self.depth)


class Scattered(NamedTuple):
    """What one bounce of :func:`_scatter` writes: the photons it stores, the photons going on (rays) and
    whether each has met specular surfaces only so far."""

    photons: Photons
    rays: RayBuffer
    spec: np.ndarray  # (m,) bool
    row: int  # the row of ``photons`` this bounce stores from (the bounces before filled those above)


def empty_photons(n: int = 0) -> Photons:
    return Photons(np.zeros((n, 3), np.float32), np.zeros((n, 3), np.float32), np.zeros((n, 3), np.float32),
                   np.zeros((n, 3), np.float32), np.zeros(n, np.int16), np.zeros(n, bool))


def subset(photons: Photons, keep: np.ndarray) -> Photons:
    """The photons where ``keep`` (a mask or indices) says, in order."""
    return Photons(*(a[keep] for a in photons))


def join(parts: list[Photons]) -> Photons:
    """The photons of ``parts``, in order."""
    if not parts:
        return empty_photons()
    return Photons(*(np.concatenate(cols) for cols in zip(*parts)))


@jit
def _emit(stream, first, geo, rays, spec):
    """Photons first .. first + len(rays) - 1 of ``stream`` leave the emitters: rays with their flux π·Le/p_A."""
    for i in range(rays.path.size):
        pt = path_point(stream, first + i)
        u = sample_2d(stream, pt, EMIT_U)
        y, ny, e, pe = sample_emitter(sample_1d(stream, pt, EMIT_PICK), u[0], u[1], geo)
        w = sample_2d(stream, pt, EMIT_DIR_U)
        dx, dy, dz, cos = cosine_hemisphere(ny[0], ny[1], ny[2], w[0], w[1])
        k = math.pi / pe if pe > 0.0 and cos > 0.0 else 0.0  # zero-pdf samples carry nothing
        set_ray(rays, i, offset_origin(y, ny, geo.offset), (dx, dy, dz))
        set_path(rays, i, i, (geo.radiance[e, 0] * k, geo.radiance[e, 1] * k, geo.radiance[e, 2] * k), 0.0)
        spec[i] = True  # no bounce yet: "specular only" so far


@jit
def _store(out, k, x, power, d, n, depth, caustic):
    """Photon ``k`` of ``out``: at ``x`` with ``power``, arrived along ``d``, on a surface of normal ``n``."""
    out.position[k, 0], out.position[k, 1], out.position[k, 2] = x
    out.power[k, 0], out.power[k, 1], out.power[k, 2] = power
    out.direction[k, 0], out.direction[k, 1], out.direction[k, 2] = -d[0], -d[1], -d[2]
    out.normal[k, 0], out.normal[k, 1], out.normal[k, 2] = n
    out.depth[k] = depth
    out.caustic[k] = caustic


@jit
def _photon_buffer(size):
    """Room for ``size`` photons (:class:`Photons`), inside a kernel."""
    return Photons(np.empty((size, 3), np.float32), np.empty((size, 3), np.float32), np.empty((size, 3), np.float32),
                   np.empty((size, 3), np.float32), np.empty(size, np.int16), np.empty(size, np.bool_))


@jit
def _grown(photons, n, size):
    """The first ``n`` photons of ``photons`` in a buffer of ``size`` rows."""
    out = _photon_buffer(size)
    out.position[:n] = photons.position[:n]
    out.power[:n] = photons.power[:n]
    out.direction[:n] = photons.direction[:n]
    out.normal[:n] = photons.normal[:n]
    out.depth[:n] = photons.depth[:n]
    out.caustic[:n] = photons.caustic[:n]
    return out


@jit
def _scatter(hits, rays, spec, stream, first, depth, mode, extend, geo, out):
    """One bounce of a photon wavefront (photon ``first`` + path of ``stream``): store where the mode says,
    then scatter or absorb.

    Stores photons into ``out.photons`` from row ``out.row`` on.
    Returns (rows of ``out.photons`` now filled, photons going on into ``out.rays``).
    """
    ns, nn = out.row, 0
    for i in range(hits.prim.size):
        p = hits.prim[i]
        if p < 0:
            continue
        d, x, n, cos_o, t, mat = ray_hit(geo, rays, i, p, hits.t_sphere)
        if not faces(mat, cos_o):
            continue  # a one-sided surface's back: absorbed
        power = (rays.beta[i, 0], rays.beta[i, 1], rays.beta[i, 2])
        rho = (geo.reflectance[p, 0], geo.reflectance[p, 1], geo.reflectance[p, 2])
        diffuse = not is_delta(mat)
        if diffuse:
            caustic = spec[i] and depth >= 2
            reflects = rho[0] > 0.0 or rho[1] > 0.0 or rho[2] > 0.0  # ρ = 0: no estimate here can use it
            if reflects and (mode == STORE_ALL or (mode == STORE_CAUSTIC and caustic)
                             or (mode == STORE_INDIRECT and depth >= 2)):
                _store(out.photons, ns, x, power, d, n, depth, caustic)
                ns += 1
            if mode == STORE_CAUSTIC:
                continue  # past a diffuse bounce no photon is a caustic one
        if not extend:
            continue
        pt = path_point(stream, first + rays.path[i])
        u = sample_2d(stream, pt, bounce_dim(depth, BOUNCE_U))
        wi, cos_w, f, valid = bsdf_sample(mat, n, (-d[0], -d[1], -d[2]), cos_o, rho, geo.eta[p], u[0], u[1])
        if not valid:
            continue
        s = refraction_scale(mat, cos_o, cos_w, geo.eta[p])  # flux has no (η_i/η_t)² (module docstring)
        w = (f[0] / s, f[1] / s, f[2] / s)
        q = min(max(w[0], w[1], w[2]), Q_MAX)
        if not (q > 0.0 and sample_1d(stream, pt, bounce_dim(depth, BOUNCE_ROULETTE)) < q):
            continue
        side = n if cos_w > 0.0 else (-n[0], -n[1], -n[2])
        set_ray(out.rays, nn, offset_origin(x, side, geo.offset), wi)
        set_path(out.rays, nn, rays.path[i], (power[0] * w[0] / q, power[1] * w[1] / q, power[2] * w[2] / q), 0.0)
        out.spec[nn] = spec[i] and not diffuse
        nn += 1
    return ns, nn


def trace_photons(geom: SceneGeometry, scene: Scene, stream: Stream, first: int, stop: int, mode: int) -> Photons:
    """The photons ``first .. stop-1`` of ``stream`` (:func:`cornell_harness.renderers.core.sampler.sequence_stream`: one
    sequence over a map's photons), traced and stored by ``mode`` (not normalised)."""
    m = stop - first
    if m <= 0 or not geom.has_emitters or not (scene.max_depth < 0 or scene.max_depth >= 2):
        return empty_photons()
    photons, n, traced = _trace(geom.tables(), stream, first, scene.max_depth, mode, wavefront(m, geom.has_spheres),
                                np.empty(m, np.bool_), np.empty(m, np.bool_), _photon_buffer(2 * m))
    geom.count(traced)
    return Photons(*(a[:n] for a in photons))


@jit
def _trace(geo, stream, first, max_depth, mode, wf, spec, spec_nxt, photons):
    """The bounce loop of :func:`trace_photons` as one kernel, as :func:`cornell_harness.renderers.pathtracer._trace` (why
    there): emission, then per bounce the closest hits and :func:`_scatter`, each bounce's stored photons
    written after the last one's into ``photons`` (grown when a bounce could overflow it), so they come out
    in bounce order. Returns (the buffer, photons stored, rays traced)."""
    cur, nxt = wf.cur, wf.nxt  # double buffers: a bounce reads one wavefront and its flags, writes the next
    _emit(stream, first, geo, cur, spec)
    n, depth, ns, traced = spec.size, 1, 0, 0  # live photons; segments from the light; photons stored; rays
    while n:
        if ns + n > photons.depth.size:  # each live photon stores at most one
            photons = _grown(photons, ns, max(2 * photons.depth.size, ns + n))
        hits = wavefront_hits(geo, wf, cur, n)
        traced += n
        extend = max_depth < 0 or depth + 2 <= max_depth
        ns, n = _scatter(hits, cur, spec, stream, first, depth, mode, extend, geo,
                         Scattered(photons, nxt, spec_nxt, ns))
        cur, nxt = nxt, cur
        spec, spec_nxt = spec_nxt, spec
        depth += 1
    return photons, ns, traced


def shoot(geom: SceneGeometry, scene: Scene, key: np.uint64, count: int, mode: int, threads: int,
          stored: bool = False, first: int = 0, sampler: str = "independent") -> tuple[Photons, int]:
    """A photon map's photons, their flux divided by the photons emitted: (photons, emitted).

    The map's photons are one sequence of ``sampler``
    (:func:`cornell_harness.renderers.core.sampler.sequence_stream`) keyed ``key``.
    ``count`` photons are emitted (numbered ``first`` on), or, with
    ``stored``, batches of :data:`BATCH` are emitted until ``count`` photons
    are stored (Mitsuba 0.6's ``globalPhotons``/``causticPhotons`` count stored
    photons), up to :data:`MAX_EMITTED_PER_STORED` times ``count`` emitted.
    Batches are traced on ``threads`` threads and joined in order.
    """
    parts: list[Photons] = []
    state = {"stored": 0, "emitted": 0, "done": False}

    def batches():
        b = first
        limit = first + (count * MAX_EMITTED_PER_STORED if stored else count)
        while b < limit and not state["done"]:
            yield b, min(b + BATCH, limit)
            b += BATCH

    stream = sequence_stream(sampler, key)

    def work(batch):
        return trace_photons(geom, scene, stream, batch[0], batch[1], mode)

    def reduce(batch, photons):
        if state["done"]:
            return  # traced ahead by another thread after the target was reached: not part of the map
        parts.append(photons)
        state["stored"] += len(photons)
        state["emitted"] = batch[1] - first
        state["done"] = stored and state["stored"] >= count

    run_units(batches(), work, reduce, threads)
    photons = join(parts)
    emitted = state["emitted"]
    photons.power[:] /= max(emitted, 1)
    return photons, emitted
