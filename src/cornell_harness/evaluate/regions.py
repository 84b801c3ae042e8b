"""Named image regions: their pixel masks, from the scene's geometry, and the metrics inside each.

A scene's ``[regions.*]`` (:class:`cornell_harness.scenes.model.Region`) name parts
of the image by what the camera sees there: some objects, optionally only
where they lie inside a world-space box. This module owns turning them into
pixel masks (:func:`region_masks`) and scoring an image inside each one
(:func:`region_metrics`). The metrics themselves are
:mod:`cornell_harness.evaluate.metrics`' and :mod:`cornell_harness.evaluate.noise`'s,
applied to the masked pixels; nothing here redefines them.

Masks
-----
Camera rays are cast in pure NumPy with the renderers' pinhole convention
(:meth:`Camera.frame`, :meth:`Camera.tan_half_fov`; pixel (row, col) covers
image-plane ``[col, col + 1) × [row, row + 1)``, (0, 0) top-left, as in
``src/cornell_harness/renderers/core/camera.py`` and Mitsuba 3's perspective sensor). Each pixel
is probed by a :data:`SUBPIXELS` × :data:`SUBPIXELS` grid of rays spread over
its *closed* square, corners and edges included, so neighbouring pixels
share their edge rays and the whole image is one lattice of
``(W·(k−1)+1) × (H·(k−1)+1)`` rays. Every ray finds its first hit among all
triangles (Möller & Trumbore 1997, "Fast, minimum storage ray-triangle
intersection", two-sided) and spheres. A pixel belongs to a region when
*all* its rays hit one of the region's objects (any object, if none are
named) at a point inside the region's box (if one is given): pixels that
straddle a region's boundary are left out, so a region's pixels see only it.

Why k = 4: a straight boundary that crosses a pixel but misses all 16 of
its rays can only cut off a corner with both legs under 1/3 pixel, less than
1/18 of the pixel's area; k = 8 would bring that to 1/98 at 3.7 times the
rays. At 256 × 256 the lattice is 769² ≈ 0.6 M rays, which the Cornell box's
36 triangles intersect in about 0.2 s. The intersection is brute force (every
ray against every triangle): fine for validation scenes of up to a few
thousand triangles, too slow for big meshes.

The gate and ``cbox converge`` score many images of one scene, so masks are
cached per process, keyed on the scene's content hash, its resolution and
its regions (:func:`functools.lru_cache`). The cached arrays are read-only.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Collection, Mapping

import numpy as np

from cornell_harness.evaluate import metrics
from cornell_harness.evaluate import noise
from cornell_harness.evaluate.registry import COLOUR_METRICS, REGION_METRICS, REGION_PREFIX, region_metric
from cornell_harness.scenes.model import Scene, triangle_arrays
from cornell_harness.scenes.quantities import has_colour

#: Rays per pixel along each axis (see the module docstring for why 4).
SUBPIXELS = 4
#: Elements of each (rays × triangles) temporary: 64 Ki float64 (512 KiB) stay in cache, which made the
#: Cornell box's hits 6 times faster than chunks of 32 Ki rays (measured: 0.17 s against about 1 s).
CHUNK_ELEMENTS = 1 << 16
#: Lattice rays traced per band of pixel rows: bounds the directions and hit points held at once
#: (~50 MB), so a 2048² image's 37 M rays need no gigabytes.
BAND_RAYS = 1 << 20
#: A hit this far (relative to the scene's size) outside a region's box still counts as inside it,
#: so a box face laid exactly on a surface (min y = the floor's y) keeps that surface despite rounding.
BOX_TOLERANCE = 1e-6
# REGION_METRICS (the metrics of each region, in table order) and REGION_PREFIX (their columns are
# ``region.<name>.<metric>``) live in the light metric registry, so the gate's config can check names
# without this module's imports; they are imported above and stay importable from here.


# --------------------------------------------------------------------------
# Rays and hits
# --------------------------------------------------------------------------


def lattice_directions(scene: Scene, k: int = SUBPIXELS, rows: tuple[int, int] | None = None) -> np.ndarray:
    """(H·(k−1)+1, W·(k−1)+1, 3) float64 directions (not normalised) through the image-plane lattice.

    Lattice point (i, j) is image-plane point (x, y) = (j, i) / (k − 1) in
    pixel units: pixel (row, col)'s k × k rays are points
    ``[row·(k−1) .. row·(k−1)+k−1] × [col·(k−1) .. col·(k−1)+k−1]``. The
    direction is that of ``cornell_harness.renderers.core.camera.camera_ray`` for the point.
    ``rows`` = (first, end) pixel rows gives only their lattice rows.
    """
    if k < 2:
        raise ValueError(f"need at least 2 rays per pixel axis to cover its corners, got {k}")
    cam = scene.camera
    first, end = rows if rows is not None else (0, cam.height)
    x = np.arange(cam.width * (k - 1) + 1) / (k - 1)
    y = np.arange(first * (k - 1), end * (k - 1) + 1) / (k - 1)
    return cam.directions(x[None, :], y[:, None])


def _triangle_coefficients(origin: np.ndarray, v0, v1, v2) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Möller-Trumbore for rays that all start at ``origin``: (3, T) matrices A, B, Q and (T,) c.

    With e1 = v1 − v0, e2 = v2 − v0, s = origin − v0, Möller-Trumbore's
    det = e1·(d×e2), u = s·(d×e2)/det, v = d·(s×e1)/det and t = e2·(s×e1)/det.
    By the scalar triple product det = d·(e2×e1) and s·(d×e2) = d·(e2×s), so
    with a shared origin a ray's det, u·det, v·det are d @ A, d @ B, d @ Q with
    A = e2×e1, B = e2×s, Q = s×e1, and t·det = c = e2·Q.
    """
    e1, e2, s = v1 - v0, v2 - v0, origin - v0
    q = np.cross(s, e1)
    return np.cross(e2, e1).T.copy(), np.cross(e2, s).T.copy(), q.T.copy(), np.einsum("ij,ij->i", e2, q)


