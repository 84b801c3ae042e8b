"""Dynamic diffuse global illumination: a grid of irradiance probes, updated by ray tracing, read with visibility.

Majercik, Guertin, Nowrouzezahrai and McGuire 2019, "Dynamic Diffuse Global
Illumination with Ray-Traced Irradiance Fields", JCGT 8(2), as NVIDIA's
RTXGI SDK implements it (``ProbeBlendingCS.hlsl``, ``Irradiance.hlsl``;
its defaults are quoted below as "RTXGI"). Everything here is a pure
function of arrays or a numba kernel; :mod:`cornell_harness.renderers.probes` is the
adapter that runs the updates and the camera pass.

**The volume** (:class:`Volume`): probes on a regular grid (:class:`ProbeGrid`;
probe (i, j, k) at ``origin + (i, j, k) · spacing``, index ``i + nx (j + ny k)``),
each with two octahedral maps (:mod:`cornell_harness.renderers.core.octahedral`, one-texel
borders): **irradiance** E(n) for normals n (``irradiance_texels``², RTXGI
6 × 6) and the **mean and mean square of the distance** to the nearest
surface in each direction (``depth_texels``², RTXGI 14 × 14).

**An update** (:func:`trace_probe_rays`, :func:`blend`), per probe: N rays
(``rays_per_probe``, RTXGI 256) along the spherical Fibonacci directions
(:func:`cornell_harness.renderers.core.sampling.spherical_fibonacci`), all turned by one
random rotation per update. At a ray's hit the radiance leaving the surface
towards the probe is its **reflected** radiance: direct light (one light
sample and one cosine-weighted BSDF sample, combined by MIS) plus ρ/π times the irradiance the volume
gave at that point in the **previous** update (:func:`probe_irradiance`), so
update k carries light of up to k bounces. Emission is left out: the camera
pass sees emitters itself and estimates direct light exactly, so the probes
hold the *indirect* irradiance, the part no light sample reaches. A miss
carries nothing (no environment); a surface hit from behind is a
**backface** (RTXGI ``DDGIStoreProbeRayBackfaceHit``): no radiance, and its
distance shortened to 0.2 t; mirrors and glass reflect nothing into the
probes (DDGI treats every surface as diffuse; our camera pass follows them
instead). Then each irradiance texel of direction n_t blends the rays,
weight max(0, n_t · ω), backfaces skipped; each depth texel the distances
(clamped to 1.5 × |spacing|), weight max(0, n_t · ω)^``sharpness`` (RTXGI
``probeDistanceExponent`` 50).

**A lookup** (:func:`probe_irradiance`) at a surface point x, normal n, seen
along v: the point is biased to x + ``normal_bias``·n − ``view_bias``·v; the
8 probes of its grid cell are weighted by trilinear weights (at least
0.001), the "wrap" backface term ((1 + n·ω_p)/2)² + 0.2 with ω_p towards
the probe, and **Chebyshev's visibility bound** P(d ≥ r) ≤ σ²/(σ² + (r − μ)²)
from the distance moments when the probe is farther than the mean distance
μ in its direction (Majercik et al. §4.2, after variance shadow maps).

**The heuristics that change energy**, each a switch of :class:`Volume` and
of the adapter (measured in ``docs/irradiance-probes.md``):

- ``gamma_blending``: texels are stored as E^(1/5) (RTXGI
  ``probeIrradianceEncodingGamma`` 5) and blended over time in that space;
  lookups decode to E^(1/2), interpolate, and square ("perceptual"
  blending). Off: everything linear.
- ``half_normalisation``: a texel is π · Σ L w / Σ w, RTXGI's division by
  2 Σ w followed by its ×2π at lookup: a ratio estimator over the rays
  that did not hit a backface. Off: the Monte Carlo estimator of
  E = ∫ L max(0, n·ω) dω for N directions of 4π/N each, (4π/N) Σ L w.
- ``weight_floor``: the visibility weight is at least 0.05 (RTXGI), so
  some probe always contributes. Off: 0.
- ``crush``: weights under 0.2 are multiplied by (w/0.2)² (RTXGI's
  "crush tiny weights").

Not modelled: RTXGI's probe relocation and classification, its change
limiting (``probeIrradianceThreshold``, ``probeBrightnessThreshold``) and
texture quantisation: the volume is float64 throughout.

Temporal blending (:func:`blend`): each texel becomes lerp(new, old, h),
with h chosen by the caller per update (:func:`cornell_harness.renderers.probes.history_weight`:
0 to replace, RTXGI's hysteresis 0.97, or the running mean's j/(j + 1)),
and 0 wherever the old texel is still all zero (a probe's first update, as
RTXGI).
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from cornell_harness.renderers.core.bsdf import faces, is_delta, lambert_pdf, lambert_sample
from cornell_harness.renderers.core.direct import sample_ld
from cornell_harness.renderers.core.geometry import SceneGeometry, offset_origin, ray_hit
from cornell_harness.renderers.core.lights import emits, solid_angle_pdf_along
from cornell_harness.renderers.core.octahedral import bilinear_texels, fill_borders, octahedral_uv, texel_directions
from cornell_harness.renderers.core.rays import add_unoccluded, head, ray_buffer, set_path, set_ray, set_shadow, shadow_buffer
from cornell_harness.renderers.core.sampler import (PROBE_BSDF_U, PROBE_EMITTER_PICK, PROBE_EMITTER_U, Stream,
                                                    sample_1d, sample_2d, sequence_point)
from cornell_harness.renderers.core.sampling import INV_PI, jit, power_heuristic

#: RTXGI's constants of the heuristics (Irradiance.hlsl, ProbeBlendingCS.hlsl, DDGIVolume.h).
ENCODING_GAMMA = 5.0
WEIGHT_FLOOR = 0.05
CRUSH_THRESHOLD = 0.2
BACKFACE_DISTANCE = 0.2
MAX_DISTANCE_SPACINGS = 1.5
MIN_TRILINEAR = 0.001
MIN_WEIGHT = 1e-6
NEGLIGIBLE_WEIGHT = 1e-12


class ProbeGrid(NamedTuple):
    """Where the probes are: probe (i, j, k) at origin + (i, j, k)·spacing."""

    origin: np.ndarray  # (3,) float64
    spacing: np.ndarray  # (3,) float64, > 0
    counts: np.ndarray  # (3,) int64, >= 2 each


class Volume(NamedTuple):
    """What a lookup reads: the grid, every probe's maps, and the lookup's parameters (scene units)."""

    origin: np.ndarray
    spacing: np.ndarray
    counts: np.ndarray
    irradiance: np.ndarray  # (P, n+2, n+2, 3) E^(1/gamma) per texel, bordered
    moments: np.ndarray  # (P, m+2, m+2, 2) mean distance and mean squared distance, bordered
    normal_bias: float
    view_bias: float
    gamma: float  # encoding gamma of the irradiance maps; 1: linear
    visibility: bool
    weight_floor: float
    crush: float


def probe_grid(lo, hi, counts) -> ProbeGrid:
    """``counts`` probes per axis (each >= 2) from corner ``lo`` to corner ``hi``."""
    lo, hi, counts = np.asarray(lo, np.float64), np.asarray(hi, np.float64), np.asarray(counts, np.int64)
    return ProbeGrid(lo, (hi - lo) / (counts - 1), counts)


def probe_positions(grid: ProbeGrid) -> np.ndarray:
    """Every probe's position (P, 3), in index order i + nx (j + ny k)."""
    k, j, i = np.meshgrid(*(np.arange(c) for c in grid.counts[::-1]), indexing="ij")
    idx = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)
    return grid.origin + idx * grid.spacing


