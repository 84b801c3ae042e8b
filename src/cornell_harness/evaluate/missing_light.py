"""What an approximation gets wrong per region: the bias of the region's mean radiance, the share of the
reference's light it misses, each with its standard error; and the study's extra regions (docs/whitted.md).

The figures are read off the harness's own per-region metrics (results rows' ``region.<name>.<metric>``
columns, :func:`cornell_harness.evaluate.regions.region_metrics`) and the reference's noise inside each region
(:func:`cornell_harness.evaluate.regions.region_noise`); nothing here re-scores an image.

Standard errors are *over seeds*: a biased renderer (photon map, probes, Whitted) gives no variance of its
own image, but its region mean still moves from seed to seed. With per-seed relative errors
``r_s = m_s / m_R − 1`` of the region mean ``m_s`` against the reference's ``m_R``:

- missing share ``1 − mean(m_s) / m_R = −mean(r_s)``, SE ``sqrt(var(r)/n + ((1 + mean r)·ρ)²)``;
- bias ``mean(m_s) − m_R = m_R·mean(r_s)``, SE ``m_R·sqrt(var(r)/n + ρ²)``;

where ``ρ`` is the reference's relative standard error of the region mean (its own per-pixel variance of
the mean, pixels independent) and var is the sample variance over the n seeds (first-order error
propagation; a renderer that gives one image whatever the seed contributes only ρ).

Extra regions. The stored scenes' regions are pinned by many tests and enter the gate's z-test family, so
the study adds its own without touching the scene files (regions are not in the content hash, so the scene
with them is the same scene, :func:`with_study_regions`): ``floor`` and ``back-edge`` on the caustics scene
(as on ``cornell-box``), and on ``cornell-box`` the ``penumbra``: the floor pixels whose centre sees part of
the area light, neither all nor none of it (:func:`penumbra_mask`), where soft shadows cost samples.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from cornell_harness.evaluate import regions as named_regions
from cornell_harness.scenes.model import Region, Scene, triangle_arrays

#: Regions the study adds to a scene, by scene name (the scene's own, of the same name, win).
STUDY_REGIONS: dict[str, tuple[Region, ...]] = {
    "cornell-box-caustics": (
        Region("floor", ("floor",), None, "the floor, caustic and glass shadow included"),
        Region("back-edge", ("floor", "back"), ((-1.01, -1.01, -1.01), (1.01, -0.9, -0.9)),
               "where the floor meets the back wall (within 0.1), as on cornell-box"),
    ),
}
#: The penumbra: floor points that see more than LOW and less than HIGH of the light's area.
PENUMBRA_LOW, PENUMBRA_HIGH = 0.05, 0.95
#: Light samples per emitter triangle side for the visibility: 8² sub-triangles per triangle.
VISIBILITY_SUBDIVISIONS = 8


def with_study_regions(scene: Scene) -> Scene:
    """``scene`` with :data:`STUDY_REGIONS` added after its own (same content hash: regions are not content)."""
    extra = {r.name: r for r in STUDY_REGIONS.get(scene.name, ()) if r.name not in scene.regions}
    return dataclasses.replace(scene, regions={**scene.regions, **extra}) if extra else scene


# --------------------------------------------------------------------------
# The penumbra
# --------------------------------------------------------------------------


def emitter_samples(scene: Scene, n: int = VISIBILITY_SUBDIVISIONS) -> tuple[np.ndarray, np.ndarray]:
    """Points on the emitters, (m, 3), and their area weights (m,) summing to 1.

    Each emitter triangle is cut into n² equal-area sub-triangles (the barycentric grid); the points are their
    centroids, each weighted by its area.
    """
    arrays = triangle_arrays(scene)
    emitting = np.array([m.is_emitter for m in scene.meshes])[arrays["mesh"]]
    tri = arrays["vertices"][arrays["triangles"][emitting]]  # (T, 3, 3)
    if len(tri) == 0:
        raise ValueError(f"scene {scene.name!r} has no emitter: no penumbra to find")
    bary = []
    for i in range(n):
        for j in range(n - i):
            bary.append(((i + 1 / 3) / n, (j + 1 / 3) / n))  # upright sub-triangle's centroid
            if i + j < n - 1:
                bary.append(((i + 2 / 3) / n, (j + 2 / 3) / n))  # the inverted one beside it
    b = np.array(bary)
    w = np.concatenate([b, 1.0 - b.sum(axis=1, keepdims=True)], axis=1)  # (n², 3) weights of v1, v2, v0
    points = (w[None, :, 0, None] * tri[:, None, 1] + w[None, :, 1, None] * tri[:, None, 2]
              + w[None, :, 2, None] * tri[:, None, 0])
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    weights = np.repeat(area / len(b), len(b))
    return points.reshape(-1, 3), weights / weights.sum()


def light_visibility(scene: Scene, points: np.ndarray, n: int = VISIBILITY_SUBDIVISIONS) -> np.ndarray:
    """The area-weighted fraction of the emitters each of ``points`` (k, 3) sees unblocked, in [0, 1].

    A segment from a light sample to a point is blocked by any non-emitting triangle or sphere strictly
    between them (a relative margin of 1e-6 at the point's end, so its own surface does not block it).
    """
    samples, weights = emitter_samples(scene, n)
    arrays = triangle_arrays(scene)
    emitting = np.array([m.is_emitter for m in scene.meshes])[arrays["mesh"]]
    v = arrays["vertices"][arrays["triangles"][~emitting]]
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    seen = np.zeros(len(points))
    for light, w in zip(samples, weights):
        dirs = points - light  # t = 1 at the point
        _, t = named_regions._first_triangle_hits(light, dirs, v[:, 0], v[:, 1], v[:, 2])
        for s in scene.spheres:
            t = np.minimum(t, s.hit_distances(light, dirs))
        seen += w * (t >= 1.0 - 1e-6)
    return seen


def penumbra_mask(scene: Scene, objects: Sequence[str] = ("floor",), low: float = PENUMBRA_LOW,
                  high: float = PENUMBRA_HIGH, n: int = VISIBILITY_SUBDIVISIONS) -> np.ndarray:
    """(H, W) bool: pixels whose centre's camera ray first hits ``objects`` at a point that sees more than
    ``low`` and less than ``high`` of the light (:func:`light_visibility`): the soft shadows' edges."""
    cam = scene.camera
    x = np.arange(cam.width) + 0.5
    y = np.arange(cam.height) + 0.5
    dirs = cam.directions(x[None, :], y[:, None]).reshape(-1, 3)
    obj, points = named_regions.first_hits(scene, dirs)
    names = scene.object_names()
    on = np.isin(obj, [names.index(o) for o in objects])
    vis = np.zeros(len(obj))
    vis[on] = light_visibility(scene, points[on], n)
    return (on & (vis > low) & (vis < high)).reshape(cam.height, cam.width)


def study_masks(scene: Scene) -> dict[str, np.ndarray]:
    """Every region mask the study scores ``scene`` in: the scene's own, :data:`STUDY_REGIONS`' and, on a
    scene with a floor and no spheres (the boxes' soft shadows), ``penumbra``."""
    masks = named_regions.region_masks(with_study_regions(scene))
    if "floor" in scene.object_names() and not scene.spheres and scene.emitters:
        masks["penumbra"] = penumbra_mask(scene)
    return masks


# --------------------------------------------------------------------------
# Figures over seeds
# --------------------------------------------------------------------------


@dataclass(frozen=True)
class Missing:
    """One renderer in one region: bias of the region mean and share of the reference's light missing."""

    bias: float  # mean(m_s) − m_R, radiance
    bias_se: float
    share: float  # 1 − mean(m_s) / m_R
    share_se: float
    seeds: int


def missing_light(rel_errors: Sequence[float], ref_mean: float, ref_rel_se: float) -> Missing:
    """:class:`Missing` from per-seed ``mean_radiance_rel_error`` of a region (see the module docstring).

    ``ref_mean`` and ``ref_rel_se`` are the reference's region mean and its relative standard error
    (:func:`cornell_harness.evaluate.regions.region_noise`'s ``mean`` and ``mean_rel_se``). Non-finite errors
    (a failed run, an empty region) are dropped; with none left every figure is NaN.
    """
    r = np.array([e for e in rel_errors if e is not None and math.isfinite(e)], dtype=np.float64)
    if r.size == 0:
        return Missing(math.nan, math.nan, math.nan, math.nan, 0)
    mean = float(r.mean())
    seed_var = float(r.var(ddof=1)) / r.size if r.size > 1 else 0.0
    rho = float(ref_rel_se) if ref_rel_se is not None and math.isfinite(ref_rel_se) else 0.0
    return Missing(bias=ref_mean * mean, bias_se=abs(ref_mean) * math.sqrt(seed_var + rho ** 2),
                   share=-mean, share_se=math.sqrt(seed_var + ((1.0 + mean) * rho) ** 2), seeds=int(r.size))


def region_table(rows: Sequence[Mapping], regions: Sequence[str], ref_noise: Mapping[str, Mapping],
                 label: str = "renderer") -> list[dict]:
    """One dict per (label value, region), in first-seen order: :class:`Missing`'s figures, the mean ΔE00
    over seeds (``delta_e``), and the median render time (``time_s``).

    ``rows`` are results rows of ok runs (one per seed), ``ref_noise`` the reference's
    :func:`cornell_harness.evaluate.regions.region_noise` by region.
    """
    groups: dict[str, list[Mapping]] = {}
    for row in rows:
        if row.get("status", "ok") == "ok":
            groups.setdefault(str(row[label]), []).append(row)
    out = []
    for name, group in groups.items():
        times = [float(g["time_s"]) for g in group if g.get("time_s") is not None]
        for region in regions:
            prefix = f"{named_regions.REGION_PREFIX}{region}."
            noise = ref_noise.get(region, {})
            m = missing_light([g.get(prefix + "mean_radiance_rel_error") for g in group],
                              float(noise.get("mean", math.nan)), noise.get("mean_rel_se") or 0.0)
            de = [float(g[prefix + "delta_e2000_mean"]) for g in group
                  if g.get(prefix + "delta_e2000_mean") is not None and math.isfinite(g[prefix + "delta_e2000_mean"])]
            out.append({label: name, "region": region, **dataclasses.asdict(m),
                        "delta_e": float(np.mean(de)) if de else math.nan,
                        "time_s": float(np.median(times)) if times else math.nan,
                        "spp": group[0].get("spp")})
    return out


def study_columns(scene: Scene, image: np.ndarray, reference, spp: int,
                  masks: Mapping[str, np.ndarray] | None = None) -> dict:
    """Results-row columns ``region.<name>.<metric>`` of ``image`` in the study's regions that ``scene`` does
    not declare itself (``masks``, default :func:`study_masks`; pass them to score many images), scored by
    :func:`cornell_harness.evaluate.regions.region_metrics`."""
    masks = {k: m for k, m in (study_masks(scene) if masks is None else masks).items() if k not in scene.regions}
    return named_regions.region_columns(named_regions.region_metrics(image, reference, masks, spp=spp))
