"""Photon maps: stored photons indexed for nearest-neighbour search, and the density estimate over them.

Jensen 2001 ("Realistic Image Synthesis Using Photon Mapping", §7.2): the
irradiance at a point x of a surface with normal n is estimated from the k
photons nearest to x, within a maximum radius, as

    E(x) ≈ Σ_p Φ_p · K(‖x − x_p‖; r),

r the distance to the k-th photon (or the maximum radius when fewer are
found there), K a kernel on the disc of radius r normalised to ∫ K dA = 1
(:data:`KERNELS`). A Lambertian surface of albedo ρ reflects L = ρ/π · E,
so callers multiply by their throughput·ρ/π. The index is
:class:`scipy.spatial.cKDTree` over the photon positions.

- **Normal test** (Jensen §7.2.3): a photon counts only if its surface
  normal is within :data:`NORMAL_COS_MIN` of the query's, so light on a wall
  does not leak onto the floor at a corner, and only if it arrived from the
  query's side (its incoming direction above the query's surface), so light
  does not leak through a thin object.
- Φ_p is the flux that crossed the surface: the cosine of its incidence is
  already in it (the photon density is per unit area), so no cos θ factor.
- **Depth budget**: a query point reached by d camera segments may use a
  photon of depth k only when d + k ≤ max_depth (``budget``).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from cornell_harness.renderers.core.photons import Photons, subset
from cornell_harness.renderers.core.sampling import jit

#: Kernels of the density estimate: Jensen's cone filter (§7.2.2, k = 1: weight 1 − d/r,
#: normalised by 1/((1 − 2/3)·πr²)), Epanechnikov's (1 − d²/r², by 2/(πr²); Silverman 1986 §4.2,
#: the kernel of least mean integrated squared error) and the uniform disc (1/(πr²), SPPM's).
KERNELS = ("cone", "epanechnikov", "uniform")
_CONE, _EPANECHNIKOV, _UNIFORM = 0, 1, 2
#: cos of the largest angle between a photon's surface normal and the query's (60°): a corner (90°)
#: is rejected, a curved diffuse surface within the lookup radius is not.
NORMAL_COS_MIN = 0.5
#: Depth budget meaning "unbounded" (max_depth = -1): deeper than any stored photon.
UNBOUNDED = np.iinfo(np.int16).max


def kernel_id(name: str) -> int:
    return KERNELS.index(name)


def depth_budget(max_depth: int, depth: np.ndarray) -> np.ndarray:
    """Deepest photon a point reached by ``depth`` camera segments may use: max_depth − depth, or unbounded."""
    return np.full(len(depth), UNBOUNDED) if max_depth < 0 else max_depth - np.asarray(depth)


@jit
def photon_faces(n, p_normal, p_direction, p) -> float:
    """cos θ of photon ``p``'s incidence at a query of unit normal ``n``, or 0 where it must not count.

    It counts when its surface faces the query's way (the normal test) and it
    arrived from the query's side (the incoming-side test): the module
    docstring's rules, the same for every estimate of ours.
    """
    cos_n = n[0] * p_normal[p, 0] + n[1] * p_normal[p, 1] + n[2] * p_normal[p, 2]
    if cos_n < NORMAL_COS_MIN:
        return 0.0
    cos_in = n[0] * p_direction[p, 0] + n[1] * p_direction[p, 1] + n[2] * p_direction[p, 2]
    return cos_in if cos_in > 0.0 else 0.0


@jit
def pairs_that_count(normals, query, p_normal, p_direction, photon, out):
    """out[k] = whether photon ``photon[k]`` counts at query ``query[k]`` (:func:`photon_faces`)."""
    for k in range(query.size):
        i = query[k]
        out[k] = photon_faces((normals[i, 0], normals[i, 1], normals[i, 2]), p_normal, p_direction, photon[k]) > 0.0


@jit
def kernel_weight(kernel, d, r) -> float:
    """K(d; r) of :data:`KERNELS` (by index), normalised over the disc of radius r; 0 outside it.

    The k-th photon itself, on the circle, gets 0: with r = d_k the other k − 1
    photons are uniform in the disc, and (k − 1)/(πr²) is the unbiased density
    estimate (k/(πr²) reads k/(k − 1) too high: +3.4% at k = 30).
    """
    if not (r > 0.0 and d < r):
        return 0.0
    area = math.pi * r * r
    if kernel == _CONE:
        return (1.0 - d / r) * 3.0 / area
    if kernel == _EPANECHNIKOV:
        s = d / r
        return (1.0 - s * s) * 2.0 / area
    return 1.0 / area


@jit
def _estimate(dist, idx, normals, budget, r_max, kernel, photons, out, radius):
    """out[i] = Σ over the found ``photons`` of query i that pass the tests of Φ_p·K (see the module docstring)."""
    n_ph = photons.depth.size
    m, k = dist.shape
    for i in range(m):
        r = dist[i, k - 1] if idx[i, k - 1] < n_ph else r_max
        radius[i] = r
        for c in range(3):
            out[i, c] = 0.0
        for a in range(k):
            p = idx[i, a]
            if p >= n_ph:
                break  # cKDTree pads missing neighbours with n, after the found ones
            if photons.depth[p] > budget[i]:
                continue
            cos_in = photon_faces((normals[i, 0], normals[i, 1], normals[i, 2]), photons.normal, photons.direction, p)
            if not cos_in > 0.0:
                continue
            w = kernel_weight(kernel, dist[i, a], r)
            for c in range(3):
                out[i, c] += w * photons.power[p, c]


class PhotonMap:
    """Photons and the kd-tree over their positions (state: built once, queried by many threads)."""

    def __init__(self, photons: Photons, emitted: int):
        self.photons = photons
        self.emitted = emitted
        # Positions are float32 to keep maps compact; the tree holds its own float64 copy.
        self.tree = cKDTree(photons.position, balanced_tree=False, compact_nodes=False) if len(photons) else None

    def __len__(self) -> int:
        return len(self.photons)

    def irradiance(self, points: np.ndarray, normals: np.ndarray, budget: np.ndarray, k: int, r_max: float,
                   kernel: str) -> tuple[np.ndarray, np.ndarray]:
        """Irradiance (m, 3) at ``points`` (m, 3) with ``normals``, and the radius each estimate used.

        ``budget`` (m,) int: the deepest photon each point may use. The points
        must not be positions of this map's photons: a photon at the query
        point would count with the kernel's peak weight, not its mean
        (+2/(k − 1) for the cone; see :class:`PrecomputedIrradiance`).
        """
        m = len(points)
        out, radius = np.zeros((m, 3)), np.full(m, r_max)
        if m == 0 or self.tree is None:
            return out, radius
        k = min(k, len(self))
        dist, idx = self.tree.query(points, k=k, distance_upper_bound=r_max, workers=1)
        dist, idx = dist.reshape(m, k), idx.reshape(m, k)
        _estimate(dist, idx, np.ascontiguousarray(normals, np.float64), np.asarray(budget, np.int64), r_max,
                  kernel_id(kernel), self.photons, out, radius)
        return out, radius


#: Neighbours :meth:`PrecomputedIrradiance.lookup` considers for the nearest one that passes the normal test.
LOOKUP_CANDIDATES = 8


@jit
def _nearest_facing(idx, normals, p_normal, p_value, out):
    """out[i] = the value of the first candidate of query i whose normal passes the test (0 if none)."""
    n_pt = p_value.shape[0]
    for i in range(idx.shape[0]):
        for c in range(3):
            out[i, c] = 0.0
        for a in range(idx.shape[1]):
            p = idx[i, a]
            if p >= n_pt:
                break
            if normals[i, 0] * p_normal[p, 0] + normals[i, 1] * p_normal[p, 1] + normals[i, 2] * p_normal[p, 2] \
                    >= NORMAL_COS_MIN:
                for c in range(3):
                    out[i, c] = p_value[p, c]
                break


class PrecomputedIrradiance:
    """Irradiance estimated once at a subset of a map's photons, looked up by nearest neighbour.

    Christensen 1999 ("Faster Photon Map Global Illumination", JGT 4(3)):
    final gathering asks the global map for the radiance at many points,
    each a k-nearest-neighbour estimate; estimating the irradiance at every
    ``stride``-th photon's position (the sites) beforehand turns each into
    one nearest lookup (with the normal test), at the price of a
    piecewise-constant irradiance between sites, which the gather's
    averaging hides.

    The sites are taken out of the map their irradiance is estimated from
    (and the estimate scaled by stride/(stride − 1) for the photons taken
    out: a thinning by emission order, independent of position). Estimated
    from the whole map, a site's k nearest photons would be the same photons
    whose absence made it the nearest site to a lookup point: conditioned on
    that empty disc, its k-th neighbour is farther and its irradiance reads
    low, by a fraction that does not shrink with more photons (measured on
    the Cornell box at k = 30, 16 spp: -1.5% image-wide at 250k and -1.4% at
    1M photons, -2.2% with every photon a site, -1.1% at k = 100). With the
    sites taken out: -0.5%, -0.3%, -0.2% at 62.5k, 250k, 1M photons.
    """

    def __init__(self, pmap: PhotonMap, stride: int, k: int, r_max: float, kernel: str, budget: int):
        ph = pmap.photons
        site = np.zeros(len(ph), bool)
        site[::stride] = True
        rest = PhotonMap(subset(ph, ~site), pmap.emitted)
        self.position = ph.position[site]
        self.normal = ph.normal[site].astype(np.float64)
        irradiance, _ = rest.irradiance(self.position.astype(np.float64), self.normal,
                                        np.full(len(self.position), budget), k, r_max, kernel)
        self.irradiance = irradiance * (stride / (stride - 1))
        self.r_max = r_max
        self.tree = cKDTree(self.position, balanced_tree=False, compact_nodes=False) if len(self.position) else None

    def lookup(self, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """Irradiance (m, 3) at ``points``: that of the nearest precomputed point facing the same way."""
        m = len(points)
        out = np.zeros((m, 3))
        if m == 0 or self.tree is None:
            return out
        k = min(LOOKUP_CANDIDATES, len(self.position))
        _, idx = self.tree.query(points, k=k, distance_upper_bound=self.r_max, workers=1)
        _nearest_facing(idx.reshape(m, k), np.ascontiguousarray(normals, np.float64), self.normal,
                        self.irradiance, out)
        return out