def empty_volume(grid: ProbeGrid, irradiance_texels: int, depth_texels: int, normal_bias: float,
                 view_bias: float, gamma: float, visibility: bool, weight_floor: float, crush: float) -> Volume:
    """A volume of black probes (every texel 0): the state before the first update."""
    p = int(np.prod(grid.counts))
    return Volume(grid.origin, grid.spacing, grid.counts,
                  np.zeros((p, irradiance_texels + 2, irradiance_texels + 2, 3)),
                  np.zeros((p, depth_texels + 2, depth_texels + 2, 2)),
                  float(normal_bias), float(view_bias), float(gamma), bool(visibility), float(weight_floor),
                  float(crush))


def max_distance(volume: Volume) -> float:
    """Probe-ray distances are clamped to 1.5 grid-cell diagonals (RTXGI ProbeBlendingCS)."""
    return MAX_DISTANCE_SPACINGS * float(np.linalg.norm(volume.spacing))


@jit
def _bilinear(m, q, r0, c0, fr, fc, ch):
    """Channel ``ch`` of probe ``q``'s bordered map ``m``, bilinear at the texels :func:`bilinear_texels` gave."""
    return ((1.0 - fr) * ((1.0 - fc) * m[q, r0, c0, ch] + fc * m[q, r0, c0 + 1, ch])
            + fr * ((1.0 - fc) * m[q, r0 + 1, c0, ch] + fc * m[q, r0 + 1, c0 + 1, ch]))


