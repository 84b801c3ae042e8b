"""Monte Carlo ambient occlusion: one visibility ray per sample from the first surface a pixel sees.

Estimates the quantity an ``ambient_occlusion`` scene pins
(:mod:`cornell_harness.scenes.quantities`): at the first surface point x a camera ray
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
:meth:`cornell_harness.renderers.core.geometry.SceneGeometry.unoccluded`, which tests them
after Embree's triangles.

Random numbers: a sample makes two decisions, each with named dimensions of
its own layout, drawn from the ``sampler`` setting's stream (as
:mod:`cornell_harness.renderers.core.sampler` describes): the pixel jitter of the toolkit's
camera rays (dimensions 0-1, :data:`cornell_harness.renderers.core.sampler.CAMERA_U` and
``CAMERA_V``), then the direction (the sampler's block ``AO_DIRECTION``: ``AO_U``, ``AO_V``),
each a 2D draw; no other decision. The
image depends on the seed only, bit for bit, for any thread count
(:mod:`cornell_harness.renderers.core.schedule`); passes double, so power-of-two checkpoints
are free.

With a low-discrepancy sampler the reported variance (:func:`pooled_variance`)
is the Bernoulli form scaled by a locally pooled stratification gain, not the
film's 8-batch estimate: see there why. With independent samples it is the
film's, the Bernoulli one with n − 1 degrees of freedom.

Numerics: float64 maths; the occlusion ray leaves from ``x + offset·n``
with the toolkit's scene-scaled offset (:func:`cornell_harness.renderers.core.geometry.offset_origin`),
and Embree gets float32 copies of it and of ``tfar = max_distance``.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from cornell_harness.adapters.api import RenderResult
from cornell_harness.scenes.model import Scene
from cornell_harness.renderers.core.adapter import ToolkitRenderer, warmed_geometry
from cornell_harness.renderers.core.camera import camera_basis, camera_rays
from cornell_harness.renderers.core.geometry import SceneGeometry, ray_hit
from cornell_harness.renderers.core.occlusion import face_forward, occlusion_segment
from cornell_harness.renderers.core.rays import add_unoccluded, head, ray_buffer, shadow_buffer
from cornell_harness.renderers.core.sampler import AO_U, Stream, independent, path_point, sample_2d, sampler_setting
from cornell_harness.renderers.core.sampling import jit
from cornell_harness.renderers.core.schedule import render_image
from cornell_harness.renderers.core.settings import with_defaults


@jit
def ao_sample(stream, path):
    """The two numbers (u1, u2) in [0, 1)² that pick sample ``path``'s direction."""
    return sample_2d(stream, path_point(stream, path), AO_U)


# One kernel for the whole sample, as the path tracer's _shade: it reads and writes the buffers itself
# (helpers that take arrays and branch cost reference counting and inlining, src/cornell_harness/renderers/core/rays.py).
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
#: Two pixels are alike when their stabilised means differ by at most this many standard deviations of the
#: difference (:func:`alike_pixels`).
ALIKE_SIGMAS = 3.0


def shifted(a: np.ndarray, dy: int, dx: int) -> tuple[np.ndarray, np.ndarray]:
    """``a`` (axes 0-1 an image) moved so that ``out[y, x] = a[y + dy, x + dx]``, 0 where that is outside the
    image; and where it is inside (a mask that broadcasts against ``a``)."""
    h, w = a.shape[:2]
    out = np.zeros_like(a)
    inside = np.zeros((h, w) + (1,) * (a.ndim - 2), bool)
    src = slice(max(dy, 0), h + min(dy, 0)), slice(max(dx, 0), w + min(dx, 0))
    dst = slice(max(-dy, 0), h + min(-dy, 0)), slice(max(-dx, 0), w + min(-dx, 0))
    out[dst] = a[src]
    inside[dst] = True
    return out, inside


