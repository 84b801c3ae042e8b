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
  there for :data:`HOLD_FRAMES` frames (one frame inside the band by chance does not end the lag). An
  exponential history of weight α on the new frame decays as (1 − α)^k: its excess error A·λ^k (λ = 1 − α)
  enters a band of half-width w at about k = ln(w/A)/ln λ. A stateless renderer's lag is 0 up to chance: a frame
  of independent Gaussian noise lies in a band estimated from 32 steady frames with probability about 0.943, the
  first :data:`HOLD_FRAMES` after the change with 0.84, so a lag above 0 is a false alarm of about 0.16, and a
  short one (mean 0.4 frames; above 5 in 0.8% of series of 96 frames).

  **Not settled** (lag ``math.inf``): the band is a steady state only if the steady frames do not themselves
  move. They **trend** (:func:`steady_trend`) when three things hold. (1) Their least-squares line changes across
  them by more than the band's half-width: the trend matters, the error moving further than the band is wide, so
  the band would only say where the error was when the sequence ended (an error still falling, as a long
  history's does, would enter a band drawn on its own tail at the tail's start, whatever its decay). (2) It moves
  back towards where the change put it from, against the error's offset at the change from the band's centre:
  what a lag measures is that return; a tail wandering away is noise or another matter. (3) The slope is
  significant: the steady frames are cut into :data:`TREND_BATCHES` consecutive batches, and the least-squares
  slope of the batch means against their order has a t (on batches − 2 degrees of freedom) beyond the
  two-sided :data:`TREND_LEVEL` quantile, in the direction of (2) (the method of batch means: a history's error
  is correlated from frame to frame, which a t over single frames would take for a trend, while the means of
  batches longer than its memory are nearly independent). Simulated on series of 144 frames (48 steady), 10,000
  each: independent noise never trends, AR(1) noise of lag-1 correlation 0.5 in 0.2% of series, 0.8 (about
  temporal accumulation's here) in 1.4%, 0.9 in 2.8% (a two-sided t over single frames: 0.5%, 12% and 27%); an
  exponential decay of 0.982 a frame from 4.83 ΔE₀₀ with noise 0.03 (the probes at hysteresis 0.97 here) is not
  settled in every one of 500 series of 144 frames, nor of 240, and settled in every one of 400 frames. A trending tail, or an error that never enters the band for :data:`HOLD_FRAMES` frames, is
  "not settled within the sequence": its lag is more than the :func:`lag_bound` frames the sequence shows after
  the change, and is written ``inf``.
- **ghosting** (:func:`ghosting`): the RMSE (linear radiance) of the frames over the pixels that the motion
  uncovered, the disocclusion masks of the reference's motion
  (:func:`cornell_harness.evaluate.disocclusion.disocclusion_mask`): where a history reprojected from the previous
  frame has nothing valid, a temporal method shows its ghosts.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from scipy import stats

#: The steady-state band of :func:`lag` is the mean ± this many standard deviations of the steady frames' errors.
BAND_SDS = 2.0
#: The steady frames of :func:`lag`: this last fraction of the sequence.
STEADY_FRACTION = 1.0 / 3.0
#: Frames in a row inside the band that end the lag.
HOLD_FRAMES = 3
#: The two-sided level of :func:`steady_trend`'s test of the slope of the steady frames' batch means; as the test
#: counts only a return towards the steady state, independent noise trends at most half this often.
TREND_LEVEL = 0.01
#: :func:`steady_trend` tests the means of this many consecutive batches of the steady frames (fewer frames: each
#: its own batch): 8 frames each of 48, several times the memory of the histories measured here.
TREND_BATCHES = 6


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


def _slope_t(y: np.ndarray) -> tuple[float, float]:
    """The least-squares slope of ``y`` against 0, 1, 2, ... and its t (slope over its standard error, on
    len(y) − 2 degrees of freedom; inf for an exact line that is not flat)."""
    n = len(y)
    x = np.arange(n, dtype=np.float64) - (n - 1) / 2.0
    slope = float(np.dot(x, y - y.mean()) / np.dot(x, x))
    residual = y - y.mean() - slope * x
    se = math.sqrt(float(np.dot(residual, residual)) / (n - 2) / float(np.dot(x, x)))
    return slope, abs(slope) / se if se > 0 else (math.inf if slope else 0.0)


def steady_trend(errors: Sequence[float], change: int | None = None) -> tuple[float, bool]:
    """(drift, trending) of the steady frames of :func:`steady_band`: ``drift`` is their least-squares line's change
    across them (slope × (n − 1)); they trend (module docstring) when its size exceeds the band's half-width, it
    runs against the offset of ``errors[change]`` from the band's centre (either way without ``change``), and the
    slope of the means of :data:`TREND_BATCHES` consecutive batches of them is significant at the two-sided
    :data:`TREND_LEVEL`. Fewer than three steady frames never trend."""
    e = np.asarray(errors, dtype=np.float64)
    lo, hi, first = steady_band(e)
    tail = e[first:]
    n = len(tail)
    drift = _slope_t(tail)[0] * (n - 1) if n >= 3 else float(tail[-1] - tail[0])
    batches = min(TREND_BATCHES, n)
    if batches < 3:
        return drift, False
    size = n // batches
    means = tail[n - size * batches:].reshape(batches, size).mean(axis=1)  # the latest frames, whole batches
    slope, t = _slope_t(means)
    returning = change is None or drift * (e[change] - (lo + hi) / 2.0) < 0
    significant = slope * drift > 0 and t > float(stats.t.ppf(1.0 - TREND_LEVEL / 2.0, batches - 2))
    return drift, abs(drift) > (hi - lo) / 2.0 and returning and significant


def lag(errors: Sequence[float], change: int, hold: int = HOLD_FRAMES) -> float:
    """Frames after ``change`` until the per-frame ``errors`` enter the steady band (:func:`steady_band`) and stay
    in it for ``hold`` frames: 0 when they are in it from ``change`` on. ``math.inf`` when they did not settle
    within the sequence (module docstring): the steady frames trend (:func:`steady_trend`), or the errors never
    enter the band for ``hold`` frames; the lag is then more than :func:`lag_bound` frames. NaN when the change is
    not before the steady frames (there is no steady state after it to come back to)."""
    e = np.asarray(errors, dtype=np.float64)
    lo, hi, first = steady_band(e)
    if not 0 <= change < first:
        return math.nan
    if steady_trend(e, change)[1]:
        return math.inf
    inside = (e >= lo) & (e <= hi)
    for k in range(len(e) - change - hold + 1):
        if inside[change + k: change + k + hold].all():
            return float(k)
    return math.inf


def lag_bound(frames: int, change: int) -> int:
    """The frames a sequence of ``frames`` frames shows after its change at position ``change``: what a lag of
    ``math.inf`` (not settled within the sequence) is known to exceed."""
    return frames - 1 - change


def lag_over_seeds(lags: Sequence[float], level: float = 0.95) -> tuple[float, float]:
    """The mean lag over seeds and its confidence half-width at ``level`` (Student t,
    :func:`cornell_harness.evaluate.convergence.mean_ci`), NaN lags (no change to follow) left out. Where a seed's
    lag is ``math.inf`` (not settled) the mean is too, with a NaN half-width: it is only known to exceed the
    bound."""
    from cornell_harness.evaluate.convergence import mean_ci

    values = [float(v) for v in lags if not math.isnan(float(v))]
    if any(math.isinf(v) for v in values):
        return math.inf, math.nan
    return mean_ci(values, level)


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