@jit
def probe_irradiance(vol, x, n, v):
    """Irradiance (3-tuple) at point ``x`` with unit normal ``n``, seen along unit ``v``: the module's lookup."""
    bx = x[0] + n[0] * vol.normal_bias - v[0] * vol.view_bias
    by = x[1] + n[1] * vol.normal_bias - v[1] * vol.view_bias
    bz = x[2] + n[2] * vol.normal_bias - v[2] * vol.view_bias
    nx, ny, nz = vol.counts[0], vol.counts[1], vol.counts[2]
    gx = min(max(int(math.floor((bx - vol.origin[0]) / vol.spacing[0])), 0), nx - 1)
    gy = min(max(int(math.floor((by - vol.origin[1]) / vol.spacing[1])), 0), ny - 1)
    gz = min(max(int(math.floor((bz - vol.origin[2]) / vol.spacing[2])), 0), nz - 1)
    ax = min(max((bx - (vol.origin[0] + gx * vol.spacing[0])) / vol.spacing[0], 0.0), 1.0)
    ay = min(max((by - (vol.origin[1] + gy * vol.spacing[1])) / vol.spacing[1], 0.0), 1.0)
    az = min(max((bz - (vol.origin[2] + gz * vol.spacing[2])) / vol.spacing[2], 0.0), 1.0)
    ni = vol.irradiance.shape[1] - 2
    nd = vol.moments.shape[1] - 2
    ui, vi = octahedral_uv(n[0], n[1], n[2])
    ri, ci, fri, fci = bilinear_texels(ni, ui, vi)
    e0 = e1 = e2 = 0.0
    total = 0.0
    for k in range(8):
        ox, oy, oz = k & 1, (k >> 1) & 1, (k >> 2) & 1
        cx, cy, cz = min(gx + ox, nx - 1), min(gy + oy, ny - 1), min(gz + oz, nz - 1)
        q = cx + nx * (cy + ny * cz)
        px = vol.origin[0] + cx * vol.spacing[0]
        py = vol.origin[1] + cy * vol.spacing[1]
        pz = vol.origin[2] + cz * vol.spacing[2]
        # Wrap shading: a probe behind the surface counts less, never nothing.
        wx, wy, wz = px - x[0], py - x[1], pz - x[2]
        wl = math.sqrt(wx * wx + wy * wy + wz * wz)
        cos_p = (wx * n[0] + wy * n[1] + wz * n[2]) / wl if wl > 0.0 else 1.0
        wrap = (cos_p + 1.0) * 0.5
        w = wrap * wrap + 0.2
        if vol.visibility:
            dx, dy, dz = bx - px, by - py, bz - pz  # probe to biased point
            r = math.sqrt(dx * dx + dy * dy + dz * dz)
            cheb = 1.0
            if r > 0.0:
                ud, vd = octahedral_uv(dx, dy, dz)
                rd, cd, frd, fcd = bilinear_texels(nd, ud, vd)
                mean = _bilinear(vol.moments, q, rd, cd, frd, fcd, 0)
                mean2 = _bilinear(vol.moments, q, rd, cd, frd, fcd, 1)
                if r > mean:  # farther than the surfaces the probe saw this way: maybe hidden
                    var = abs(mean * mean - mean2)
                    t = r - mean
                    cheb = var / (var + t * t)  # t > 0: no zero division
                    cheb = cheb * cheb * cheb
            w *= max(vol.weight_floor, cheb)
        w = max(MIN_WEIGHT, w)
        if w < vol.crush:
            w *= w * w / (vol.crush * vol.crush)
        tx = ax if ox else 1.0 - ax
        ty = ay if oy else 1.0 - ay
        tz = az if oz else 1.0 - az
        w *= max(MIN_TRILINEAR, tx) * max(MIN_TRILINEAR, ty) * max(MIN_TRILINEAR, tz)
        s0 = _bilinear(vol.irradiance, q, ri, ci, fri, fci, 0)
        s1 = _bilinear(vol.irradiance, q, ri, ci, fri, fci, 1)
        s2 = _bilinear(vol.irradiance, q, ri, ci, fri, fci, 2)
        if vol.gamma != 1.0:  # decode to a gamma-2 curve for the spatial blend (RTXGI)
            h = vol.gamma * 0.5
            s0, s1, s2 = s0 ** h, s1 ** h, s2 ** h
        e0 += w * s0
        e1 += w * s1
        e2 += w * s2
        total += w
    e0, e1, e2 = e0 / total, e1 / total, e2 / total  # total >= 8·MIN_WEIGHT·MIN_TRILINEAR^3 > 0
    if vol.gamma != 1.0:
        return e0 * e0, e1 * e1, e2 * e2
    return e0, e1, e2