def stabilised(mean: np.ndarray, n: int) -> np.ndarray:
    """Anscombe's arcsine root of a mean of ``n`` samples in [0, 1], asin √((n·mean + 3/8)/(n + 3/4)).

    Anscombe (1948, "The transformation of Poisson, binomial and
    negative-binomial data", Biometrika 35, 246-254): for a binomial count its
    variance is about 1/(4n) whatever the mean, near 0 and 1 too, where the
    mean's own variance vanishes. Samples of variance below the Bernoulli one
    (Bhatia-Davis, :func:`pooled_variance`), or stratified, give less.
    """
    return np.arcsin(np.sqrt(np.clip((n * np.asarray(mean, np.float64) + 0.375) / (n + 0.75), 0.0, 1.0)))


def alike_pixels(mean: np.ndarray, n: int, radius: int, sigmas: float = ALIKE_SIGMAS) -> dict:
    """For each offset (dy, dx) of the (2·radius + 1)² window: where pixel (y + dy, x + dx) is inside the image,
    alike pixel (y, x), and joined to it by a path of such pixels that steps between 4-neighbours.

    Two pixels are alike when their :func:`stabilised` means differ by at
    most ``sigmas``·√(2/(4n)), ``sigmas`` standard deviations of the
    difference of two independent ones: two pixels of the same AO are called
    unlike with probability at most 0.27% at 3 (normal approximation), and
    less where stratification helps. In the stabilised scale a step near 1
    weighs more than one near ½, as it does in the Bernoulli form: AO 0.9
    against 1 is 3.6 σ apart at 64 spp, 0.19 against 0.9 is 8.9 σ. The path:
    4-neighbour steps cannot cross a line of unlike pixels, even a diagonal
    one a pixel wide (an edge as a renderer draws it, 8-connected), so the
    two sides of an edge stay apart even where their AO is alike. Each
    pixel's own window; the centre is always its own.
    """
    ry, rx = min(radius, mean.shape[0] - 1), min(radius, mean.shape[1] - 1)
    offsets = [(dy, dx) for dy in range(-ry, ry + 1) for dx in range(-rx, rx + 1)]
    a = stabilised(mean, n)
    like = {}
    for dy, dx in offsets:
        a_j, inside = shifted(a, dy, dx)
        like[dy, dx] = inside & (np.abs(a - a_j) <= sigmas / np.sqrt(2.0 * n))
    reach = {o: np.zeros_like(like[o]) for o in offsets}
    reach[0, 0] = like[0, 0]
    grew = True
    while grew:  # each round adds a step to the paths: at most (2·radius + 1)² rounds, a few in practice
        grew = False
        for dy, dx in offsets:
            near = [reach[o] for o in ((dy - 1, dx), (dy + 1, dx), (dy, dx - 1), (dy, dx + 1)) if o in reach]
            more = like[dy, dx] & ~reach[dy, dx] & np.logical_or.reduce(near)
            if more.any():
                reach[dy, dx], grew = reach[dy, dx] | more, True
    return reach


