"""Monte Carlo ambient occlusion: one visibility ray per sample from the first surface a pixel sees.

Estimates the quantity an ``ambient_occlusion`` scene pins
(:mod:`harness.scenes.quantities`): at the first surface point x a camera ray
finds, with n the normal on the side the camera sees,

- ``cosine``:  A(x) = 1/π ∫_H V(x, ω) cos θ dω   (ambient occlusion),
- ``uniform``: A(x) = 1/(2π) ∫_H V(x, ω) dω      (obscurance with a step falloff),

where H is the hemisphere about n, θ the angle to n, and V(x, ω) = 1 when the
ray from x along ω meets nothing nearer than the scene's ``max_distance``
(which may be inf); a camera ray that hits nothing gives the scene's
``miss_value``. A pixel is the box-filtered mean over its footprint, written
to all three channels.

What it follows is pbrt-v4's ``AOIntegrator`` (its source,
``src/pbrt/cpu/integrators.cpp``, ``AOIntegrator::Li``; the hemisphere
samplings it calls are the book's §A.5.2-A.5.3): a camera ray, its first
hit, the geometric normal turned to face the incoming ray
(``FaceForward(isect.n, -ray.d)``), **one** direction per sample,
cosine-weighted or uniform over the hemisphere, and an occlusion ray up to
the maximum distance. Where it differs:

- pbrt-v4 weights a direction by cos θ / (π p(ω)) whichever way it was
  sampled, so both of its samplings estimate the cosine-weighted A. Here the
  scene's weighting chooses the integral, and each is sampled by its own
  density: cosine-weighted directions (p = cos θ / π) for A = 1/π ∫ V cos θ,
  uniform ones (p = 1/(2π)) for A = 1/(2π) ∫ V. In both the weight
  (cos θ / π or 1 / (2π)) over the pdf is exactly 1, so the estimate is V ∈
  {0, 1} itself: no division is left to guard, and with independent samples
  a pixel's variance is the Bernoulli one, Ā(1 − Ā)/n (what
  tests/renderers/test_ao.py tests against).
- A miss gives ``miss_value`` (pbrt-v4 returns no radiance: ``miss_value = 0``).
- Our flat triangles and analytic spheres have no shading normal distinct
  from the geometric one, so the scene's ``normal`` (geometric or shading)
  selects the same n.

Every surface occludes, whatever its material: mirrors, glass and emitters
are geometry to an AO ray (pbrt-v4 skips only surfaces without a BSDF,
medium boundaries, which our scenes have none of). Spheres occlude through
:meth:`renderers.core.geometry.SceneGeometry.unoccluded`, which tests them
after Embree's triangles.

Random numbers: a sample makes two decisions, each with named dimensions of
its own layout, drawn from the ``sampler`` setting's stream (as
:mod:`renderers.core.sampler` describes): the pixel jitter of the toolkit's
camera rays (dimensions 0-1, :data:`renderers.core.sampler.CAMERA_U` and
``CAMERA_V``), then the direction (:data:`AO_U`, :data:`AO_V`), each a 2D draw. The
image depends on the seed only, bit for bit, for any thread count
(:mod:`renderers.core.schedule`); passes double, so power-of-two checkpoints
are free.

With a low-discrepancy sampler the reported variance (:func:`pooled_variance`)
is the Bernoulli form scaled by a locally pooled stratification gain, not the
film's 8-batch estimate: see there why. With independent samples it is the
film's, the Bernoulli one with n − 1 degrees of freedom.

Numerics: float64 maths; the occlusion ray leaves from ``x + offset·n``
with the toolkit's scene-scaled offset (:func:`renderers.core.geometry.offset_origin`),
and Embree gets float32 copies of it and of ``tfar = max_distance``.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from harness.adapters.api import RenderResult
from harness.scenes.model import Scene
from renderers.core.adapter import ToolkitRenderer, warmed_geometry
from renderers.core.camera import camera_basis, camera_rays
from renderers.core.geometry import SceneGeometry, ray_hit
from renderers.core.occlusion import face_forward, occlusion_segment
from renderers.core.rays import add_unoccluded, head, ray_buffer, shadow_buffer
from renderers.core.sampler import CAMERA_DIMS, SAMPLER_SETTING, Stream, independent, path_point, sample_2d
from renderers.core.sampling import jit
from renderers.core.schedule import render_image
from renderers.core.settings import with_defaults

#: A sample's layout: the pixel jitter (CAMERA_U, CAMERA_V: dimensions 0 and 1, drawn by the toolkit's
#: camera rays), then the AO direction's two numbers; no other decision, so AO_DIMS dimensions in all.
AO_U = CAMERA_DIMS
AO_V = CAMERA_DIMS + 1
AO_DIMS = CAMERA_DIMS + 2


@jit
def ao_sample(stream, path):
    """The two numbers (u1, u2) in [0, 1)² that pick sample ``path``'s direction."""
    return sample_2d(stream, path_point(stream, path), AO_U)


