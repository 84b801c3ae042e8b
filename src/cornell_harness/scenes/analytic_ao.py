"""Ambient occlusion with analytic answers: a floor point beside walls.

A point on a floor (normal up) with infinite vertical walls around it, each
a plane at distance ``d`` from the point in the horizontal direction of
azimuth ``φ_w`` (the walls bound a convex room that holds the point, so a
ray's first wall is the first plane it crosses). A ray of polar angle θ and
azimuth φ crosses wall i at distance t_i = d_i / (sin θ · cos(φ − φ_i)) when
it heads towards it, always above the floor, so it is occluded within the
maximum distance R when sin θ ≥ s(φ) = min_i d_i / (R cos(φ − φ_i)).

The θ integral is then closed-form (:mod:`cornell_harness.scenes.quantities` for the
two weightings):

- cosine: (1/π) ∫ cos θ sin θ dθ over [θ0, π/2] = (1 − s²) / (2π) per unit azimuth;
- uniform: (1/2π) ∫ sin θ dθ over [θ0, π/2] = √(1 − s²) / (2π);

and the azimuth integral is done by quadrature (:func:`scipy.integrate.quad`),
which the issue asks for, split where the integrand has kinks. Known values
it reproduces (tests/renderers/test_ao.py): A = 1 in an open plane, A = 1/2 beside one
wall and 1/4 in a corner when R is infinite, whatever the distances; and
the closed form of one wall under cosine weighting,
:func:`cosine_ao_beside_wall`.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from scipy.integrate import quad


def _min_ratio(phi: float, walls: Sequence[tuple[float, float]], max_distance: float) -> float:
    """s(φ) of the module docstring, capped at 1 (1: nothing within reach)."""
    s = 1.0
    for d, azimuth in walls:
        c = math.cos(phi - azimuth)
        if c > 0.0:
            s = min(s, d / (max_distance * c)) if math.isfinite(max_distance) else 0.0
    return s


def ao_beside_walls(walls: Sequence[tuple[float, float]], max_distance: float = math.inf,
                    weighting: str = "cosine") -> float:
    """AO of a floor point with infinite vertical walls at ``(distance, azimuth)`` around it, by quadrature."""
    if weighting not in ("cosine", "uniform"):
        raise ValueError(f"unknown weighting {weighting!r}")

    def occluded_part(phi: float) -> float:
        s = _min_ratio(phi, walls, max_distance)
        return (1.0 - s * s) / (2.0 * math.pi) if weighting == "cosine" else math.sqrt(1.0 - s * s) / (2.0 * math.pi)

    # Kinks: where a wall starts to face the ray (cos = 0) and where the reach d/(R cos) crosses 1.
    points = []
    for d, azimuth in walls:
        for k in (-1, 1):
            points.append(azimuth + k * math.pi / 2)
            if math.isfinite(max_distance) and d < max_distance:
                points.append(azimuth + k * math.acos(d / max_distance))
    points = sorted({p % (2.0 * math.pi) for p in points} | {0.0, 2.0 * math.pi})
    occluded = sum(quad(occluded_part, a, b, epsabs=1e-12, epsrel=1e-10, limit=200)[0]
                   for a, b in zip(points[:-1], points[1:]) if b > a)
    return 1.0 - occluded


def cosine_ao_beside_wall(distance, max_distance: float = math.inf):
    """Closed form of one wall, cosine weighting: A = 1 − (1/π)(acos(x) − x√(1 − x²)), x = d/R (x ≥ 1: 1).

    The azimuth integral of (1 − x²/cos²φ)/2 over |φ| < acos x, which
    :func:`ao_beside_walls` does by quadrature; vectorised over ``distance``.
    """
    d = np.asarray(distance, dtype=np.float64)
    if not math.isfinite(max_distance):
        return np.where(d >= 0, 0.5, np.nan)
    x = np.clip(d / max_distance, 0.0, 1.0)
    return 1.0 - (np.arccos(x) - x * np.sqrt(1.0 - x * x)) / math.pi
