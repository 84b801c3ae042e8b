"""Statistical agreement of a render with the reference: tiled, regional and global z-tests with a Šidák correction.

For an unbiased renderer, render − reference is zero-mean noise. Pixels are
independent, so a set of pixels' summed difference D has variance V = Σ
(var_img + var_ref) over them, and z = D / √V is close to standard normal (a
tile sums thousands of samples). The test runs one two-sided z-test per
channel on each tile, on each of the scene's named regions (``[regions.*]``,
masks from :func:`cornell_harness.evaluate.regions.region_masks`: the caustic, a
glass shadow, the mirror, where bugs of one light path live) and on the whole
image (which catches global energy errors far below a tile's noise). A
region's test has the power a tile grid lacks when a bias covers a small
patch of pixels that straddles tiles: on the caustics scene at the gate's
512 spp, a −5% error confined to the ``caustic`` region (147 pixels across
two 16 × 16 tiles) is a 4.05 sd effect on its worst tile and 4.9 sd on the
region, which takes the power over seeds from 0.67 to 0.98
(docs/gate-detection.md). The family-wise false-alarm rate is controlled at α
with Šidák's correction: each of the m tests (tiles, regions and image, times
3 channels) uses level 1 − (1 − α)^(1/m) (Šidák 1967, J. Am. Stat. Assoc. 62,
626-633). Regions overlap tiles and each other, so the tests are positively
correlated; for two-sided tests of jointly normal statistics Šidák's level
is then conservative (Šidák's inequality, the same paper), never
anticonservative.

``var_img`` is the render's own per-pixel variance of its mean when the
renderer reports it, floored at the reference renderer's noise model
(``var_ref · ref_spp / spp``: same per-sample variance as the reference; the
gate passes the floored image, :func:`cornell_harness.gate.checks.evaluate`); without
one, the noise model alone, which is exact for the reference renderer itself
(:func:`render_agreement`: the gate's test, and the ``agreement`` column of
``cbox compare``'s unbiased renderers).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np
from scipy.stats import norm

from cornell_harness.evaluate import metrics, noise

CHANNELS = "RGB"


def sidak_level(alpha: float, tests: int) -> float:
    """Per-test level that keeps the family-wise false-alarm rate at ``alpha`` over ``tests`` independent tests:
    1 − (1 − alpha)^(1/tests), computed through log1p and expm1 so that a tiny ``alpha`` (an early sequential
    look spends 1e-30) does not round to a level of 0."""
    return float(-math.expm1(math.log1p(-alpha) / max(tests, 1)))


def tile_sums(a: np.ndarray, tile: int) -> np.ndarray:
    """Sums of ``a`` (H, W, C) over tile×tile blocks; edge tiles may be smaller. Shape (rows, cols, C)."""
    h, w, c = a.shape
    rows, cols = -(-h // tile), -(-w // tile)
    padded = np.zeros((rows * tile, cols * tile, c))
    padded[:h, :w] = a
    return padded.reshape(rows, tile, cols, tile, c).sum(axis=(1, 3))


def _z(diff: np.ndarray, var: np.ndarray) -> np.ndarray:
    """diff/√var; 0 where both are 0, ±inf where only the variance is 0 (a noise-free disagreement)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        z = diff / np.sqrt(var)
    z[(var <= 0) & (diff == 0)] = 0.0
    return z


@dataclass
class Agreement:
    """Outcome of :func:`agreement_test`."""

    passed: bool
    alpha: float
    tests: int
    level: float  # per-test level after Šidák
    z_tiles: np.ndarray  # (rows, cols, 3)
    p_tiles: np.ndarray  # two-sided p-values, same shape
    z_global: np.ndarray  # (3,)
    p_global: np.ndarray  # (3,)
    tile: int
    failures: list[dict] = field(default_factory=list)  # worst first
    z_regions: dict[str, np.ndarray] = field(default_factory=dict)  # named region -> (3,); empty regions left out
    p_regions: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def p_min(self) -> float:
        return float(min([self.p_tiles.min(initial=1.0), self.p_global.min(initial=1.0),
                          *(p.min() for p in self.p_regions.values())]))

    def _count(self) -> str:
        regions = f", {3 * len(self.z_regions)} on {len(self.z_regions)} regions" if self.z_regions else ""
        return f"{self.tests} tests: {self.z_tiles.size} on tiles{regions}, 3 on the whole image"

    def message(self) -> str:
        if self.passed:
            return (f"agrees with the reference: smallest p = {self.p_min:.3g} ≥ per-test level {self.level:.3g} "
                    f"({self._count()}; family-wise α = {self.alpha:g})")
        head = (f"{len(self.failures)} of {self.tests} tests reject agreement at family-wise α = {self.alpha:g} "
                f"(per-test level {self.level:.3g})")
        return head + "; worst: " + "; ".join(f["where"] for f in self.failures[:3])