# One kernel for the whole sample, as the path tracer's _shade: it reads and writes the buffers itself
# (helpers that take arrays and branch cost reference counting and inlining, renderers/core/rays.py).
class Occlusion(NamedTuple):
    """What an occlusion ray tests, from the scene's ``ambient_occlusion`` (module docstring)."""

    cosine: bool  # cosine-weighted directions (AO); otherwise uniform (obscurance)
    tfar: float  # an occluder counts only if nearer than this (inf: any)
    miss: float  # the estimate of a camera ray that hits nothing


@jit
def _occlusion_rays(prim, t_sphere, rays, stream, first, ao, geo, A, occ):
    """For camera ray i of a unit (hit ``prim[i]``, -1: missed), its occlusion ray, into ``occ``.

    A miss writes ``ao.miss`` into ``A[i]``; a hit leaves ``A[i]`` at 0 and writes
    one segment from the offset hit point along the sampled direction, up to
    ``ao.tfar``, carrying 1 in every channel (added where unoccluded). Random
    numbers are drawn for sample ``first + i``. Returns the number of segments.
    """
    k = 0
    for i in range(prim.size):
        p = prim[i]
        if p < 0:
            for c in range(3):
                A[i, c] = ao.miss
            continue
        _, x, n0, cos_o, _, _ = ray_hit(geo, rays, i, p, t_sphere)
        n = face_forward(n0, cos_o)
        u = ao_sample(stream, first + i)
        occlusion_segment(occ, k, x, n, ao.cosine, u, ao.tfar, geo.offset, i, (1.0, 1.0, 1.0))
        k += 1
    return k


def trace_ao(geom: SceneGeometry, scene: Scene, first: int, stop: int, pixels: int, stream: Stream) -> np.ndarray:
    """AO estimates (m, 3): 0, 1 or the miss value, for samples ``first .. stop-1`` (j sees pixel j mod ``pixels``)."""
    ao = scene.ambient_occlusion
    m = stop - first
    cam = scene.camera
    rays = ray_buffer(m)
    camera_rays(camera_basis(cam), cam.width, cam.height, first, pixels, stream, rays)
    prim, t_sphere = geom.closest_hits(rays)  # Embree's triangles, then the spheres (float64)
    A = np.zeros((m, 3))
    occ = shadow_buffer(m)
    tfar = ao.max_distance  # an occluder counts only if nearer than this (inf: any)
    k = _occlusion_rays(prim, t_sphere, rays, stream, first,
                        Occlusion(ao.weighting == "cosine", float(tfar), float(ao.miss_value)), geom.tables(), A, occ)
    seg = head(occ, k)
    add_unoccluded(A, seg, geom.unoccluded(seg.o, seg.d, seg.t))
    return A


#: Half-widths of the windows of :func:`pooled_variance`: the neighbours' mean's (3×3) and the gain's (5×5).
MEAN_RADIUS = 1
GAIN_RADIUS = 2


def box_sum(a: np.ndarray, radius: int) -> np.ndarray:
    """Sum of ``a`` over the (2·radius + 1)² window about each pixel (axes 0-1), clipped at the image border."""
    pad = ((1, 0), (1, 0)) + ((0, 0),) * (a.ndim - 2)
    c = np.cumsum(np.cumsum(np.pad(np.asarray(a, np.float64), pad), axis=0), axis=1)
    h, w = a.shape[:2]
    y0, y1 = np.clip(np.arange(h) - radius, 0, h), np.clip(np.arange(h) + radius + 1, 0, h)
    x0, x1 = np.clip(np.arange(w) - radius, 0, w), np.clip(np.arange(w) + radius + 1, 0, w)
    return c[y1][:, x1] - c[y0][:, x1] - c[y1][:, x0] + c[y0][:, x0]


