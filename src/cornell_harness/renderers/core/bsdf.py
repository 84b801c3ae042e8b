"""Materials: the BSDF interface our integrators call, and its implementations.

A material is an integer type id per primitive (:func:`material_tables`,
stored on :class:`cornell_harness.renderers.core.geometry.SceneGeometry` as ``material``)
plus that primitive's parameters: an RGB triple ``rho`` (a diffuse albedo or
a mirror's reflectance) and a relative index of refraction ``eta``.
Integrators call the dispatchers, which branch on the id (pbrt-v4 §9.1
``BSDF``; the same four questions):

- :func:`bsdf_eval` — f(ωo, ωi) for the pair's cosine with the normal;
- :func:`bsdf_sample` — a direction ωi, its cosine, and the sample's weight
  f·cos/pdf per channel (exact where it simplifies: ρ for Lambert);
- :func:`bsdf_pdf` — the solid-angle pdf of sampling ωi;
- :func:`is_delta` — whether f is a Dirac delta (mirror, glass): then it
  cannot be evaluated or hit by light sampling, so an integrator skips
  next-event estimation there, and :func:`bsdf_pdf` says 0, by which the
  emission the sampled ray finds counts with weight 1 (Veach 1997 §9.2.4).

The one-sided rule (Mitsuba's ``diffuse`` and ``conductor``, which the
references use): a non-transmissive BSDF reflects only on the side its
geometric normal points to. A ray arriving from the back side gets nothing
and ends its path (:func:`two_sided` says where this does not hold: glass),
and directions below the surface have f = 0 and pdf 0.

The maths of each material is cited where it is written: Lambert
(pbrt-v4 §9.2), the mirror (§9.3 with Fresnel factor 1), the dielectric
(Mitsuba 3 ``dielectric``; pbrt-v4 §9.3 and §9.5, :func:`fresnel_dielectric`).
"""

from __future__ import annotations

import math

import numpy as np

from cornell_harness.scenes.materials import Dielectric, Diffuse, Mirror
from cornell_harness.scenes.model import Scene
from cornell_harness.renderers.core.sampling import INV_PI, cosine_hemisphere, jit, jit_inline

#: Material type ids (int8 per primitive).
LAMBERT = 0
MIRROR = 1
DIELECTRIC = 2
_TYPE_IDS = {Diffuse: LAMBERT, Mirror: MIRROR, Dielectric: DIELECTRIC}


