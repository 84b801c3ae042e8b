"""Occlusion rays: the hemisphere direction of an ambient-occlusion sample, and the segment that tests it.

Shared by our Monte Carlo ambient occlusion (:mod:`cornell_harness.renderers.ao`) and the
ambient term of :mod:`cornell_harness.renderers.ambient`, both after pbrt-v4's
``AOIntegrator`` (``src/pbrt/cpu/integrators.cpp``): at a surface point x
with normal n turned to the side the ray came from (:func:`face_forward`,
pbrt-v4's ``FaceForward(n, -d)``), one direction about n, cosine-weighted
or uniform (:func:`ao_direction`), and an occlusion segment from x along it
up to a maximum distance (:func:`occlusion_segment`), written into a
:class:`cornell_harness.renderers.core.rays.ShadowBuffer` so Embree answers a unit's
segments in one call and :func:`cornell_harness.renderers.core.rays.add_unoccluded` adds
what each carries where it is unoccluded.

For A = 1/π ∫ V cos θ dω sampled with pdf cos θ / π, and for
A = 1/(2π) ∫ V dω sampled with pdf 1/(2π), the weight over the pdf is
exactly 1: the estimate of A is the visibility V ∈ {0, 1} itself, so a
segment carries its caller's factor unchanged and no division is left to
guard.
"""

from __future__ import annotations

from cornell_harness.renderers.core.geometry import offset_origin
from cornell_harness.renderers.core.rays import set_shadow
from cornell_harness.renderers.core.sampling import cosine_hemisphere, jit, uniform_hemisphere

#: The default reach of an ambient term's occlusion rays (cornell_harness.renderers.ambient's ao_max_distance,
#: cornell_harness.renderers.whitted's ambient = ao), relative to the scene's size: 0.1441 × 3.470 (cornell-box's bounding-box
#: diagonal) = 0.500 scene units, a quarter of the box's width, the distance cornell-box-ao pins.
DEFAULT_AO_MAX_DISTANCE = 0.1441


@jit
def ao_direction(n, cosine, u1, u2):
    """The sample's direction about ``n``, drawn from the density of the scene's weighting.

    ``cosine``: pdf cos θ / π, for A = 1/π ∫ V cos θ dω; otherwise pdf 1/(2π), for
    A = 1/(2π) ∫ V dω. Either way the integrand's weight over the pdf is 1.
    """
    if cosine:
        d = cosine_hemisphere(n[0], n[1], n[2], u1, u2)
    else:
        d = uniform_hemisphere(n[0], n[1], n[2], u1, u2)
    return d[0], d[1], d[2]


@jit
def face_forward(n, cos_o):
    """``n`` turned to the side the camera ray came from (``cos_o = -d·n``): pbrt-v4's FaceForward(n, -d).

    The hemisphere is on the side the camera sees, so a surface seen from its
    back is not black (:mod:`cornell_harness.scenes.quantities`).
    """
    return n if cos_o >= 0.0 else (-n[0], -n[1], -n[2])


# Straight-line code over scalars and one buffer, as src/cornell_harness/renderers/core/rays.py's writers: the only branch
# is ao_direction's, on a scalar, so callers' kernels inline it without per-call reference counting.
@jit
def occlusion_segment(occ, k, x, n, cosine, u, tfar, offset, path, value):
    """Segment ``k`` of ``occ``: from ``x`` (offset along unit ``n``, the side to test) along the direction
    :func:`ao_direction` draws from ``u`` (u1, u2), up to ``tfar``, for ``path``, carrying the 3-tuple ``value``."""
    w = ao_direction(n, cosine, u[0], u[1])
    set_shadow(occ, k, offset_origin(x, n, offset), w, tfar, path, value)
