"""Confidence intervals of a relative bias, render mean / reference mean − 1, from both images' variances.

Over a region's pixels (or the whole image) and per channel, the render's sum
X and the reference's sum Y are independent and close to normal (a region
sums thousands of samples), with variances V_X and V_Y, the sums of their
pixels' variances of the mean (pixels are independent). The ratio
ρ = E[X] / E[Y] is the render's mean over the reference's, and ρ − 1 its
relative bias.

**Fieller's interval** (Fieller 1954, "Some problems in interval estimation",
J. R. Stat. Soc. B 16, 175-185): X − ρY is normal with mean 0 and variance
V_X + ρ² V_Y, so the ρ with (X − ρY)² ≤ z² (V_X + ρ² V_Y) form a
(1 − level)-confidence set, exact for normal sums whatever ρ. It is the
interval between the roots of (Y² − z² V_Y) ρ² − 2 XY ρ + (X² − z² V_X) = 0
when Y is significantly far from 0 (Y² > z² V_Y), and unbounded otherwise:
then no finite interval is honest (a region whose reference mean is lost in
its own noise), and the interval is (−∞, ∞). Unlike the delta method's
symmetric interval it widens on the side where the ratio's distribution is
skewed, which matters where the reference's own variance is a sizeable share.

**Its standard error** for planning is the delta method's (Casella & Berger
2002, "Statistical Inference", §5.5.4): Var(X/Y) ≈ (V_X + ρ² V_Y) / Y². The
render's share V_X falls as 1/spp, the reference's share ρ² V_Y does not: that
is what :func:`spp_for_half_width` solves, and why a reference's variance
alone can keep a margin unresolvable at any spp.

**Detectable bias**: a two-sided z-test at level ``level`` detects a true
relative bias δ with power 1 − β when |δ| ≥ (z_{1−level/2} + z_{1−β}) · se
(the usual sample-size formula, e.g. Chow, Shao & Wang 2008, "Sample Size
Calculations in Clinical Research", §3.1), se the relative bias's standard
error at δ = 0: :func:`detectable_bias`.

Every function takes and returns arrays of any one shape (regions × channels),
so the gate, ``cbox reference verify`` and a planner share them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np
from scipy.stats import norm


@dataclass(frozen=True)
class BiasIntervals:
    """Relative biases with their (1 − level) Fieller intervals and delta-method standard errors (same shapes)."""

    estimate: np.ndarray  # X / Y − 1
    low: np.ndarray
    high: np.ndarray
    se: np.ndarray  # delta method, at the estimate
    render_share: np.ndarray  # V_X / (V_X + ρ² V_Y): the part of the ratio's variance that shrinks with spp
    level: float  # the interval's miss rate: each covers with probability 1 − level


def critical_z(level: float) -> float:
    """The two-sided normal critical value: P(|Z| > z) = ``level``."""
    return float(norm.isf(level / 2.0))


def fieller(x, vx, y, vy, level: float) -> tuple[np.ndarray, np.ndarray]:
    """Fieller's (1 − ``level``) interval (low, high) of E[x] / E[y] for independent normal x, y of variances vx, vy.

    Unbounded, (−∞, ∞), where y is not significantly far from 0. Both variances 0: the point x / y; 0 / 0 with no
    variance (a black region rendered black): 1, the two agree.
    """
    x, vx, y, vy = (np.asarray(a, np.float64) for a in (x, vx, y, vy))
    z2 = critical_z(level) ** 2
    a = y * y - z2 * vy
    b = x * y
    c = x * x - z2 * vx
    with np.errstate(divide="ignore", invalid="ignore"):
        root = np.sqrt(np.maximum(b * b - a * c, 0.0))
        low, high = (b - root) / a, (b + root) / a
    bounded = a > 0
    low, high = np.where(bounded, low, -np.inf), np.where(bounded, high, np.inf)
    exact = (vx == 0) & (vy == 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        point = np.where((x == 0) & (y == 0), 1.0, x / y)
    low, high = np.where(exact, point, low), np.where(exact, point, high)
    bad = ~(np.isfinite(x) & np.isfinite(y) & np.isfinite(vx) & np.isfinite(vy))  # a NaN proves nothing
    return np.where(bad, -np.inf, low), np.where(bad, np.inf, high)


def relative_bias(x, vx, y, vy, level: float) -> BiasIntervals:
    """The relative bias x / y − 1 of sums x (the render's) against y (the reference's), variances vx, vy: its
    (1 − ``level``) Fieller interval and delta-method standard error (see the module docstring)."""
    x, vx, y, vy = (np.asarray(a, np.float64) for a in (x, vx, y, vy))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where((x == 0) & (y == 0), 1.0, x / y)
        render, reference = vx, ratio * ratio * vy
        se = np.sqrt(render + reference) / np.abs(y)
        share = np.where(render + reference > 0, render / (render + reference), 1.0)
    se = np.where((render + reference) == 0, 0.0, se)
    low, high = fieller(x, vx, y, vy, level)
    return BiasIntervals(ratio - 1.0, low - 1.0, high - 1.0, se, share, level)


def region_sums(image, variance, masks: Mapping[str, np.ndarray]) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Names, per-channel sums of ``image`` and of ``variance`` over the whole image and each non-empty mask.

    The whole image comes first, named ``""``; arrays (regions, channels)."""
    image, variance = np.asarray(image, np.float64), np.asarray(variance, np.float64)
    names, sums, vars_ = [""], [image.sum(axis=(0, 1))], [variance.sum(axis=(0, 1))]
    for name, mask in masks.items():
        mask = np.asarray(mask, dtype=bool)
        if mask.any():
            names.append(name)
            sums.append(image[mask].sum(axis=0))
            vars_.append(variance[mask].sum(axis=0))
    return names, np.array(sums), np.array(vars_)