def material_tables(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per object (meshes, then spheres): type id (int8), ``rho`` (O, 3) and ``eta`` (O,).

    ``rho`` is a diffuse material's albedo or a mirror's reflectance (1 for
    glass), ``eta`` the dielectric's int_ior / ext_ior (1 otherwise).
    ValueError for a material we do not model.
    """
    ids, rho, eta = [], [], []
    for obj in scene.meshes + scene.spheres:
        mat = scene.materials[obj.material]
        if type(mat) not in _TYPE_IDS:
            raise ValueError(f"material {obj.material!r}: {type(mat).__name__} is not supported")
        ids.append(_TYPE_IDS[type(mat)])
        rho.append(getattr(mat, "reflectance", (1.0, 1.0, 1.0)))
        eta.append(mat.eta if isinstance(mat, Dielectric) else 1.0)
    return np.asarray(ids, np.int8), np.asarray(rho, np.float64).reshape(-1, 3), np.asarray(eta, np.float64)


# -- Lambertian ---------------------------------------------------------------------

@jit
def lambert_eval(rho, cos) -> float:
    """f = ρ/π above the surface, 0 below (one-sided).

    f is linear in ρ: a caller may pass β·ρ (throughput times reflectance)
    to get β·f with the rounding of ``β·ρ/π``, as the pinned images want.
    """
    return rho * INV_PI if cos > 0.0 else 0.0


@jit
def lambert_pdf(cos) -> float:
    """Solid-angle pdf cos θ/π of the cosine-weighted sample; 0 below the surface."""
    return cos * INV_PI if cos > 0.0 else 0.0


@jit
def lambert_sample(n, u1, u2):
    """A cosine-weighted direction about unit normal ``n``: (dx, dy, dz, cos θ). Weight f·cos/pdf = ρ."""
    return cosine_hemisphere(n[0], n[1], n[2], u1, u2)


# -- Smooth mirror and dielectric ------------------------------------------------------

@jit
def reflect(wo, n, cos_o):
    """Mirror direction of ``wo`` (unit, pointing away from the surface) about unit ``n``; ``cos_o = wo·n``."""
    k = 2.0 * cos_o
    return k * n[0] - wo[0], k * n[1] - wo[1], k * n[2] - wo[2]


@jit
def refract(wo, n, cos_o, cos_t, eta_ti):
    """Snell refraction of ``wo`` through the surface: ``-η_ti·wo + (η_ti·cos_o + cos_t)·n``.

    ``cos_t`` (from :func:`fresnel_dielectric`) has the opposite sign of
    ``cos_o``; ``eta_ti`` is η_incident/η_transmitted (Mitsuba 3 ``refract``,
    pbrt-v4 eq. 9.4).
    """
    k = eta_ti * cos_o + cos_t
    return k * n[0] - eta_ti * wo[0], k * n[1] - eta_ti * wo[1], k * n[2] - eta_ti * wo[2]


@jit
def fresnel_dielectric(cos_i, eta):
    """Unpolarised Fresnel reflectance of a smooth dielectric interface: (R, cos θt, η_it, η_ti).

    ``cos_i`` is the incident direction's cosine with the front-side normal
    (negative from inside), ``eta`` = η_int/η_ext. R is the mean of the
    squared s- and p-polarised amplitude ratios (Fresnel's equations,
    pbrt-v4 eq. 9.5-9.6, written as Mitsuba 3's ``fresnel``); past the
    critical angle sin²θt > 1, cos θt = 0 and R = 1 (total internal
    reflection). An index-matched interface (η = 1) has R = 0, and grazing
    incidence (cos_i = 0) R = 1.
    """
    eta_it = eta if cos_i >= 0.0 else 1.0 / eta
    eta_ti = 1.0 / eta_it
    cos_t_sqr = 1.0 - eta_ti * eta_ti * (1.0 - cos_i * cos_i)
    ci = abs(cos_i)
    ct = math.sqrt(cos_t_sqr) if cos_t_sqr > 0.0 else 0.0
    if eta == 1.0:
        r = 0.0
    elif ci == 0.0:
        r = 1.0
    else:
        a_s = (eta_it * ct - ci) / (eta_it * ct + ci)
        a_p = (eta_it * ci - ct) / (eta_it * ci + ct)
        r = 0.5 * (a_s * a_s + a_p * a_p)
    return r, (-ct if cos_i >= 0.0 else ct), eta_it, eta_ti


@jit
def dielectric_sample(wo, n, cos_o, eta, u):
    """Reflect with probability R, else refract: (ωi, cos θi with n, weight, valid).

    Choosing by R makes the weight 1 for reflection; a refracted ray carries
    (η_ti)², the change of radiance across the interface in radiance
    transport (Veach 1997 §5.2; Mitsuba 3 ``dielectric::sample``). Total
    internal reflection is R = 1: always reflected, never absorbed.
    """
    if not cos_o != 0.0:
        return (0.0, 0.0, 1.0), 0.0, 0.0, False
    r, cos_t, eta_it, eta_ti = fresnel_dielectric(cos_o, eta)
    if u < r:
        return reflect(wo, n, cos_o), cos_o, 1.0, True
    return refract(wo, n, cos_o, cos_t, eta_ti), cos_t, eta_ti * eta_ti, True


@jit
def refraction_scale(material, cos_o, cos_w, eta) -> float:
    """The (η_ti)² radiance factor in the weight of a sample from ``cos_o`` to ``cos_w``: ≠ 1 only across glass.

    Integrators keep the product of these along a path so that Russian
    roulette can discount it (Mitsuba 3's ``path`` uses throughput·η²): a
    path inside glass carries radiance scaled by 1/η², which says nothing
    about how much it will still contribute once it leaves.
    """
    if material == DIELECTRIC and cos_o * cos_w < 0.0:
        eta_ti = 1.0 / eta if cos_o > 0.0 else eta
        return eta_ti * eta_ti
    return 1.0


# -- dispatch on the material id ------------------------------------------------------

@jit
def is_delta(material) -> bool:
    """f is a Dirac delta: no light sampling there, and no MIS against it."""
    return material != LAMBERT


@jit
def two_sided(material) -> bool:
    """Light arriving from the back side is scattered (glass), not absorbed (one-sided rule)."""
    return material == DIELECTRIC


@jit
def faces(material, cos_o) -> bool:
    """Whether a surface hit at ``cos_o`` (negative: from behind) can reflect or emit: its front side, or
    either side of a two-sided one. One-sided emitters and BSDFs give nothing on their back (or grazing)."""
    return cos_o > 0.0 or (cos_o < 0.0 and two_sided(material))


@jit
def bsdf_eval(material, rho, cos) -> float:
    """f of one channel with reflectance ``rho`` (or β·ρ, see :func:`lambert_eval`); 0 for delta BSDFs."""
    if material == LAMBERT:
        return lambert_eval(rho, cos)
    return 0.0


@jit
def bsdf_pdf(material, cos) -> float:
    """Solid-angle pdf of :func:`bsdf_sample` returning a direction at cosine ``cos``; 0 for delta BSDFs."""
    if material == LAMBERT:
        return lambert_pdf(cos)
    return 0.0


@jit_inline
def bsdf_sample(material, n, wo, cos_o, rho, eta, u1, u2):
    """Sample ωi given ``wo`` (unit, away from the surface, ``cos_o = wo·n``).

    Returns (ωi (3-tuple), cos θi with ``n`` (negative: transmitted),
    weight f·|cos|/pdf per channel (3-tuple), valid). Invalid samples end the
    path.
    """
    if material == LAMBERT:
        dx, dy, dz, cos = lambert_sample(n, u1, u2)
        return (dx, dy, dz), cos, rho, cos > 0.0
    if material == MIRROR:
        return reflect(wo, n, cos_o), cos_o, rho, cos_o > 0.0
    if material == DIELECTRIC:
        wi, cos, w, ok = dielectric_sample(wo, n, cos_o, eta, u1)
        return wi, cos, (w, w, w), ok
    return (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), False