@jit
def _start_probe_rays(positions, directions, p0, count, rays):
    """Rays of probes p0 .. p0+count-1, ``directions.shape[0]`` each, into ``rays`` (ray c·N + r: path c·N + r)."""
    n = directions.shape[0]
    for c in range(count):
        o = (positions[p0 + c, 0], positions[p0 + c, 1], positions[p0 + c, 2])
        for r in range(n):
            i = c * n + r
            set_ray(rays, i, o, (directions[r, 0], directions[r, 1], directions[r, 2]))
            set_path(rays, i, i, (1.0, 1.0, 1.0), 0.0)


class ProbeRayOutput(NamedTuple):
    """What :func:`_shade_probe_rays` writes, per probe ray i of a unit (and the direct-light rays it makes)."""

    radiance: np.ndarray  # (m, 3) reflected radiance towards the probe
    distance: np.ndarray  # (m,) hit distance; negative: a backface (-0.2 t); the clamp distance on a miss
    shadow: object  # ShadowBuffer: the light samples' segments, each carrying its MIS-weighted radiance
    bsdf: object  # RayBuffer: the BSDF samples' rays, each carrying ρ and its pdf


@jit
def _shade_probe_rays(prim, t_sphere, rays, stream, first, per_probe, vol, geo, far, out):
    """Reflected radiance towards the probe and hit distance of each probe ray, into ``out``
    (:class:`ProbeRayOutput`).

    Writes the radiance the previous volume gives (ρ/π·E), the light sample's
    segments into ``out.shadow`` and the BSDF sample's rays into ``out.bsdf``,
    each carrying its MIS weight; returns how many of each. Ray i draws the
    numbers of probe ray ``first + i``, ``per_probe`` rays to a probe
    (:func:`cornell_harness.renderers.core.sampler.sequence_point`).
    """
    radiance, distance, shadow, bsdf = out
    ns = 0
    nb = 0
    for i in range(prim.size):
        radiance[i, 0] = radiance[i, 1] = radiance[i, 2] = 0.0
        p = prim[i]
        if p < 0:
            distance[i] = far
            continue
        d, x, n, cos_o, t, mat = ray_hit(geo, rays, i, p, t_sphere)
        if not faces(mat, cos_o):
            distance[i] = -BACKFACE_DISTANCE * t  # negative marks the backface
            continue
        distance[i] = t
        if is_delta(mat):
            continue
        rho = (geo.reflectance[p, 0], geo.reflectance[p, 1], geo.reflectance[p, 2])
        e = probe_irradiance(vol, x, n, d)
        for c in range(3):
            radiance[i, c] = rho[c] * INV_PI * e[c]
        if geo.emitter_ids.size == 0:
            continue
        point = sequence_point(stream, first + i, per_probe)
        # Direct light by MIS of a light sample and a cosine-weighted BSDF sample (Veach 1997 §9.2, power
        # heuristic): a light sample alone has unbounded variance next to an emitter that meets the surface
        # at an edge (the furnace: every wall emits).
        u1, u2 = sample_2d(stream, point, PROBE_EMITTER_U)
        found, a, sd, tfar, lc = sample_ld(x, n, mat, rho, (sample_1d(stream, point, PROBE_EMITTER_PICK), u1, u2),
                                           geo, True)
        if found:
            set_shadow(shadow, ns, a, sd, tfar, i, lc)
            ns += 1
        ub1, ub2 = sample_2d(stream, point, PROBE_BSDF_U)
        dx, dy, dz, cos_b = lambert_sample(n, ub1, ub2)
        if cos_b > 0.0:
            set_ray(bsdf, nb, offset_origin(x, n, geo.offset), (dx, dy, dz))
            set_path(bsdf, nb, i, rho, lambert_pdf(cos_b))  # f·cos/pdf = ρ for a cosine sample
            nb += 1
    return ns, nb


