"""Area emitters: sampling them by power, their pdfs, and the one-sided rule.

Every emitter of ours is a triangle of a mesh with a ``radiance``: a
one-sided diffuse area light (Mitsuba's ``area`` emitter, pbrt-v4's
``DiffuseAreaLight`` §12.5 without ``twosided``). It emits radiance Le
into the hemisphere its normal points to and nothing behind it.

Sampling (pbrt-v4 §12.6 ``PowerLightSampler`` and §6.5.4 for the point):
a triangle is picked in proportion to its power π·A·Le, weighted by the
mean of the three channels, then a point uniformly by area. The area pdf of
a point on triangle t is therefore ``P(t) / A(t) = mean(Le_t) / Σ A·mean(Le)``,
one number per triangle (:class:`Emitters.pdf_area`, zero for
non-emitters): the same number whether the point was sampled (next-event
estimation) or found by a ray (the MIS weight of BSDF sampling).

Integrators need it per unit solid angle at the receiver:
``p_ω = p_A · r² / cos θ_y`` (dω = cos θ_y dA / r², pbrt-v4 §4.2.3),
:func:`solid_angle_pdf`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from cornell_harness.renderers.core.sampling import jit, triangle_barycentrics


class Emitters(NamedTuple):
    """Tables to sample emitter triangles (all float64 except ``ids``)."""

    ids: np.ndarray  # (E,) int64: the emitter triangles
    cdf: np.ndarray  # (E,) over ids, by power; cdf[-1] == 1 exactly (empty: no emitter)
    pdf_area: np.ndarray  # (T,) per triangle of the scene: area pdf of a point on it, 0 for non-emitters


def emitter_tables(area: np.ndarray, radiance: np.ndarray) -> Emitters:
    """Sampling tables from per-triangle areas (T,) and emitted radiance (T, 3)."""
    weight = area * radiance.mean(axis=1)
    ids = np.flatnonzero(weight > 0)
    total = float(weight.sum())
    pdf_area = np.zeros(len(area))
    if total > 0:
        pdf_area[ids] = radiance[ids].mean(axis=1) / total
        cdf = np.cumsum(weight[ids]) / total
        cdf[-1] = 1.0
    else:
        cdf = np.zeros(0)
    return Emitters(ids, cdf, pdf_area)


@jit
def sample_emitter(u0, u1, u2, g):
    """A point on an emitter: (point, emitter normal, triangle, area pdf); the scene must have one.

    ``u0`` picks the triangle by power, ``(u1, u2)`` the point on it.
    ``g`` holds the triangle tables (``v0``, ``e1``, ``e2``, ``normal``) and
    the emitter tables (``emitter_ids``, ``emitter_cdf``, ``light_pdf_area``):
    :meth:`cornell_harness.renderers.core.geometry.SceneGeometry.tables`. Straight-line code
    on purpose (see :mod:`cornell_harness.renderers.core.rays`): callers check
    ``g.emitter_ids.size > 0``.
    """
    e = g.emitter_ids[min(np.searchsorted(g.emitter_cdf, u0, side="right"), g.emitter_ids.size - 1)]
    b1, b2 = triangle_barycentrics(u1, u2)
    v0, e1, e2 = g.v0, g.e1, g.e2
    y = (v0[e, 0] + b1 * e1[e, 0] + b2 * e2[e, 0],
         v0[e, 1] + b1 * e1[e, 1] + b2 * e2[e, 1],
         v0[e, 2] + b1 * e1[e, 2] + b2 * e2[e, 2])
    return y, (g.normal[e, 0], g.normal[e, 1], g.normal[e, 2]), e, g.light_pdf_area[e]


@jit
def emitter_cos(ny, w) -> float:
    """cos θ_y at an emitter point with normal ``ny``, towards a receiver it is seen from along unit ``w``.

    The one-sided rule: the emitter sends light only where this is > 0
    (:func:`emits`); its back side is black.
    """
    return -(ny[0] * w[0] + ny[1] * w[1] + ny[2] * w[2])


@jit
def emits(cos_y) -> bool:
    """One-sided emitters: light leaves only the side the normal points to (grazing, cos 0, gives none)."""
    return cos_y > 0.0


@jit
def towards_emitter(x, n, y, ny):
    """From a receiver at ``x`` (unit normal ``n``) to an emitter point ``y`` (normal ``ny``).

    Returns (unit direction, distance², cos θ_x, cos θ_y). cos θ_x is 0 when
    no light passes: coincident points, the emitter seen from its back side
    (:func:`emits`), or the receiver facing away. Next-event estimation's
    geometry term is ``cos θ_x cos θ_y / r²`` from these.
    """
    w0, w1, w2 = y[0] - x[0], y[1] - x[1], y[2] - x[2]
    dist2 = w0 * w0 + w1 * w1 + w2 * w2
    if not dist2 > 0.0:
        return (0.0, 0.0, 1.0), 0.0, 0.0, 0.0
    dist = math.sqrt(dist2)
    wi = (w0 / dist, w1 / dist, w2 / dist)
    cos_x = n[0] * wi[0] + n[1] * wi[1] + n[2] * wi[2]
    cos_y = emitter_cos(ny, wi)
    if not (cos_x > 0.0 and emits(cos_y)):
        return wi, dist2, 0.0, cos_y
    return wi, dist2, cos_x, cos_y


@jit
def solid_angle_pdf(pdf_area, dist2, cos_y) -> float:
    """Area pdf → solid angle at the receiver, ``p_A · r² / cos θ_y``; 0 where the emitter faces away."""
    return pdf_area * dist2 / cos_y if cos_y > 0.0 else 0.0


@jit
def solid_angle_pdf_along(pdf_area, t, cos_y) -> float:
    """:func:`solid_angle_pdf` for a point found at distance ``t`` along a unit ray (r² = t·t).

    Kept apart because ``p_A·t·t`` and ``p_A·(t·t)`` round differently: the
    pinned images depend on this exact product.
    """
    return pdf_area * t * t / cos_y if cos_y > 0.0 else 0.0