def pooled_variance(mean: np.ndarray, batch_var: np.ndarray, n: int, exact: np.ndarray | None = None,
                    mean_radius: int = MEAN_RADIUS, gain_radius: int = GAIN_RADIUS) -> np.ndarray:
    """The variance of each pixel's AO mean of ``n`` samples, from its mean and the film's unbiased estimate.

    Why not the film's estimate itself: with the pmj02 sampler it comes from 8
    independent batches, 7 degrees of freedom, so z = d/√v̂ has Student-t
    tails (E z² = 7/5 even where v̂ is right); and where AO is nearly 0 or 1 a
    pixel's batches often all agree, v̂ = 0 while the truth is not, and |z|
    reaches 10 and more (issue 29).

    What it reports: v = ĝ · B, with

    - B = p̄(1 − p̄)/n, the Bernoulli form. By the Bhatia-Davis inequality
      (Bhatia & Davis 2000, Amer. Math. Monthly 107, 353-357) p(1 − p)/n is
      the largest variance of the mean of n independent samples in [0, 1]
      with mean p: our estimates are 0, 1 or the miss value. p̄ is the mean
      of the 8 pixels about it (3×3 less itself), moved off 0 and 1 by half a
      sample (Jeffreys' prior): p̄ = (k + ½)/(8n + 1) with k = n·ΣĀ over
      them. Not the pixel's own mean: near 0 and 1 its own draw decides its
      error and, through p̂(1 − p̂), its variance together (a pixel at AO
      0.995 reads 1 with 73% chance at 64 spp, error 0.005 and variance 0;
      one that drew a 0 has error 0.011 and 3 times the true variance), so z
      would be small where the error is large and infinite where it is small.
      The neighbours' mean is independent of the pixel's samples, and where
      they are not all 0 or 1 the pixel gets a variance even when all its own
      samples agreed.
    - ĝ = Σ v̂ / Σ B over the 5×5 pixels about it: the stratification gain.
      pmj02 samples are stratified, so the true variance of the mean is
      *below* the independent bound (measured on cornell-box-ao at 64 spp, by
      AO band: 0.26-0.75 of it); reporting B alone would overstate it up to
      4×, which the gate's variance check fails and which hides biases. v̂ is
      unbiased (the spread of independent batch means, 0 where the batches
      happened to agree), so ĝ is a ratio estimate with about 25 × 7 degrees
      of freedom, and over each window Σ v ≈ Σ v̂: the pooling moves variance
      between neighbours but neither adds nor removes any, which is what
      makes it honest on average. Pixels known to be ``exact`` (every sample
      a miss) carry no variance and are left out. A window where no v̂ is
      above 0 has no evidence of the gain: ĝ is then the whole image's, and
      1 where nothing varies anywhere (the independent bound: conservative).

    A pixel that is exact (AO exactly 1 beyond ``max_distance``) still
    reports the variance of half a sample in its neighbours' 8n,
    ĝ·(½/(8n+1))((8n+½)/(8n+1))/n (ĝ × 1.5e-5 at 64 spp), as a pixel at AO
    0.9995 that happened to read 1 must; it agrees with the reference
    exactly, and the variance check leaves pixels with d = 0 out. Measured
    (``benchmarks/variance_honesty.py``, docs/gate-detection.md): the spread
    of z per AO band over 8 seeds on cornell-box-ao is 0.92-1.01 in every band
    from 0.2 up; 1.29 in [0.1, 0.2), 39 pixels along the ceiling's front edge
    half outside the box, whose neighbours' gain is lower than theirs.
    """
    mean = np.asarray(mean, np.float64)
    batch_var = np.asarray(batch_var, np.float64)
    count = n * (box_sum(np.ones(mean.shape[:2] + (1,) * (mean.ndim - 2)), mean_radius) - 1.0)
    p_bar = (n * (box_sum(mean, mean_radius) - mean) + 0.5) / (count + 1.0)  # the neighbours' mean, not its own
    bound = np.clip(p_bar * (1.0 - p_bar), 0.0, None) / n
    exact = np.zeros(mean.shape, bool) if exact is None else np.asarray(exact, bool)
    bound = np.where(exact, 0.0, bound)
    num, den = box_sum(batch_var, gain_radius), box_sum(bound, gain_radius)
    fallback = batch_var.sum() / bound.sum() if batch_var.sum() > 0 else 1.0  # the image's gain; none without evidence
    gain = np.divide(num, den, out=np.full_like(num, fallback), where=(den > 0) & (num > 0))
    return gain * bound


class AORenderer(ToolkitRenderer):
    """Our ambient occlusion renderer (Embree, batched queries, multithreaded): the scene's AO, unbiased."""

    name = "ao"
    estimator = "unbiased"
    quantities = ("ambient_occlusion",)
    settings = (SAMPLER_SETTING,)

    def render(self, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = (),
               settings: dict | None = None) -> RenderResult:
        if scene.quantity != "ambient_occlusion" or scene.ambient_occlusion is None:
            # The runner never gets here (harness.adapters.registry.missing_features); a direct call might.
            raise ValueError(f"{scene.name}: the ao renderer computes ambient occlusion, and this scene's "
                             f"quantity is {scene.quantity}")
        geom, setup_s = warmed_geometry(scene, lambda g: trace_ao(g, scene, 0, 1, 1, independent(0)))
        result = render_image(scene, spp, seed, lambda *unit: trace_ao(geom, scene, *unit), checkpoints,
                              self.threads, sampler=with_defaults(self.settings, settings)["sampler"])
        if result.variance is not None and result.info.get("batches", 1) > 1:  # independent: Bernoulli already
            # A pixel at the miss value whose samples all agree saw nothing (an occluded surface point reads
            # the miss value 0 only inside a closed pocket): exact, variance 0, whatever its neighbours.
            exact = (result.image == scene.ambient_occlusion.miss_value) & (result.variance == 0)
            result.variance = pooled_variance(result.image, result.variance, spp, exact).astype(np.float32)
        result.info.update(rays=geom.rays, setup_s=round(setup_s, 3))
        return result
