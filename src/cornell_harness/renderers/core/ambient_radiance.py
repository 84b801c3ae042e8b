"""The constant ambient radiance of Cohen et al. 1988, computed from the scene alone: written once.

Cohen, Chen, Wallace and Greenberg 1988, "A Progressive Refinement Approach
to Fast Radiosity Image Generation" (SIGGRAPH '88), §4: the light not yet
computed is one ambient radiance per channel,

    La = Φ/(π·A_total) · Σ_{k=1..K} ρ̄^k   (K = ∞: ρ̄/(1 − ρ̄) · Φ/(π·A_total)),

with ρ̄ = Σ ρ_i A_i / A_total the area-weighted mean reflectance (ρ: a diffuse
albedo, a mirror's reflectance, 1 for lossless glass), Φ = Σ π·Le_i·A_i the
emitters' power (one-sided Lambertian) and A_total every primitive's area
(spheres 4πr²), for a renderer that computes direct light exactly and
stands for the K ≥ 1 reflections after it with this constant. The derivation
and what it ignores are in :mod:`cornell_harness.renderers.ambient`'s docstring (``ambient =
radiosity``); :mod:`cornell_harness.renderers.whitted` uses the same constant for its
``ambient = constant``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from cornell_harness.scenes.model import Scene
from cornell_harness.renderers.core.geometry import SceneGeometry


class Surfaces(NamedTuple):
    """Every primitive of a scene as the radiosity ambient sees it (float64, N = triangles + spheres)."""

    area: np.ndarray  # (N,)
    reflectance: np.ndarray  # (N, 3) fraction of incident power sent on: albedo, mirror R, 1 for glass
    radiance: np.ndarray  # (N, 3) emitted Le (one-sided Lambertian), 0 for non-emitters


class RadiosityAmbient(NamedTuple):
    """The terms of Cohen et al.'s ambient (module docstring), per channel."""

    mean_reflectance: np.ndarray  # (3,) ρ̄ = Σ ρ_i A_i / A_total
    power: np.ndarray  # (3,) Φ = Σ π Le_i A_i
    total_area: float

    def radiance(self, bounces) -> np.ndarray:
        """La for ``bounces`` reflections (K, scalar or array (m,); inf: unbounded): shape (3,) or (m, 3)."""
        k = np.asarray(bounces, np.float64)
        s = interreflection_sum(self.mean_reflectance, k[..., None])
        # No emitter: no ambient, also where the series diverges (0 · inf is not computed into the result).
        with np.errstate(invalid="ignore"):
            return np.where(self.power > 0.0, s * self.power / (math.pi * self.total_area), 0.0)


def scene_surfaces(geom: SceneGeometry) -> Surfaces:
    """The areas, power-fractions and emission of every primitive, from the toolkit's tables."""
    area = np.concatenate([geom.area, 4.0 * math.pi * geom.sphere_radius ** 2])
    return Surfaces(area, np.asarray(geom.reflectance, np.float64), np.asarray(geom.radiance, np.float64))


def radiosity_ambient(surfaces: Surfaces) -> RadiosityAmbient:
    """ρ̄, Φ and A_total of Cohen et al.'s ambient term (module docstring)."""
    a = surfaces.area
    total = float(a.sum())
    rho_bar = (surfaces.reflectance * a[:, None]).sum(axis=0) / total  # the loader refuses zero-area scenes
    power = math.pi * (surfaces.radiance * a[:, None]).sum(axis=0)
    return RadiosityAmbient(rho_bar, power, total)


def interreflection_sum(rho: np.ndarray, bounces: np.ndarray) -> np.ndarray:
    """Σ_{k=1..K} ρ^k, elementwise (K ≥ 0 whole, or inf): ρ(1 − ρ^K)/(1 − ρ), and K where ρ = 1 (inf if K is)."""
    rho, k = np.broadcast_arrays(np.asarray(rho, np.float64), np.asarray(bounces, np.float64))
    out = np.empty(rho.shape)
    one = rho >= 1.0
    # 1 − ρ is guarded: the closed form only where ρ < 1; ρ^inf = 0 there.
    with np.errstate(over="ignore"):
        out[~one] = rho[~one] * (1.0 - rho[~one] ** k[~one]) / (1.0 - rho[~one])
    out[one] = k[one]
    return out


def bounces_left(scene: Scene, depth: np.ndarray) -> np.ndarray:
    """K = max_depth − depth − 1 (at least 0) reflections an ambient path may make; inf when unbounded."""
    if scene.max_depth < 0:
        return np.full(np.shape(depth), np.inf)
    return np.maximum(scene.max_depth - np.asarray(depth) - 1, 0).astype(np.float64)