@jit
def _emission_found(prim, t_sphere, rays, geo, radiance):
    """Emission the BSDF samples found, MIS-weighted against light sampling, added to their probe rays."""
    for i in range(prim.size):
        p = prim[i]
        if p < 0 or geo.light_pdf_area[p] <= 0.0:
            continue
        _, _, _, cos_o, t, _ = ray_hit(geo, rays, i, p, t_sphere)
        if not emits(cos_o):
            continue
        w = power_heuristic(rays.pdf[i], solid_angle_pdf_along(geo.light_pdf_area[p], t, cos_o))
        q = rays.path[i]
        for c in range(3):
            radiance[q, c] += rays.beta[i, c] * geo.radiance[p, c] * w


def trace_probe_rays(geom: SceneGeometry, volume: Volume, positions: np.ndarray, directions: np.ndarray,
                     p0: int, count: int, stream: Stream) -> tuple[np.ndarray, np.ndarray]:
    """Radiance (count·N, 3) and signed distance (count·N,) of the rays of probes p0 .. p0+count-1.

    Ray r of probe p draws the numbers of probe ray ``p·N + r`` of the update's ``stream``
    (:func:`cornell_harness.renderers.probes.update_stream`): independent of how probes are cut into units.
    """
    m = count * len(directions)
    rays = ray_buffer(m)
    _start_probe_rays(positions, directions, p0, count, rays)
    prim, t_sphere = geom.closest_hits(rays)
    out = ProbeRayOutput(np.empty((m, 3)), np.empty(m), shadow_buffer(m), ray_buffer(m))
    radiance, distance, shadow, bsdf = out
    geo = geom.tables()
    n = len(directions)
    ns, nb = _shade_probe_rays(prim, t_sphere, rays, stream, p0 * n, n, volume, geo, max_distance(volume), out)
    seg = head(shadow, ns)
    add_unoccluded(radiance, seg, geom.unoccluded(seg.o, seg.d, seg.t))
    found = head(bsdf, nb)
    _emission_found(*geom.closest_hits(found), found, geo, radiance)
    return radiance, distance


