"""The pure functions behind the report's charts: log-axis domains, ticks and their labels, the Pareto front.

Numbers in, numbers (or a label) out; :mod:`cornell_harness.reports.plots` draws with them.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def pareto_front(x: Sequence[float], y: Sequence[float]) -> list[int]:
    """Indices of the points that no other point beats in both ``x`` and ``y`` (lower is better).

    A point is dominated when another is at least as good in both coordinates
    and strictly better in one; identical points do not dominate each other,
    so both stay on the front. Points with a NaN or infinite coordinate are
    never on it. The result is ordered by increasing ``x`` (then ``y``).
    """
    xs = np.asarray(x, dtype=np.float64)
    ys = np.asarray(y, dtype=np.float64)
    if xs.shape != ys.shape:
        raise ValueError(f"x and y differ in length: {xs.shape} vs {ys.shape}")
    valid = [i for i in range(xs.size) if math.isfinite(xs[i]) and math.isfinite(ys[i])]
    front = []
    for i in valid:
        dominated = any(
            xs[j] <= xs[i] and ys[j] <= ys[i] and (xs[j] < xs[i] or ys[j] < ys[i]) for j in valid if j != i
        )
        if not dominated:
            front.append(i)
    return sorted(front, key=lambda i: (xs[i], ys[i], i))


def format_tick(v: float) -> str:
    """A tick label: plain for moderate values, ``2×10⁻⁵`` style otherwise."""
    if v == 0 or not math.isfinite(v):
        return "0" if v == 0 else str(v)
    if 1e-3 <= abs(v) < 1e5:
        return f"{v:g}"
    exp = int(math.floor(math.log10(abs(v)) + 1e-9))
    mant = v / 10**exp
    power = "10" + str(exp).translate(_SUPERSCRIPT)
    if abs(mant - 1) < 1e-6:
        return power
    return f"{mant:g}×{power}"


def log_domain(values: Sequence[float], pad: float = 0.06) -> tuple[float, float] | None:
    """log10 extent of the positive finite ``values``, padded; None if there are none."""
    v = np.asarray([x for x in values if x is not None and math.isfinite(x) and x > 0], dtype=np.float64)
    if v.size == 0:
        return None
    lo, hi = math.log10(v.min()), math.log10(v.max())
    if hi - lo < 0.3:  # a nearly flat series still gets a readable axis
        mid = 0.5 * (lo + hi)
        lo, hi = mid - 0.15, mid + 0.15
    span = hi - lo
    return lo - pad * span, hi + pad * span


def log_ticks(lo: float, hi: float, base2: bool = False, max_ticks: int = 9) -> list[float]:
    """Tick values inside the log10 domain [lo, hi]: powers of 2 (``base2``) or 1-2-5 decades."""
    if base2:
        k0, k1 = math.ceil(lo / math.log10(2) - 1e-9), math.floor(hi / math.log10(2) + 1e-9)
        ks = list(range(k0, k1 + 1))
        step = 1
        while len(ks[::step]) > max_ticks:
            step += 1
        return [2.0**k for k in ks[::step]]
    def thin(ticks: list[float]) -> list[float]:
        step = 1
        while len(ticks[::step]) > max_ticks:
            step += 1
        return ticks[::step]

    decades, one25, all9 = (
        [m * 10.0**e for e in range(math.floor(lo) - 1, math.ceil(hi) + 1) for m in mults
         if lo - 1e-9 <= math.log10(m * 10.0**e) <= hi + 1e-9]
        for mults in ((1,), (1, 2, 5), (1, 2, 3, 4, 5, 6, 7, 8, 9))
    )
    if len(decades) >= 3:
        return thin(decades)
    if 2 <= len(one25) <= max_ticks:
        return one25
    for ticks in (decades, one25, all9):
        if len(ticks) >= 2:
            return thin(ticks)
    return [10.0 ** (0.5 * (lo + hi))]