def spp_for_half_width(se, render_share, spp: float, half_width, level: float) -> np.ndarray:
    """About the spp at which the (1 − ``level``) interval's half-width z·se falls to ``half_width``.

    The render's share of the variance falls as 1/spp, the reference's stays: with s² = se² at ``spp``,
    s²(n) = s² (share · spp / n + 1 − share). ∞ where the reference's share alone is too wide, or
    ``half_width`` ≤ 0; ``spp`` itself (or fewer) where the interval is narrow enough already.
    """
    se, share, hw = (np.asarray(a, np.float64) for a in (se, render_share, half_width))
    z = critical_z(level)
    target = (hw / z) ** 2
    fixed = se * se * (1.0 - share)
    room = target - fixed
    with np.errstate(divide="ignore", invalid="ignore"):
        n = np.where((room > 0) & (hw > 0), se * se * share * spp / room, np.inf)
    return np.where(se == 0, np.where(hw > 0, 0.0, np.inf), n)


def detectable_bias(se, level: float, beta: float) -> np.ndarray:
    """The smallest relative bias a two-sided z-test at ``level`` detects with power 1 − ``beta``:
    (z_{1−level/2} + z_{1−β}) · se, ``se`` the relative bias's standard error (module docstring)."""
    return (critical_z(level) + float(norm.isf(beta))) * np.asarray(se, np.float64)


def percent(x: float) -> str:
    """A relative bias as a signed percentage, with a real minus sign: ``−0.4%``, ``+5.3%``, ``−∞``."""
    if not np.isfinite(x):
        return "−∞" if x < 0 else "+∞"
    digits = 1 if abs(x) >= 0.001 or x == 0 else 2
    return f"{100 * x:+.{digits}f}%".replace("-", "−")


def interval_text(name: str, estimate: float, low: float, high: float) -> str:
    """``glass-shadow: bias −0.4% [−6.1%, +5.3%]``; without a name, ``−0.4% [−6.1%, +5.3%]``."""
    shown = f"{percent(estimate)} [{percent(low)}, {percent(high)}]"
    return f"{name}: bias {shown}" if name else shown
