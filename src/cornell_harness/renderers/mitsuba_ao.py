"""Ambient occlusion in Mitsuba 3: a wavefront integrator in Python, for scenes of quantity ``ambient_occlusion``.

Mitsuba 3.9 has no AO integrator (mitsuba-renderer/mitsuba3 issue #372), so
this one is scripted on Mitsuba's ray-tracing API as its tutorial "Scripting a
renderer" (https://mitsuba.readthedocs.io/en/stable/src/rendering/scripting_renderer.html)
does, and estimates what pbrt-v4's ``AOIntegrator`` (src/pbrt/cpu/integrators.cpp)
estimates, with the definition the scene pins (:mod:`cornell_harness.scenes.quantities`):

- a camera ray per sample through a uniformly jittered point of its pixel
  (``Sensor.sample_ray``: the box filter of the radiance path's ``mi.render``),
  and ``Scene.ray_intersect``; a ray that hits nothing gives ``miss_value``;
- at the hit, one direction from ``mi.warp.square_to_cosine_hemisphere``
  (cosine weighting: f/pdf = (V cos θ/π) / (cos θ/π) = V, pbrt's ``cossample``)
  or ``square_to_uniform_hemisphere`` (uniform: (V/2π) / (1/2π) = V), in the
  frame of the geometric normal ``si.n`` or the shading normal ``si.sh_frame.n``,
  flipped to the side the camera ray came from (pbrt's ``FaceForward(n, -ray.d)``),
  so a back face is not black;
- ``si.spawn_ray`` (Mitsuba's offset along the normal, towards the sampled side)
  with ``maxt`` the scene's maximum distance, then ``Scene.ray_test``: V = 1
  when nothing is hit within it.

Each sample's estimate is V (or ``miss_value``); a pixel is the mean over its
samples, grey in three channels, with the variance of that mean from the
per-pixel sums of values and squares (as :mod:`cornell_harness.renderers.core.film`).

Distances: the scene is loaded in the adapter's unit frame
(:func:`cornell_harness.scenes.transforms.unit_frame`: moved and scaled by ``k`` = 1/extent),
so the maximum distance in scene units becomes ``max_distance · k`` there.

Determinism: sample j of a pass looks through pixel ``j // n`` (n samples per
pixel in the pass) and draws from Mitsuba's ``independent`` sampler seeded with
the pass's 32-bit seed (:func:`cornell_harness.adapters.api.pass_seed`) for a
wavefront of the pass's size; sums are taken in NumPy (float64, fixed order),
so an image depends only on the seed, the spp and the checkpoints' boundaries.
Needs a JIT variant (``llvm_ad_rgb``): the scalar variant would trace one ray
per Python call.
"""

from __future__ import annotations

import math

import numpy as np

from cornell_harness.scenes.model import Scene


def unit_max_distance(scene: Scene, scale: float) -> float:
    """The scene's AO maximum distance in Mitsuba's unit frame (scene units × ``scale``); inf stays inf."""
    return scene.ambient_occlusion.max_distance * scale


def ao_values(mi_scene, sensor, sampler, ao, maxt: float, width: int, height: int, n: int):
    """One estimate per sample of a wavefront of ``width·height·n`` samples, pixel ``j // n`` for sample j.

    Returns a Mitsuba ``Float`` (lazy): V of one occlusion ray, or the miss value.
    """
    import drjit as dr
    import mitsuba as mi

    j = dr.arange(mi.UInt32, width * height * n)
    pixel = j // dr.opaque(mi.UInt32, n)  # opaque: one kernel for every pass size
    w = dr.opaque(mi.UInt32, width)
    col, row = mi.Float(pixel % w), mi.Float(pixel // w)
    film = mi.Point2f((col + sampler.next_1d()) / width, (row + sampler.next_1d()) / height)
    ray, _ = sensor.sample_ray(0.0, 0.5, film, mi.Point2f(0.5))
    si = mi_scene.ray_intersect(ray)
    return occlusion_estimate(mi_scene, si, ray, sampler.next_2d(), ao, maxt)


def occlusion_estimate(mi_scene, si, ray, u, ao, maxt: float):
    """V for one hemisphere direction from ``u`` at ``si`` (``miss_value`` where the camera ray missed)."""
    import drjit as dr
    import mitsuba as mi

    normal = si.n if ao.normal == "geometric" else si.sh_frame.n
    normal = dr.select(dr.dot(normal, ray.d) < 0.0, normal, -normal)  # towards the camera
    warp = mi.warp.square_to_cosine_hemisphere if ao.weighting == "cosine" else mi.warp.square_to_uniform_hemisphere
    shadow = si.spawn_ray(mi.Frame3f(normal).to_world(warp(u)))
    if math.isfinite(maxt):
        shadow.maxt = mi.Float(maxt)
    hit = si.is_valid()
    blocked = mi_scene.ray_test(shadow, hit)
    return dr.select(hit, dr.select(blocked, 0.0, 1.0), mi.Float(ao.miss_value))


def ao_pass(mi_scene, scene: Scene, maxt: float, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel sums of the estimates and of their squares over one pass of ``n`` spp, float64 (H·W,)."""
    import drjit as dr
    import mitsuba as mi

    cam = scene.camera
    sensor = mi_scene.sensors()[0]
    sampler = sensor.sampler().fork()
    size = cam.width * cam.height * n
    sampler.seed(dr.opaque(mi.UInt32, seed), size)
    values = ao_values(mi_scene, sensor, sampler, scene.ambient_occlusion, maxt, cam.width, cam.height, n)
    x = np.asarray(values, dtype=np.float64).reshape(cam.width * cam.height, n)
    return x.sum(axis=1), (x * x).sum(axis=1)


def mean_and_variance(s1: np.ndarray, s2: np.ndarray, n: int,
                      shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray | None]:
    """Grey (H, W, 3) float32 mean of ``n`` samples per pixel and the variance of that mean (None for n = 1)."""
    mean = s1 / n
    grey = lambda a: np.repeat(a.reshape(*shape, 1), 3, axis=2).astype(np.float32)  # noqa: E731
    if n < 2:
        return grey(mean), None
    return grey(mean), grey(np.maximum(s2 / n - mean * mean, 0.0) / (n - 1))