def _first_triangle_hits(origin, dirs, v0, v1, v2) -> tuple[np.ndarray, np.ndarray]:
    """Nearest triangle (index, -1 if none) and its ray parameter t (inf if none) per ray; two-sided."""
    idx = np.full(len(dirs), -1, dtype=np.int64)
    best = np.full(len(dirs), np.inf)
    if len(v0) == 0:
        return idx, best
    a, b, q, c = _triangle_coefficients(origin, v0, v1, v2)
    chunk = max(64, CHUNK_ELEMENTS // len(v0))
    for lo in range(0, len(dirs), chunk):
        d = dirs[lo:lo + chunk]
        # In place on (rays, triangles) arrays: this loop is the whole cost of a mask.
        # det = 0 (ray parallel to the triangle) gives inf/NaN, which fail every test below.
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.divide(1.0, d @ a)
            u, v = d @ b, d @ q
            u *= inv
            v *= inv
            t = inv * c
            hit = u >= 0.0
            hit &= v >= 0.0
            u += v
            hit &= u <= 1.0
            hit &= t > 0.0
        np.copyto(t, np.inf, where=~hit)
        j = np.argmin(t, axis=1)
        tj = np.take_along_axis(t, j[:, None], axis=1)[:, 0]
        idx[lo:lo + chunk] = np.where(np.isfinite(tj), j, -1)
        best[lo:lo + chunk] = tj
    return idx, best


def first_hits(scene: Scene, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For camera rays ``dirs`` (n, 3): the object each hits first and the hit point.

    Objects are numbered as :meth:`Scene.object_names` lists them (meshes,
    then spheres); -1 (and a NaN point) where a ray hits nothing.
    """
    origin = np.asarray(scene.camera.position, dtype=np.float64)
    dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    arrays = triangle_arrays(scene)
    v = arrays["vertices"][arrays["triangles"]]
    tri, t = _first_triangle_hits(origin, dirs, v[:, 0], v[:, 1], v[:, 2])
    obj = np.where(tri >= 0, arrays["mesh"][np.maximum(tri, 0)], -1)
    for j, s in enumerate(scene.spheres):
        ts = s.hit_distances(origin, dirs)
        closer = ts < t
        obj, t = np.where(closer, len(scene.meshes) + j, obj), np.where(closer, ts, t)
    with np.errstate(invalid="ignore"):  # inf · 0 for rays that hit nothing
        points = np.where(np.isfinite(t)[:, None], origin + t[:, None] * dirs, np.nan)
    return obj, points


# --------------------------------------------------------------------------
# Masks
# --------------------------------------------------------------------------


def _all_in_pixel(inside: np.ndarray, k: int) -> np.ndarray:
    """(H, W) bool: every one of each pixel's k × k lattice points is ``inside``."""
    windows = np.lib.stride_tricks.sliding_window_view(inside, (k, k))[:: k - 1, :: k - 1]
    return windows.all(axis=(-2, -1))


def masks_from_hits(scene: Scene, obj: np.ndarray, points: np.ndarray, k: int = SUBPIXELS) -> dict[str, np.ndarray]:
    """Each region's (H, W) mask from the lattice's hit objects (Ly, Lx) and points (Ly, Lx, 3)."""
    names = scene.object_names()
    tol = BOX_TOLERANCE * scene.extent()
    out = {}
    for name, region in scene.regions.items():
        ids = [names.index(o) for o in region.objects]
        inside = np.isin(obj, ids) if ids else obj >= 0
        if region.box is not None:
            lo, hi = (np.asarray(b, dtype=np.float64) for b in region.box)
            with np.errstate(invalid="ignore"):  # NaN points (no hit) are outside
                inside &= np.all((points >= lo - tol) & (points <= hi + tol), axis=-1)
        out[name] = _all_in_pixel(inside, k)
    return out


@dataclass(frozen=True)
class _MaskKey:
    """What the masks depend on; the scene rides along uncompared, to compute them on a cache miss."""

    content_hash: str
    width: int
    height: int
    regions: tuple
    k: int
    scene: Scene = field(compare=False, hash=False, repr=False)


@functools.lru_cache(maxsize=16)
def _cached_masks(key: _MaskKey) -> dict[str, np.ndarray]:
    scene, k = key.scene, key.k
    cam = scene.camera
    band = max(1, BAND_RAYS // ((cam.width * (k - 1) + 1) * (k - 1)))
    parts: dict[str, list[np.ndarray]] = {name: [] for name in scene.regions}
    for first in range(0, cam.height, band):  # bands share their edge lattice row, traced twice
        dirs = lattice_directions(scene, k, (first, min(first + band, cam.height)))
        obj, points = first_hits(scene, dirs.reshape(-1, 3))
        for name, m in masks_from_hits(scene, obj.reshape(dirs.shape[:2]), points.reshape(dirs.shape), k).items():
            parts[name].append(m)
    masks = {name: np.concatenate(ms) for name, ms in parts.items()}
    for m in masks.values():
        m.setflags(write=False)  # shared by every caller of the cache
    return masks


def region_masks(scene: Scene, k: int = SUBPIXELS) -> dict[str, np.ndarray]:
    """Region name -> (H, W) bool mask at the scene's resolution, in the scene's order; {} without regions.

    Cached per process on (content hash, resolution, regions, k); the
    arrays are read-only (copy one to change it).
    """
    if not scene.regions:
        return {}
    regions = tuple((r.name, tuple(r.objects), None if r.box is None else tuple(tuple(map(float, b)) for b in r.box))
                    for r in scene.regions.values())
    key = _MaskKey(scene.content_hash(), scene.camera.width, scene.camera.height, regions, int(k), scene)
    return dict(_cached_masks(key))


# --------------------------------------------------------------------------
# Metrics inside each region
# --------------------------------------------------------------------------


def region_columns(nested: dict[str, dict]) -> dict:
    """{name: {metric: value}} as flat columns ``region.<name>.<metric>`` (a results-table row's)."""
    return {f"{REGION_PREFIX}{name}.{k}": v for name, ms in nested.items() for k, v in ms.items()}


def nested_regions(row: Mapping) -> dict[str, dict]:
    """The ``region.<name>.<metric>`` columns of a flat row as {name: {metric: value}}.

    The metric is after the last dot: metric keys have none, region names may.
    """
    out: dict[str, dict] = {}
    for key, v in row.items():
        if isinstance(key, str) and (parts := region_metric(key)) is not None:
            out.setdefault(parts[0], {})[parts[1]] = v
    return out


def region_metrics(image, reference, masks: Mapping[str, np.ndarray], spp: int | None = None,
                   variance=None, keys: Collection[str] | None = None) -> dict[str, dict[str, float]]:
    """Per region, :data:`REGION_METRICS` of ``image`` against ``reference`` on the region's pixels.

    ``reference`` is a :class:`cornell_harness.store.references.Reference` (its
    ``image``, ``variance`` of the mean and ``spp``). Per region:

    - ``pixels``: how many pixels the mask holds;
    - ``mean_radiance_rel_error``, ``rmse``, ``rel_mse``: as image-wide
      (:mod:`cornell_harness.evaluate.metrics`), on the region's pixels; broken
      pixels count as black, except in the mean radiance, which skips them;
    - ``delta_e2000_mean``: mean CIEDE2000 of the region's pixels, at the
      exposure of the *whole* reference (the one every image shares);
    - ``mean_z``: z-score of the region's mean-radiance difference
      (:func:`cornell_harness.evaluate.noise.mean_difference_z`). The difference's
      per-pixel variance is the reference's variance of its mean plus the
      image's: ``variance`` (the image's own variance of its mean) when
      given, else the noise model's at ``spp``
      (:func:`cornell_harness.evaluate.noise.render_variance`), else none (the image
      is taken as noise-free).

    An empty region has ``pixels`` 0 and NaN metrics. ``keys`` (of :data:`REGION_METRICS`) computes those
    only, with ``pixels``: each value the same as with every one (a gate's slope scores one metric per
    checkpoint, and ΔE is most of a region's cost).
    """
    img, ref = metrics.as_pair(image, reference.image)
    colour = has_colour(reference.quantity)
    wanted = [k for k in REGION_METRICS[1:] if (keys is None or k in keys) and (colour or k not in COLOUR_METRICS)]
    if "mean_z" in wanted:
        ref_var = np.asarray(reference.variance, dtype=np.float64)
        if variance is not None:
            img_var = np.asarray(variance, dtype=np.float64)
        elif spp is not None:
            img_var = noise.render_variance(ref_var, reference.spp, spp)
        else:
            img_var = 0.0
        diff_var = ref_var + img_var
    exposure = metrics.display_exposure(ref, reference.quantity) if "delta_e2000_mean" in wanted else None
    clean = metrics.zero_broken_pixels(img)
    out = {}
    for name, mask in masks.items():
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != img.shape[:2]:
            raise ValueError(f"region {name!r}: mask shape {mask.shape} does not match image shape {img.shape[:2]}")
        n = int(np.count_nonzero(mask))
        if n == 0:
            out[name] = {"pixels": 0, **{k: float("nan") for k in wanted}}
            continue
        im, rf = metrics.masked_pixels(clean, mask), metrics.masked_pixels(ref, mask)
        values = {"pixels": n}
        if "mean_radiance_rel_error" in wanted:
            values["mean_radiance_rel_error"] = metrics.mean_radiance_rel_error(metrics.masked_pixels(img, mask), rf)
        if "mean_z" in wanted:
            values["mean_z"] = noise.mean_difference_z(metrics.masked_pixels(img, mask), rf,
                                                       metrics.masked_pixels(diff_var, mask))
        if "rmse" in wanted:
            values["rmse"] = metrics.rmse(im, rf)
        if "rel_mse" in wanted:
            values["rel_mse"] = metrics.rel_mse(im, rf)
        if "delta_e2000_mean" in wanted:
            values["delta_e2000_mean"] = metrics.delta_e2000(im, rf, exposure=exposure)
        out[name] = values
    return out


def region_noise(image: np.ndarray, variance: np.ndarray, masks: Mapping[str, np.ndarray]) -> dict[str, dict]:
    """How noisy a reference is inside each region: what its provenance reports.

    ``variance`` is the per-pixel variance of ``image``'s mean. Per region,
    over its pixels and the three channels: ``mean`` (radiance), the region
    mean's relative standard error ``mean_rel_se`` (pixels independent), and
    the median per-pixel relative standard error ``pixel_rel_se_median``
    (√variance / value; a pixel of value 0 counts as 0 when its variance is 0,
    else inf). Rounded to 4 significant digits: they are for reading.
    """
    out = {}
    for name, mask in masks.items():
        n = int(np.count_nonzero(mask))
        if n == 0:
            out[name] = {"pixels": 0}
            continue
        x, v = np.asarray(image, np.float64)[mask], np.asarray(variance, np.float64)[mask]
        mean = float(x.mean())
        se = float(np.sqrt(v.sum())) / x.size
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = np.where(x > 0, np.sqrt(v) / x, np.where(v > 0, np.inf, 0.0))
        out[name] = {"pixels": n, "mean": float(f"{mean:.4g}"),
                     "mean_rel_se": float(f"{se / mean:.4g}") if mean > 0 else None,
                     "pixel_rel_se_median": float(f"{float(np.median(rel)):.4g}")}
    return out