def region_sums(a: np.ndarray, masks: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Sums of ``a`` (H, W, C) over each non-empty mask (H, W) bool: name -> (C,). Empty masks are left out."""
    out = {}
    for name, mask in masks.items():
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != a.shape[:2]:
            raise ValueError(f"region {name!r}: mask shape {mask.shape} does not match image shape {a.shape[:2]}")
        if mask.any():
            out[name] = a[mask].sum(axis=0)
    return out


def _p(z: np.ndarray) -> np.ndarray:
    """Two-sided p-values; a test that cannot be evaluated (NaN from a NaN variance) rejects: p = 0, never a silent
    pass."""
    return np.nan_to_num(2 * norm.sf(np.abs(z)), nan=0.0)


def agreement_test(img: np.ndarray, var_img: np.ndarray, ref: np.ndarray, var_ref: np.ndarray,
                   tile: int = 16, alpha: float = 0.01, regions: Mapping[str, np.ndarray] | None = None) -> Agreement:
    """Tiled, regional and global z-tests of ``img`` against ``ref``, Šidák-corrected to family-wise ``alpha``.

    ``regions`` are the scene's named regions (name -> (H, W) bool mask,
    :func:`cornell_harness.evaluate.regions.region_masks`); each non-empty one adds
    one test per channel to the family.
    """
    img, ref = np.asarray(img, np.float64), np.asarray(ref, np.float64)
    var = np.asarray(var_img, np.float64) + np.asarray(var_ref, np.float64)
    diff = img - ref
    d_t, v_t, r_t = tile_sums(diff, tile), tile_sums(var, tile), tile_sums(ref, tile)
    z_tiles = _z(d_t, v_t)
    z_global = _z(diff.sum(axis=(0, 1)), var.sum(axis=(0, 1)))
    d_r, v_r, r_r = (region_sums(a, regions or {}) for a in (diff, var, ref))
    z_regions = {name: _z(d_r[name], v_r[name]) for name in d_r}
    p_tiles, p_global = _p(z_tiles), _p(z_global)
    p_regions = {name: _p(z) for name, z in z_regions.items()}
    tests = z_tiles.size + z_global.size + 3 * len(z_regions)
    level = sidak_level(alpha, tests)
    failures = []
    h, w, _ = img.shape
    for ch in range(3):
        if p_global[ch] < level:
            rel = diff[..., ch].sum() / max(abs(ref[..., ch].sum()), 1e-300)
            failures.append({"p": float(p_global[ch]), "z": float(z_global[ch]), "where":
                             f"whole image, channel {CHANNELS[ch]}: z = {z_global[ch]:.2f}, mean off by {rel:+.3%}"})
    for name, z in z_regions.items():
        n = int(np.count_nonzero(regions[name]))
        for ch in range(3):
            if p_regions[name][ch] < level:
                rel = d_r[name][ch] / max(abs(r_r[name][ch]), 1e-300)
                failures.append({"p": float(p_regions[name][ch]), "z": float(z[ch]), "region": name,
                                 "channel": CHANNELS[ch], "where":
                                 f"region {name} ({n} pixels), channel {CHANNELS[ch]}: z = {z[ch]:.2f}, "
                                 f"region mean off by {rel:+.2%}"})
    for r, c, ch in zip(*np.nonzero(p_tiles < level)):
        y0, x0 = r * tile, c * tile
        y1, x1 = min(y0 + tile, h), min(x0 + tile, w)
        rel = d_t[r, c, ch] / max(abs(r_t[r, c, ch]), 1e-300)
        failures.append({"p": float(p_tiles[r, c, ch]), "z": float(z_tiles[r, c, ch]), "x": (int(x0), int(x1)),
                         "y": (int(y0), int(y1)), "channel": CHANNELS[ch], "where":
                         f"pixels x {x0}-{x1 - 1}, y {y0}-{y1 - 1}, channel {CHANNELS[ch]}: "
                         f"z = {z_tiles[r, c, ch]:.2f}, tile mean off by {rel:+.2%}"})
    failures.sort(key=lambda f: (f["p"], -abs(f["z"]) if math.isfinite(f["z"]) else -math.inf))
    return Agreement(not failures, alpha, tests, level, z_tiles, p_tiles, z_global, p_global, tile, failures,
                     z_regions, p_regions)


def render_agreement(image: np.ndarray, variance: np.ndarray | None, spp: int, ref: np.ndarray, ref_var: np.ndarray,
                     ref_spp: int, tile: int = 16, alpha: float = 0.01,
                     regions: Mapping[str, np.ndarray] | None = None) -> Agreement:
    """:func:`agreement_test` of a render at ``spp``: NaN/Inf pixels taken as black, its own ``variance`` (if it
    reports one) floored at the reference's noise model at ``spp``.

    The floor, because where samples are skewed (a caustic seen through glass) a tile whose few bright paths did
    not come reads low with a variance estimate that is low too, and its own variance alone turns that into a
    false alarm (2 of 20 clean gate runs, docs/gate-detection.md).
    """
    model = noise.render_variance(ref_var, ref_spp, spp)
    var = model if variance is None else np.maximum(variance, model)
    return agreement_test(metrics.zero_broken_pixels(image), var, ref, ref_var, tile, alpha, regions)