def pooled_variance(mean: np.ndarray, batch_var: np.ndarray, n: int, exact: np.ndarray | None = None,
                    mean_radius: int = MEAN_RADIUS, gain_radius: int = GAIN_RADIUS,
                    sigmas: float = ALIKE_SIGMAS) -> np.ndarray:
    """The variance of each pixel's AO mean of ``n`` samples, from its mean and the film's unbiased estimate.

    Why not the film's estimate itself: with the pmj02 sampler (Christensen,
    Kensler & Kilpatrick 2018, "Progressive Multi-Jittered Sample Sequences",
    Computer Graphics Forum 37(4)) it comes from 8 independent batches (batch
    means: the spread of independently randomised replicates), 7 degrees of
    freedom, so z = d/√v̂ has Student-t tails (E z² = 7/5 even where v̂ is
    right); and where AO is nearly 0 or 1 a pixel's batches often all agree,
    v̂ = 0 while the truth is not, and |z| reaches 10 and more (docs/ambient-occlusion.md).

    What it reports: v = ĝ · B, with

    - B = p̄(1 − p̄)/n, the Bernoulli form. By the Bhatia-Davis inequality
      (Bhatia & Davis 2000, Amer. Math. Monthly 107, 353-357) p(1 − p)/n is
      the largest variance of the mean of n independent samples in [0, 1]
      with mean p: our estimates are 0, 1 or the miss value. p̄ is the mean
      of the pixels about it (3×3 less itself) that are alike it
      (:func:`alike_pixels`) and not ``exact``, moved off 0 and 1 by half a sample (Jeffreys' prior):
      p̄ = (k + ½)/(mn + 1) with k = n·ΣĀ over those m. Not the pixel's own
      mean: near 0 and 1 its own draw decides its error and, through
      p̂(1 − p̂), its variance together (a pixel at AO 0.995 reads 1 with 73%
      chance at 64 spp, error 0.005 and variance 0; one that drew a 0 has
      error 0.011 and 3 times the true variance), so z would be small where
      the error is large and infinite where it is small. The neighbours'
      mean is independent of the pixel's samples, and where they are not all
      0 or 1 the pixel gets a variance even when all its own samples agreed.
      A pixel with no alike neighbour (a one-pixel feature, or one whose
      own draw was far off) takes all its neighbours that are not exact,
      still independent of its own samples, and one without any its own
      mean, (nĀ + ½)/(n + 1).
    - ĝ = Σ v̂ / Σ B over the pixels of the 5×5 window about it that are
      alike it (:func:`alike_pixels`; itself included): the stratification
      gain. pmj02 samples are stratified, so the true variance of the mean
      is *below* the independent bound (measured on cornell-box-ao at 64
      spp, by AO band: 0.26-0.75 of it); reporting B alone would overstate
      it up to 4×, which the gate's variance check fails and which hides
      biases. v̂ is unbiased (the spread of independent batch means, 0
      where the batches happened to agree), so ĝ is a ratio estimate with
      up to 25 × 7 degrees of freedom, and over a group of alike pixels Σ v ≈ Σ v̂: the pooling
      moves variance between them but neither adds nor removes any, which is
      what makes it honest on average. Pixels known to be ``exact`` (every
      sample a miss) carry no variance and are left out. A window where no
      v̂ is above 0 has no evidence of the gain: ĝ is then the whole image's,
      and 1 where nothing varies anywhere (the independent bound:
      conservative).

    Why only alike pixels: the gain depends on what a pixel covers, and the
    Bernoulli form on its AO. Measured on cornell-box-ao (64 seeds, 64 spp),
    the pixels the ceiling's front edge crosses (AO 0.19) gain 0.55 from
    stratification, their neighbours on either side (AO 0.94 and 0.90) about
    0.7 and 0.2. Pooled over the whole window, as this did before, the edge
    pixels reported half their variance (z spread 1.38 over 8 seeds), the
    pixels beside an edge took a Bernoulli form from the other side's AO
    (2-3× too large), and pixels near AO 1 two rows from the floor's edge had
    their gain pooled down to 0.06 by it and read |z| up to 31 where they
    drew a rare 0. Pooling over the alike pixels joined to it, a pixel pools
    along an edge and not across it.

    Its limits. Two surfaces of alike AO but different gains that meet
    without a line of unlike pixels between them still pool together; and
    within two pixels of an edge where AO rises steeply to 1 (0.94, 0.994,
    0.998 in three rows under the ceiling) pixels are alike (1.8σ) while
    their Bernoulli forms differ 10×, so those rows still over- or
    understate about 4× and 1.6× one by one, which their band's spread
    averages. The pixels of a diagonal line a pixel wide are joined to none
    of each other (4-neighbour steps): each takes its gain from its own
    batches, 7 degrees of freedom, unbiased but with Student-t tails.

    A pixel that is exact (AO exactly 1 beyond ``max_distance``) still
    reports the variance of half a sample in its neighbours' 8n,
    ĝ·(½/(8n+1))((8n+½)/(8n+1))/n (ĝ × 1.5e-5 at 64 spp), as a pixel at AO
    0.9995 that happened to read 1 must; it agrees with the reference
    exactly, and the variance check leaves pixels with d = 0 out. Measured
    (``benchmarks/variance_honesty.py``, docs/gate-detection.md): the spread
    of z per AO band over 8 seeds on cornell-box-ao is 0.950-1.031 in every
    band, 1.023 in [0.1, 0.2) (1.38 pooled across edges), largest |z| 18.4
    (26.5 before).
    """
    mean = np.asarray(mean, np.float64)
    batch_var = np.asarray(batch_var, np.float64)
    exact = np.zeros(mean.shape, bool) if exact is None else np.asarray(exact, bool)
    total, count = np.zeros_like(mean), np.zeros_like(mean)  # over the alike neighbours
    total_all, count_all = np.zeros_like(mean), np.zeros_like(mean)  # over all of them
    for (dy, dx), joined in alike_pixels(mean, n, mean_radius, sigmas).items():
        if (dy, dx) != (0, 0):
            m_j, inside = shifted(mean, dy, dx)
            inside = inside & ~shifted(exact, dy, dx)[0]
            total, count = total + np.where(joined & inside, m_j, 0.0), count + (joined & inside)
            total_all, count_all = total_all + np.where(inside, m_j, 0.0), count_all + inside
    alone = count == 0  # no alike neighbour: all of them; none at all: its own mean
    total, count = np.where(alone, total_all, total), np.where(alone, count_all, count)
    total, count = np.where(count == 0, mean, total), np.where(count == 0, 1.0, count)
    p_bar = (n * total + 0.5) / (n * count + 1.0)
    bound = np.where(exact, 0.0, np.clip(p_bar * (1.0 - p_bar), 0.0, None) / n)
    num, den = np.zeros_like(mean), np.zeros_like(mean)
    for (dy, dx), joined in alike_pixels(mean, n, gain_radius, sigmas).items():
        num += np.where(joined, shifted(batch_var, dy, dx)[0], 0.0)
        den += np.where(joined, shifted(bound, dy, dx)[0], 0.0)
    fallback = batch_var.sum() / bound.sum() if batch_var.sum() > 0 else 1.0  # the image's gain; none without evidence
    gain = np.divide(num, den, out=np.full_like(num, fallback), where=(den > 0) & (num > 0))
    return gain * bound


