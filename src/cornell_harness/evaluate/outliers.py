"""Single outlier pixels: a per-pixel z-test whose heavy-tailed null is calibrated on the reference's noise batch.

The tiled agreement test sums a tile's pixels, so one pixel twice as
bright as it should be moves its 16×16 tile by only z ≈ 2-3 on the Cornell
box at 256 spp, though it sits 20-40 standard deviations out at its own
pixel. This test looks at every pixel.

**Statistic.** Per pixel and channel, z = (img − ref) / √(v + var_ref), with
v = max(var_img, var_model): the renderer's own variance where it reports
one, but never less than the reference renderer's noise model at this spp
(``var_model``, :func:`cornell_harness.evaluate.noise.render_variance`). The floor
keeps a pixel whose few samples happened to agree (a variance estimate of
0) from giving an infinite z; the renderer's own variance tames its
fireflies, which raise that pixel's variance as much as its value. The
pixel's statistic is the median of its three channels' z: a pixel is an
outlier only when two channels agree. Fireflies are mostly one channel
(on the Cornell box's coloured walls, a rare path that brought light from
the other wall: red on the green wall, green on the red), a wrong pixel
moves all three.

**Threshold.** That statistic is still heavier-tailed than normal (a white
surface's firefly moves all channels), so a normal quantile would cry wolf.
The reference stores one independent batch of ``noise_spp`` samples
(``reference.noise``): its statistic, computed the same way with the
noise model's variance, is a sample of the real null of each pixel. The
test fits a Pareto tail to the k = ⌈√N⌉ largest of its N values |m| by
Hill's estimator (Hill 1975, Ann. Statist. 3, 1163-1174),
γ = mean ln(m_(i)/u) over them, u the (k+1)-th largest, so
P(|m| > t) ≈ (k/N)(t/u)^(−1/γ) for t ≥ u (pooled over the pixels; the
union bound below needs no more). Hill's γ is asymptotically normal with
standard deviation γ/√k (Hall 1982, J. R. Stat. Soc. B 44, 37-42), and one
noise batch of a small image (the furnace's 32×32 pixels) can happen to be
light-tailed, so the test uses γ⁺ = γ(1 + 1.645/√k), the one-sided 95%
upper confidence bound: a tail at least as heavy as the batch's with 95%
confidence. The per-pixel level is Šidák's ℓ = 1 − (1 − α)^(1/N), and the
threshold solves (k/N)(t/u)^(−1/γ⁺) = ℓ: t = u·(k/(Nℓ))^γ⁺. By the union
bound the family-wise false-alarm rate over the N pixels is then at most
N·P̄(|m| > t) = α wherever the tail is no heavier than that Pareto tail
(and less where it is lighter, e.g. normal or nearly so: a Pareto tail
overstates a light one far out).

At ``spp`` samples instead of ``noise_spp``, a heavy tail comes from single
large samples, whose z scales as 1/√spp: a Pareto tail of index a = 1/γ⁺
moves the threshold by (noise_spp/spp)^(1/2 − γ⁺) (for γ⁺ < 1/2; no change
otherwise). The threshold is never below the one a normal null would need,
Φ⁻¹(1 − ℓ/3) (the median of three normal channels exceeds t in absolute
value with probability at most 3 Φ̄(t), whatever their correlation: two of
the three must). On the Cornell box at 256 spp this gives 11.4 (normal
floor 5.5), on the light panel 9.5, on the furnace 5.7 (see
``docs/gate-detection.md``).

A pixel with no variance but a difference (z = ±∞) or with a NaN is an
outlier; z = 0/0 (no variance, no difference) is 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import norm

from cornell_harness.evaluate.agreement import sidak_level

CHANNELS = "RGB"
#: Fewest noise-batch values above zero for a tail fit; with fewer, the normal threshold alone.
MIN_TAIL = 10
#: One-sided 95% normal quantile: γ⁺ = γ(1 + UPPER_Z/√k) bounds Hill's estimate from above.
UPPER_Z = 1.645


def _z(diff: np.ndarray, var: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        z = diff / np.sqrt(var)
    z[(var <= 0) & (diff == 0)] = 0.0
    return z


def pixel_statistic(z: np.ndarray) -> np.ndarray:
    """The median of a pixel's three channel z-scores, shape (H, W); +inf where one is NaN (never a silent pass)."""
    nan = np.isnan(z)
    m = np.median(np.where(nan, 0.0, z), axis=-1)
    m[nan.any(axis=-1)] = np.inf
    return m


@dataclass
class Threshold:
    """The calibrated threshold on |m| and how it was found."""

    value: float
    level: float  # per-pixel level ℓ
    gamma: float  # γ⁺, the upper confidence bound on Hill's γ = 1/(tail index); nan without a fit
    k: int  # top order statistics used
    u: float  # the (k+1)-th largest |m| of the noise batch
    spp_factor: float  # (noise_spp/spp)^(1/2 − γ)
    normal: float  # the floor Φ⁻¹(1 − ℓ/3)
    noise_max: float  # largest |m| of the noise batch

    def describe(self) -> str:
        if math.isnan(self.gamma):
            return f"normal threshold {self.normal:.2f} (noise batch too small for a tail fit)"
        src = "normal floor" if self.value == self.normal else "Pareto tail of the reference's noise batch"
        return (f"{src}: tail index ≥ {1 / self.gamma:.1f} (Hill, 95% bound, top {self.k}, above {self.u:.2f}; "
                f"noise batch max {self.noise_max:.2f}), spp factor {self.spp_factor:.2f}, "
                f"normal floor {self.normal:.2f}")


