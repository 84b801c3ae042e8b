"""Temporal metrics of a rendered sequence against its per-frame references: flicker, lag and ghosting.

Pure functions of arrays (frames first: ``(F, H, W, 3)`` images, ``(F,)`` error series); the registry
(:mod:`cornell_harness.evaluate.registry`) names and defines each once, and the sequence workflow
(:mod:`cornell_harness.workflows.sequence_run`) computes them. Per-frame errors are the one scorer's
(:func:`cornell_harness.evaluate.score.score_image`), frame by frame.

- **flicker** (:func:`flicker`): the RMS over pixels, channels and consecutive frame pairs of the frame-to-frame
  change of the signed error image e_i = image_i − reference_i (linear radiance). The reference's own change
  cancels out, so a renderer that follows a moving light exactly does not flicker; what is left is noise that is
  not held from frame to frame, and jumps. Its **floor** (:func:`flicker_floor`) is the same figure for two
  independent reference-quality sequences A and B: with V_i the reference's per-pixel variance of its mean at
  frame i and frames independent, (A_i − B_i) − (A_{i−1} − B_{i−1}) has variance 2·(V_i + V_{i−1}), so the
  floor's expected mean square is the mean of 2·(V_i + V_{i−1}) over pixels, channels and pairs, and the floor
  is its square root (the RMS of an estimate of it lies slightly below, by Jensen's inequality, negligibly so
  over many pixels).
- **lag** (:func:`lag`): after a change frame c (the last frame of a motion, after which the scene rests, or a
  switch: :func:`settle_frames`), the number of frames k until the per-frame error is back in its steady-state
  band, mean ± :data:`BAND_SDS` standard deviations of the last :data:`STEADY_FRACTION` of the frames, and stays
  there for :data:`HOLD_FRAMES` frames (one frame inside the band by chance does not end the lag). A stateless
  renderer's lag is 0 up to chance; an exponential history of weight α on the new frame decays as (1 − α)^k.
- **ghosting** (:func:`ghosting`): the RMSE (linear radiance) of the frames over the pixels that the motion
  uncovered, the disocclusion masks of the reference's motion
  (:func:`cornell_harness.evaluate.disocclusion.disocclusion_mask`): where a history reprojected from the previous
  frame has nothing valid, a temporal method shows its ghosts.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

#: The steady-state band of :func:`lag` is the mean ± this many standard deviations of the steady frames' errors.
BAND_SDS = 2.0
#: The steady frames of :func:`lag`: this last fraction of the sequence.
STEADY_FRACTION = 1.0 / 3.0
#: Frames in a row inside the band that end the lag.
HOLD_FRAMES = 3


def _frames(images) -> np.ndarray:
    return np.asarray(images, dtype=np.float64)


def error_images(images, references) -> np.ndarray:
    """The signed error images (F, H, W, C) float64: image − reference per frame, linear radiance."""
    images, references = _frames(images), _frames(references)
    if images.shape != references.shape:
        raise ValueError(f"images {images.shape} and references {references.shape} differ in shape")
    return images - references


def flicker(images, references) -> float:
    """RMS of the frame-to-frame change of the error image (module docstring); NaN for fewer than two frames."""
    e = error_images(images, references)
    if len(e) < 2:
        return math.nan
    return float(np.sqrt(np.mean(np.diff(e, axis=0) ** 2)))


def flicker_floor(variances) -> float:
    """The expected flicker of two independent sequences of reference quality, from the reference's per-frame
    variance of its mean (F, H, W, C): sqrt(mean of 2·(V_i + V_{i−1})) (module docstring); NaN for one frame."""
    v = _frames(variances)
    if len(v) < 2:
        return math.nan
    return float(np.sqrt(np.mean(2.0 * (v[1:] + v[:-1]))))


def steady_band(errors: Sequence[float]) -> tuple[float, float, int]:
    """(low, high, first frame) of the steady-state band: mean ± :data:`BAND_SDS` sd (ddof 1) of the per-frame
    errors of the last :data:`STEADY_FRACTION` of the frames (at least 2), which start at the first frame given."""
    e = np.asarray(errors, dtype=np.float64)
    n = max(2, int(round(len(e) * STEADY_FRACTION)))
    if len(e) < n:
        raise ValueError(f"a steady-state band needs {n} frames or more, got {len(e)}")
    tail = e[-n:]
    mean, sd = float(np.mean(tail)), float(np.std(tail, ddof=1))
    return mean - BAND_SDS * sd, mean + BAND_SDS * sd, len(e) - n


def lag(errors: Sequence[float], change: int, hold: int = HOLD_FRAMES) -> float:
    """Frames after ``change`` until the per-frame ``errors`` enter the steady band (:func:`steady_band`) and stay
    in it for ``hold`` frames: 0 when they are in it from ``change`` on. NaN when the change is not before the
    steady frames (there is no steady state after it to come back to)."""
    e = np.asarray(errors, dtype=np.float64)
    lo, hi, first = steady_band(e)
    if not 0 <= change < first:
        return math.nan
    inside = (e >= lo) & (e <= hi)
    for k in range(len(e) - change):
        run = inside[change + k: change + k + hold]
        if run.all():
            return float(k)
    return float(len(e) - change)  # never settles: as long as the sequence shows


def settle_frames(states) -> list[int]:
    """The change frames of a sequence from its scene's state per frame ((F, D): positions, radiances, the
    camera; anything that moves or switches): each frame c that differs from frame c − 1 while frame c + 1 equals
    it, i.e. the last frame of a motion, after which the scene rests, or a switch."""
    s = np.asarray(states, dtype=np.float64)
    moved = np.r_[False, np.any(~np.isclose(s[1:], s[:-1], rtol=1e-12, atol=1e-12), axis=1)]
    return [c for c in range(1, len(s) - 1) if moved[c] and not moved[c + 1]]


def ghosting(images, references, masks) -> float:
    """RMSE over the pixels of ``masks`` ((F, H, W) bool, per frame: those the motion uncovered) of every frame,
    all channels; NaN where no pixel was uncovered."""
    e = error_images(images, references)
    m = np.asarray(masks, dtype=bool)
    if m.shape != e.shape[:3]:
        raise ValueError(f"masks {m.shape} do not match the frames {e.shape[:3]}")
    if not m.any():
        return math.nan
    return float(np.sqrt(np.mean(e[m] ** 2)))
