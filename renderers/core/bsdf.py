"""Materials: the BSDF interface our integrators call, and its implementations.

A material is an integer type id per triangle (:func:`material_types`,
stored on :class:`renderers.core.geometry.SceneGeometry` as ``material``)
plus that triangle's parameters (today the reflectance ρ). Integrators call
the dispatchers, which branch on the id, so a new material (mirror, glass)
is a new id, its functions, and a branch in each dispatcher
(pbrt-v4 §9.1 ``BSDF``; the same four questions):

- :func:`bsdf_eval` — f(ωo, ωi) for the pair's cosine with the normal;
- :func:`bsdf_sample` — a direction ωi, its cosine, and the sample's weight
  f·cos/pdf (per channel, exact where it simplifies: ρ for Lambert);
- :func:`bsdf_pdf` — the solid-angle pdf of sampling ωi;
- :func:`is_delta` — whether f is a Dirac delta (perfect mirror, glass):
  then it cannot be evaluated or hit by light sampling, and an integrator
  must skip next-event estimation there and weight emission found by the
  sampled ray by 1.

The one-sided rule (Mitsuba's ``diffuse``, which the references use): a
non-transmissive BSDF reflects only on the side its geometric normal points
to. A ray arriving from the back side gets nothing and ends its path, and
directions below the surface have f = 0 and pdf 0. All cosines here are with
that normal, so "below" is cos ≤ 0.

Lambertian (pbrt-v4 §9.2 ``DiffuseBxDF``): f = ρ/π, sampled
cosine-weighted with pdf cos θ/π (:func:`renderers.core.sampling.cosine_hemisphere`),
so the sample weight f·cos θ/pdf is exactly ρ.
"""

from __future__ import annotations

import numpy as np

from harness.scenes.model import Diffuse, Scene
from renderers.core.sampling import INV_PI, cosine_hemisphere, jit

#: Material type ids (int8 per triangle). Only Lambert today.
LAMBERT = 0


def material_types(scene: Scene, mesh_of_triangle: np.ndarray) -> np.ndarray:
    """Type id per triangle, from its mesh's material; ValueError for a material we do not model."""
    ids = []
    for m in scene.meshes:
        mat = scene.materials[m.material]
        if not isinstance(mat, Diffuse):
            raise ValueError(f"material {m.material!r}: {type(mat).__name__} is not supported")
        ids.append(LAMBERT)
    return np.asarray(ids, dtype=np.int8)[mesh_of_triangle]


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


# -- dispatch on the material id ------------------------------------------------------

@jit
def is_delta(material) -> bool:
    """f is a Dirac delta: no light sampling there, and no MIS against it."""
    return False


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


@jit
def bsdf_sample(material, n, rho, u1, u2):
    """(direction (3-tuple), cos θ, weight f·cos/pdf per channel (3-tuple)); cos ≤ 0 means no sample."""
    if material == LAMBERT:
        dx, dy, dz, cos = lambert_sample(n, u1, u2)
        return (dx, dy, dz), cos, rho
    return (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0)
