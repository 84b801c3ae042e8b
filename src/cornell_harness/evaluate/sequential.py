"""Group-sequential boundaries: how a test's error rate is spent over looks at growing spp (α-spending).

A gate that looks at a render at n_1 < n_2 < … < n_K = ``max_spp`` samples
per pixel and stops at the first look with a verdict tests K times; tested at
a fixed level α each, its false-alarm rate over the looks could reach Kα.
An *α-spending function* α(t) (Lan & DeMets 1983, "Discrete sequential
boundaries for clinical trials", Biometrika 70, 659-663) says how much of α
may be spent by the information fraction t, here t_k = n_k / max_spp (the
information of a mean grows with its samples). Look k tests at the increment
α(t_k) − α(t_{k−1}) (:func:`look_levels`), and the increments sum to
α(1) = α.

Each look is tested at its increment and the looks' rates are added (the
Bonferroni bound), so the rate over all looks is at most α whatever the
looks' correlation. Lan and DeMets' own boundaries integrate over the joint
normal law of the looks' statistics and are a little less strict; they need
that joint law, which a Šidák family over tiles, regions and channels (the
gate's tests) does not have in closed form, so the bound is used.

The two spending functions of Lan & DeMets (1983, §3):

- ``obrien-fleming``: α(t) = 2 − 2Φ(z_{1−α/2} / √t), close to O'Brien &
  Fleming's (1979) boundaries. It spends almost nothing early, so the last
  look keeps nearly the power of a test at max_spp alone, and an early stop
  takes a gross effect: a large bias fails at the first look, a generous
  margin passes at a middle one.
- ``pocock``: α(t) = α ln(1 + (e − 1) t), close to Pocock's (1977) equal
  boundaries: stops earlier on moderate effects, at the price of a stricter
  last look.

The same functions spend β, the rate at which a bias at the margin is
passed, over the equivalence looks (:mod:`cornell_harness.gate.sequential`).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from scipy.stats import norm

#: The spending functions, by the name a gate config gives; the first is the default.
SPENDING = ("obrien-fleming", "pocock")


def spent(t: float, level: float, spending: str = SPENDING[0]) -> float:
    """The error rate α(t) spent by information fraction ``t`` in [0, 1] of a test of overall ``level``."""
    if spending not in SPENDING:
        raise ValueError(f"unknown spending function {spending!r}; known: {', '.join(SPENDING)}")
    if t <= 0.0:
        return 0.0
    if t >= 1.0:
        return float(level)
    if spending == "pocock":
        return float(level * math.log1p((math.e - 1.0) * t))
    return float(2.0 * norm.sf(norm.isf(level / 2.0) / math.sqrt(t)))  # 2 − 2Φ(x), without its cancellation


def look_levels(fractions: Sequence[float], level: float, spending: str = SPENDING[0]) -> np.ndarray:
    """Each look's level, α(t_k) − α(t_{k−1}), for increasing information ``fractions`` ending at 1; they sum
    to ``level`` (the last look takes what is left, so rounding cannot lose any)."""
    t = np.asarray(fractions, np.float64)
    if t.size == 0 or np.any(np.diff(t) <= 0) or t[0] <= 0 or t[-1] != 1.0:
        raise ValueError(f"information fractions must increase from above 0 to 1, got {list(t)}")
    cumulative = np.array([spent(float(x), level, spending) for x in t])
    out = np.diff(cumulative, prepend=0.0)
    out[-1] = level - cumulative[-2] if t.size > 1 else level
    return out


def doubling(first: int, last: int) -> list[int]:
    """``first``, 2·``first``, 4·``first``, … below ``last``, then ``last``: a sequential gate's looks, and the
    checkpoints of a slope."""
    out, s = [], max(1, first)
    while s < last:
        out.append(s)
        s *= 2
    return out + [last]


def fractions(spps: Sequence[int]) -> np.ndarray:
    """The information fraction n_k / n_K of each look at ``spps`` (increasing; the last is the budget)."""
    n = np.asarray(spps, np.float64)
    return n / n[-1]
