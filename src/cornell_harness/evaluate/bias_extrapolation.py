"""Bias extrapolation over seeds: a consistent renderer's limit error, tested against 0 with a t-test.

A consistent but biased estimator (photon mapping, SPPM) has at effort E
(photons stored, iterations) an expected error e(E) = b∞ + c·E^(−p) + noise,
with p the rate at which its kernel bias falls: a k-nearest-neighbour
density estimate's kernel area r² shrinks as 1/N with N photons, so its
bias, O(r²) where the density is smooth, falls as N^(−1) (p = 1; Jensen,
"Realistic Image Synthesis Using Photon Mapping", 2001, §7.2; Silverman
1986, §4.3.1); SPPM's radius follows r²_{i+1} = r²_i·(i + α)/(i + 1), so
r² ∝ i^(α−1) and its bias falls as i^(α−1) (p = 1 − α = 1/3 at α = 2/3;
Knaus & Zwicker 2011, "Progressive photon mapping: a probabilistic
approach", §4; Hachisuka & Jensen 2009, "Stochastic progressive photon
mapping"). Fitting b∞ and c by least squares at two or more efforts of
one seed is Richardson extrapolation (Richardson 1911): for a correct
renderer b∞ is 0 up to noise, for a renderer with a bias that does not
vanish (a photon-flux error) it is that bias.

The noise of a photon map is correlated across pixels (one photon lights
a disc of them), and one seed's efforts share their camera samples and
photons, so no per-pixel variance gives b∞'s standard error. The seeds
do: each seed's b∞ is an independent draw, so the mean of k of them
against 0 is a one-sample Student t-test with k − 1 degrees of freedom,
valid whatever the correlation between one seed's efforts. Several
metrics share the family-wise level by Šidák's correction. Where the
efforts CI affords have not reached the asymptotic rate everywhere (a
photon map's corners, whose bias falls more slowly than inside a face), a
``tolerance`` allows a measured small limit: the test then fails only a
limit significantly beyond it. The fitted
c (the bias at the first effort beyond the limit) is reported with its
t-interval too: the consistency slope, whose sign and size say that the
error falls with effort as the rate says.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats


#: A limit this close to 0 is 0 when every seed gives the same one (rounding of a least-squares fit).
ZERO = 1e-9


def design(efforts, rate: float) -> np.ndarray:
    """The least-squares design of e(E) = b∞ + c·(E/E₀)^(−p): columns 1 and (E/E₀)^(−rate), E₀ the first effort.

    Scaling by E₀ makes c the bias at the first effort above the limit (a number in the metric's units).
    """
    e = np.asarray(efforts, np.float64)
    if e.ndim != 1 or len(e) < 2 or np.any(e <= 0) or len(np.unique(e)) != len(e):
        raise ValueError(f"need two or more distinct positive efforts, got {list(efforts)}")
    if not rate > 0:
        raise ValueError(f"rate must be > 0, got {rate}")
    return np.column_stack([np.ones_like(e), (e / e[0]) ** -rate])


def extrapolate(errors, efforts, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Per seed (rows of ``errors``, (k, efforts)), the fitted limit b∞ and coefficient c (each (k,))."""
    x = design(efforts, rate)
    y = np.asarray(errors, np.float64)
    if y.ndim != 2 or y.shape[1] != x.shape[0]:
        raise ValueError(f"errors must be (seeds, {x.shape[0]} efforts), got shape {y.shape}")
    coef = np.linalg.lstsq(x, y.T, rcond=None)[0]
    return coef[0], coef[1]


@dataclass(frozen=True)
class TInterval:
    """A mean over seeds, its standard error, t statistic against 0, two-sided p, and a confidence interval."""

    mean: float
    se: float
    t: float
    p: float
    low: float
    high: float

    def text(self, scale: float = 100.0, unit: str = "%") -> str:
        return (f"{self.mean * scale:+.3f}{unit} [{self.low * scale:+.3f}, {self.high * scale:+.3f}]")


def t_interval(values, level: float = 0.95) -> TInterval:
    """The one-sample t-test of ``values`` against 0 (two-sided p) and their mean's ``level`` t-interval."""
    v = np.asarray(values, np.float64)
    k = len(v)
    if k < 2 or not np.all(np.isfinite(v)):
        return TInterval(float(np.mean(v)) if k else float("nan"), float("nan"), float("nan"), 0.0, float("nan"),
                         float("nan"))
    mean, se = float(v.mean()), float(v.std(ddof=1) / np.sqrt(k))
    if se <= 1e-12 * max(1.0, abs(mean)):  # identical seeds (a deterministic renderer): no spread to test with
        # A limit within rounding of 0 passes; any other is certain.
        ok = abs(mean) <= ZERO
        return TInterval(mean, se, 0.0 if ok else math.copysign(math.inf, mean), 1.0 if ok else 0.0, mean, mean)
    t = mean / se
    half = float(stats.t.ppf(0.5 + level / 2, k - 1)) * se
    return TInterval(mean, se, t, float(2 * stats.t.sf(abs(t), k - 1)), mean - half, mean + half)


@dataclass(frozen=True)
class LimitTest:
    """One metric's bias extrapolation over seeds: the limit's test against 0 and the bias coefficient."""

    limit: TInterval  # b∞ over seeds
    coefficient: TInterval  # c: the bias at the first effort above the limit
    level: float  # the test's level (its Šidák share)
    seeds: int
    tolerance: float = 0.0  # |b∞| up to this is allowed

    @property
    def t(self) -> float:
        """(|mean limit| − tolerance) / standard error: the test statistic against the nearer allowed limit."""
        if not self.limit.se > 0:
            return 0.0 if self.limit.p == 1.0 or abs(self.limit.mean) <= self.tolerance else math.inf
        return (abs(self.limit.mean) - self.tolerance) / self.limit.se

    @property
    def passed(self) -> bool:
        """The limit's (1 − level) t-interval reaches into [−tolerance, tolerance] (with tolerance 0: p ≥ level)."""
        return not self.t > self.t_critical

    @property
    def t_critical(self) -> float:
        return float(stats.t.isf(self.level / 2, self.seeds - 1))


def limit_test(errors, efforts, rate: float, level: float, tolerance: float = 0.0) -> LimitTest:
    """Fit each seed's limit (:func:`extrapolate`) and t-test their mean against 0 at ``level`` (two-sided).

    With a ``tolerance`` the test fails only a limit significantly beyond ±tolerance: the (1 − level)
    t-interval of the mean limit lies wholly above ``tolerance`` or below −``tolerance``.
    """
    b, c = extrapolate(errors, efforts, rate)
    return LimitTest(t_interval(b, 1.0 - level), t_interval(c), level, len(b), tolerance)
