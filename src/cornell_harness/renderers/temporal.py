"""Temporal accumulation with reprojection: each frame blended into the reprojected history, as in TAA.

The stage ``<renderer>+temporal`` (``pathtracer+temporal``), after temporal
anti-aliasing (Karis 2014, "High Quality Temporal Supersampling", SIGGRAPH
course; Salvi 2016, "An Excursion in Temporal Supersampling", GDC) and the
temporal half of SVGF (Schied et al. 2017, §4.1). Frame i's image is

    H_i = α · C_i + (1 − α) · clamp(H_{i−1} reprojected)

where the history reprojects (:func:`cornell_harness.renderers.core.motion.reproject`:
motion vectors, bilinear taps, disocclusion rejection by object, depth and
normal), and a pixel without history takes C_i alone. ``alpha`` is the weight
of the new frame (TAA's 0.1; SVGF's 0.2).

**Neighbourhood clamping** (setting ``clamp``) keeps a history that no longer
matches the scene (a light that moved, a surface uncovered by a wrong motion
vector) from lingering: it is limited to a box in colour space made of the
current frame's 3 × 3 neighbourhood, ``minmax`` its per-channel minimum and
maximum (Karis 2014), ``variance`` the mean ± γ standard deviations (Salvi
2016, γ = ``clip_gamma``), ``none`` not at all.

**Closed form** (the test of this module): on a static scene with nothing
clamped, every pixel's frames are independent with variance σ², and the
stationary variance of H is α² σ² / (1 − (1 − α)²) = α/(2 − α) · σ².
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from cornell_harness.adapters.api import Setting
from cornell_harness.renderers.core.motion import reproject
from cornell_harness.renderers.core.frames import Frame, TemporalStage

CLAMPS = ("minmax", "variance", "none")


def neighbourhood(image: np.ndarray) -> np.ndarray:
    """(9, H, W, C): each pixel's 3 × 3 neighbourhood (edge pixels repeated at the image's border)."""
    h, w = image.shape[:2]
    padded = np.pad(image, ((1, 1), (1, 1), (0, 0)), mode="edge")
    return np.stack([padded[dy:dy + h, dx:dx + w] for dy in range(3) for dx in range(3)])


def clamp_history(history: np.ndarray, current: np.ndarray, clamp: str, gamma: float = 1.0) -> np.ndarray:
    """``history`` limited to the colour box of ``current``'s 3 × 3 neighbourhood (module docstring)."""
    if clamp == "none":
        return history
    n = neighbourhood(current)
    if clamp == "minmax":
        lo, hi = n.min(axis=0), n.max(axis=0)
    else:
        mean, sd = n.mean(axis=0), n.std(axis=0)
        lo, hi = mean - gamma * sd, mean + gamma * sd
    return np.clip(history, lo, hi)


def accumulate(current: np.ndarray, history: np.ndarray, valid: np.ndarray, alpha: float) -> np.ndarray:
    """α · current + (1 − α) · history where ``valid``, else current: the exponential moving average."""
    return np.where(valid[..., None], alpha * current + (1.0 - alpha) * history, current)


class TemporalAccumulation(TemporalStage):
    """``<renderer>+temporal`` (module docstring) around ``base``."""

    suffix = "temporal"
    OWN_SETTINGS = (
        Setting("alpha", float, 0.1, "weight of the new frame in the exponential moving average (TAA 0.1; the "
                "noise variance tends to alpha/(2 - alpha) of one frame's)", low=0.001, high=1.0),
        Setting("clamp", str, "minmax", "neighbourhood clamping of the history: minmax (Karis 2014), variance "
                "(Salvi 2016) or none", choices=CLAMPS),
        Setting("clip_gamma", float, 1.0, "the variance box's half-width in standard deviations (Salvi 2016)",
                low=0.1, high=10.0),
    )
    citations = ('Karis 2014, "High Quality Temporal Supersampling" (SIGGRAPH course)',
                 'Salvi 2016, "An Excursion in Temporal Supersampling" (GDC)')
    approximation = ("frames blended by an exponential moving average of reprojected history (TAA): lags "
                     "behind changes, ghosts where the history is wrong; biased")

    def step(self, history: dict, frame: Frame, prev: Frame | None, settings: Mapping[str, Any]):
        current = np.asarray(frame.result.image, dtype=np.float64)
        if prev is None:
            image, valid = current, np.zeros(current.shape[:2], bool)
        else:
            old, valid = reproject(history["image"], frame.motion, prev.gbuffer, frame.gbuffer, prev.offsets,
                                   frame.offsets)
            old = clamp_history(old, current, settings["clamp"], settings["clip_gamma"])
            image = accumulate(current, old, valid, settings["alpha"])
        history["image"] = image
        return image, {"history_fraction": round(float(valid.mean()), 4)}


class PathTracerTemporal(TemporalAccumulation):
    """``pathtracer+temporal``: our path tracer (:mod:`cornell_harness.renderers.pathtracer`), accumulated over frames."""

    def __init__(self, threads: int | None = None):
        from cornell_harness.renderers.pathtracer import PathTracer

        super().__init__(PathTracer(threads), threads)
