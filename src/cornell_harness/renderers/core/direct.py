"""Direct light at a surface point by light sampling: pbrt-v4's ``SampleLd`` (§13.4.2), written once.

One emitter sample (an emitter triangle by power, a point on it uniformly
by area: :func:`cornell_harness.renderers.core.lights.sample_emitter`) gives a shadow segment
from the shading point to the emitter point and the radiance it carries if
nothing blocks it,

    f(x, ωi) · Le(y) · cos θ_x cos θ_y / r² / p_A(y) · w,

where f is the point's BSDF (:func:`cornell_harness.renderers.core.bsdf.bsdf_eval`, so any
material the toolkit adds is evaluated here, never a fixed Lambert) and w is
1, or with ``mis`` the power heuristic (Veach 1997, eq. 9.13) of the light
sample's solid-angle pdf against the BSDF's pdf of the same direction, for a
caller that also finds the light by BSDF sampling. Delta BSDFs give 0 (the
caller does not light-sample them).

It returns scalars and the caller writes the segment
(:func:`cornell_harness.renderers.core.rays.set_shadow`), for the reason
:mod:`cornell_harness.renderers.core.rays` gives: helpers that write buffers and branch
cost reference counting and inlining in the kernels.
"""

from __future__ import annotations

from cornell_harness.renderers.core.bsdf import bsdf_eval, bsdf_pdf
from cornell_harness.renderers.core.geometry import offset_origin
from cornell_harness.renderers.core.lights import sample_emitter, solid_angle_pdf, solid_angle_pdf_along, towards_emitter
from cornell_harness.renderers.core.rays import shadow_segment
from cornell_harness.renderers.core.sampling import jit, jit_inline, power_heuristic

_NONE = ((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0))
_NONE_GEOMETRY = ((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.0, 0, 0.0, 0.0)


@jit_inline
def light_sample(x, n, mat, u, geo, mis):
    """The colour-free part of :func:`sample_ld`: ``(found, origin, direction, tfar, emitter triangle, cos θ_x,
    g)``, g = cos θ_x cos θ_y / r² / p_A · w, so that a channel (or wavelength) of radiance Le and BSDF weight
    ρ' adds ``bsdf_eval(mat, ρ', cos θ_x) · Le · g`` (:func:`unoccluded_rgb` for RGB). Used by :func:`sample_ld`
    and the path tracer, whose radiance is RGB or per wavelength (:mod:`cornell_harness.renderers.pathtracer`)."""
    if geo.emitter_ids.size == 0:
        return (False,) + _NONE_GEOMETRY
    y, ny, e, pe = sample_emitter(u[0], u[1], u[2], geo)
    wi, dist2, cos_x, cos_y = towards_emitter(x, n, y, ny)
    if not (cos_x > 0.0 and pe > 0.0):
        return (False,) + _NONE_GEOMETRY
    w = power_heuristic(solid_angle_pdf(pe, dist2, cos_y), bsdf_pdf(mat, cos_x)) if mis else 1.0
    g = cos_x * cos_y / dist2 * w / pe
    # Between the two offset points, stopping short of the light (which must not shadow itself).
    a = offset_origin(x, n, geo.offset)
    sd, tfar, sl = shadow_segment(a, offset_origin(y, ny, geo.offset))
    if not sl > 0.0:
        return (False,) + _NONE_GEOMETRY
    return True, a, sd, tfar, e, cos_x, g


@jit_inline
def sample_ld(x, n, mat, weight, u, geo, mis):
    """A light sample for shading point ``x`` (normal ``n`` on the side lit, material ``mat``).

    ``weight`` is the per-channel factor the BSDF is evaluated with (β·ρ:
    throughput times reflectance), ``u`` the three numbers (emitter pick,
    point u, point v), ``geo`` the scene tables. Returns ``(found, origin,
    direction, tfar, contribution)``: when ``found``, the shadow segment
    (:func:`cornell_harness.renderers.core.rays.shadow_segment`) and the radiance
    (3-tuple) it adds if unoccluded; every pdf division guarded (no
    emitter, a zero pdf, an emitter seen from behind: not found).
    """
    found, a, sd, tfar, e, cos_x, g = light_sample(x, n, mat, u, geo, mis)
    if not found:
        return (False,) + _NONE
    return True, a, sd, tfar, unoccluded_rgb(mat, weight, cos_x, g, geo, e)


@jit_inline
def unoccluded_rgb(mat, weight, cos_x, g, geo, e):
    """The RGB radiance a light sample of :func:`light_sample` (emitter triangle ``e``, ``cos_x``, ``g``) adds if
    unoccluded, ``bsdf_eval(mat, weight, cos θ_x) · Le · g`` per channel, ``weight`` the BSDF's (β·ρ)."""
    return (bsdf_eval(mat, weight[0], cos_x) * geo.radiance[e, 0] * g,
            bsdf_eval(mat, weight[1], cos_x) * geo.radiance[e, 1] * g,
            bsdf_eval(mat, weight[2], cos_x) * geo.radiance[e, 2] * g)


@jit
def emission_weight(pdf_bsdf, pa, t, cos_o) -> float:
    """MIS weight of emission found at distance ``t`` by a ray sampled with solid-angle pdf ``pdf_bsdf``, against
    light sampling's area pdf ``pa`` of that point (power heuristic, Veach 1997 eq. 9.13); a pdf of 0 marks a
    ray light sampling could not have made (a camera ray, a delta-BSDF sample): weight 1. The path tracer's,
    in RGB and hero-wavelength mode alike."""
    return 1.0 if pdf_bsdf == 0.0 else power_heuristic(pdf_bsdf, solid_angle_pdf_along(pa, t, cos_o))