class AORenderer(ToolkitRenderer):
    """Our ambient occlusion renderer (Embree, batched queries, multithreaded): the scene's AO, unbiased."""

    name = "ao"
    citations = (
        'Pharr, Jakob and Humphreys 2023, "Physically Based Rendering", 4th ed. (pbrt-v4), AOIntegrator',)
    estimator = "unbiased"
    stops_early = True
    quantities = ("ambient_occlusion",)
    settings = (sampler_setting("the camera rays and their occlusion rays (one sequence per pixel)", "pmj02",
                                batches=False),)

    def render(self, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = (),
               settings: dict | None = None, stop=None) -> RenderResult:
        if scene.quantity != "ambient_occlusion" or scene.ambient_occlusion is None:
            # The runner never gets here (cornell_harness.adapters.registry.missing_features); a direct call might.
            raise ValueError(f"{scene.name}: the ao renderer computes ambient occlusion, and this scene's "
                             f"quantity is {scene.quantity}")
        geom, setup_s = warmed_geometry(scene, lambda g: trace_ao(g, scene, 0, 1, 1, independent(0)))
        result = render_image(scene, spp, seed, lambda *unit: trace_ao(geom, scene, *unit), checkpoints,
                              self.threads, sampler=with_defaults(self.settings, settings)["sampler"], stop=stop)
        if result.variance is not None and result.info.get("batches", 1) > 1:  # independent: Bernoulli already
            # A pixel at the miss value whose samples all agree saw nothing (an occluded surface point reads
            # the miss value 0 only inside a closed pocket): exact, variance 0, whatever its neighbours.
            exact = (result.image == scene.ambient_occlusion.miss_value) & (result.variance == 0)
            result.variance = pooled_variance(result.image, result.variance, result.spp, exact).astype(np.float32)
        result.info.update(rays=geom.rays, setup_s=round(setup_s, 3))
        return result