@jit
def _blend_irradiance(radiance, distance, directions, texels, half_normalisation, out):
    """Irradiance (count, t, t, 3) of each probe's texels from its rays (linear, before any encoding)."""
    n = directions.shape[0]
    for c in range(out.shape[0]):
        for a in range(out.shape[1]):
            for b in range(out.shape[2]):
                s0 = s1 = s2 = 0.0
                total = 0.0
                for r in range(n):
                    k = c * n + r
                    if distance[k] < 0.0:
                        continue  # backface: not blended (RTXGI)
                    w = max(0.0, texels[a, b, 0] * directions[r, 0] + texels[a, b, 1] * directions[r, 1]
                            + texels[a, b, 2] * directions[r, 2])
                    s0 += w * radiance[k, 0]
                    s1 += w * radiance[k, 1]
                    s2 += w * radiance[k, 2]
                    total += w
                if half_normalisation:
                    # π Σ L w / Σ w: RTXGI's Σ/(2 Σ w), times its 2π at lookup; the weight sum guarded.
                    k = math.pi / max(total, 1e-9 * n)
                else:
                    k = 4.0 * math.pi / n
                out[c, a, b, 0], out[c, a, b, 1], out[c, a, b, 2] = k * s0, k * s1, k * s2


@jit
def _blend_moments(distance, directions, texels, sharpness, far, out):
    """Mean and mean squared distance (count, t, t, 2) of each probe's depth texels from its rays.

    Rays whose weight cos^sharpness is below :data:`NEGLIGIBLE_WEIGHT` are skipped before the power is taken
    (the power is the kernel's cost): together they shift a texel by less than N·1e-12 of its nearest ray's.
    """
    n = directions.shape[0]
    cutoff = max(0.0, NEGLIGIBLE_WEIGHT ** (1.0 / sharpness))
    for c in range(out.shape[0]):
        for a in range(out.shape[1]):
            for b in range(out.shape[2]):
                s1 = s2 = 0.0
                total = 0.0
                for r in range(n):
                    k = c * n + r
                    w = texels[a, b, 0] * directions[r, 0] + texels[a, b, 1] * directions[r, 1] \
                        + texels[a, b, 2] * directions[r, 2]
                    if w <= cutoff:
                        continue
                    w = w ** sharpness
                    d = min(abs(distance[k]), far)
                    s1 += w * d
                    s2 += w * d * d
                    total += w
                if total > 0.0:
                    out[c, a, b, 0], out[c, a, b, 1] = s1 / total, s2 / total
                else:
                    out[c, a, b, 0], out[c, a, b, 1] = far, far * far


def blend(volume: Volume, p0: int, radiance: np.ndarray, distance: np.ndarray, directions: np.ndarray,
          hysteresis: float, half_normalisation: bool, sharpness: float) -> tuple[np.ndarray, np.ndarray]:
    """The new interior maps of probes p0 .. p0+count-1 after one update: (irradiance, moments), encoded.

    Each texel is lerp(new, old, h) with h = ``hysteresis``, or 0 where the
    old texel is all zero (a probe's first update, RTXGI).
    """
    count = len(distance) // len(directions)
    ni, nd = volume.irradiance.shape[1] - 2, volume.moments.shape[1] - 2
    irr = np.empty((count, ni, ni, 3))
    _blend_irradiance(radiance, distance, directions, _texels(ni), half_normalisation, irr)
    if volume.gamma != 1.0:
        irr = irr ** (1.0 / volume.gamma)
    mom = np.empty((count, nd, nd, 2))
    _blend_moments(distance, directions, _texels(nd), sharpness, max_distance(volume), mom)
    return (_history(irr, volume.irradiance[p0:p0 + count, 1:-1, 1:-1], hysteresis),
            _history(mom, volume.moments[p0:p0 + count, 1:-1, 1:-1], hysteresis))


@lru_cache(maxsize=8)
def _texels(n: int) -> np.ndarray:
    t = texel_directions(n)
    t.flags.writeable = False
    return t


def _history(new: np.ndarray, old: np.ndarray, hysteresis: float) -> np.ndarray:
    h = np.where((old == 0.0).all(axis=-1, keepdims=True), 0.0, hysteresis)
    return new * (1.0 - h) + old * h


def with_maps(volume: Volume, irradiance: np.ndarray, moments: np.ndarray) -> Volume:
    """``volume`` with new interior maps (P, n, n, 3) and (P, m, m, 2), their borders filled."""
    irr, mom = np.empty_like(volume.irradiance), np.empty_like(volume.moments)
    fill_borders(irr, irradiance)
    fill_borders(mom, moments)
    return volume._replace(irradiance=irr, moments=mom)