def calibrate(ref: np.ndarray, var_ref: np.ndarray, noise: np.ndarray, ref_spp: int, noise_spp: int, spp: int,
              alpha: float) -> Threshold:
    """The threshold on the pixel statistic for a render at ``spp``, from the reference's noise batch."""
    ref, var_ref = np.asarray(ref, np.float64), np.asarray(var_ref, np.float64)
    var = var_ref * (ref_spp / noise_spp + 1.0)  # of (noise batch − reference), by the noise model
    m = np.abs(pixel_statistic(_z(np.asarray(noise, np.float64) - ref, var))).ravel()
    n = m.size
    level = sidak_level(alpha, n)
    normal = float(norm.isf(level / 3.0))
    tail = np.sort(m[np.isfinite(m) & (m > 0)])[::-1]
    k = math.ceil(math.sqrt(n))
    noise_max = float(tail[0]) if tail.size else 0.0
    if tail.size < max(MIN_TAIL, k + 1) or tail[k] <= 0:
        return Threshold(normal, level, math.nan, 0, math.nan, 1.0, normal, noise_max)
    u = float(tail[k])
    gamma = float(np.mean(np.log(tail[:k] / u))) * (1.0 + UPPER_Z / math.sqrt(k))
    t = u * (k / (n * level)) ** gamma
    factor = (noise_spp / spp) ** max(0.5 - gamma, 0.0)
    return Threshold(max(t * factor, normal), level, gamma, k, u, factor, normal, noise_max)


@dataclass
class Outliers:
    """Outcome of :func:`outlier_test`."""

    passed: bool
    alpha: float
    threshold: Threshold
    m: np.ndarray  # (H, W) pixel statistic
    pixels: int
    failures: list[dict] = field(default_factory=list)  # worst first

    @property
    def worst(self) -> float:
        """Largest |m| over the image."""
        return float(np.max(np.abs(self.m))) if self.m.size else 0.0

    def message(self) -> str:
        t = self.threshold
        rule = (f"|z| > {t.value:.2f} (z: median of a pixel's three channels; per-pixel level {t.level:.2g}, "
                f"family-wise α = {self.alpha:.3g} over {self.pixels} pixels; {t.describe()})")
        if self.passed:
            y, x = np.unravel_index(int(np.argmax(np.abs(self.m))), self.m.shape)
            return f"no outlier pixel: largest |z| = {self.worst:.2f} at pixel x {x}, y {y}, within {rule}"
        head = f"{len(self.failures)} outlier pixel(s) of {self.pixels}: {rule}; worst: "
        return head + "; ".join(f["where"] for f in self.failures[:3])


def outlier_test(img: np.ndarray, var_img: np.ndarray | None, ref: np.ndarray, var_ref: np.ndarray,
                 noise: np.ndarray, ref_spp: int, noise_spp: int, spp: int, alpha: float = 0.01) -> Outliers:
    """Per-pixel test of ``img`` (at ``spp``) against the reference; ``var_img`` None: the noise model alone."""
    img, ref = np.asarray(img, np.float64), np.asarray(ref, np.float64)
    var_ref = np.asarray(var_ref, np.float64)
    model = var_ref * ref_spp / spp  # cornell_harness.evaluate.noise.render_variance
    own = model if var_img is None else np.asarray(var_img, np.float64)
    v = np.maximum(own, model) + var_ref  # a NaN variance stays NaN: its pixel is an outlier
    diff = img - ref
    z = _z(diff, v)
    m = pixel_statistic(z)
    thr = calibrate(ref, var_ref, noise, ref_spp, noise_spp, spp, alpha)
    h, w = m.shape
    bad = np.argwhere(~(np.abs(m) <= thr.value))
    failures = []
    for y, x in bad:
        zc = z[y, x]
        chans = [CHANNELS[c] for c in range(3) if not abs(zc[c]) <= thr.value]
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = img[y, x] / ref[y, x]
        shown = ", ".join(f"{CHANNELS[c]} {zc[c]:+.1f}" for c in range(3))
        times = ", ".join(f"{CHANNELS[c]} {ratio[c]:.3g}×" for c in range(3))
        failures.append({"x": int(x), "y": int(y), "z": float(m[y, x]), "channels": chans, "where":
                         f"pixel x {x}, y {y}, channel{'s' if len(chans) != 1 else ''} {', '.join(chans)}: "
                         f"z = {m[y, x]:+.1f} (per channel {shown}); render/reference {times}"})
    failures.sort(key=lambda f: -abs(f["z"]))
    return Outliers(not failures, alpha, thr, m, h * w, failures)
