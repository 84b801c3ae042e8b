"""Repeated timings of one render: their median and its 95% confidence interval, and the results columns
that carry them (``--time-repeats K``; docs/timing.md).

The rule (:func:`median_interval`): the reported time is the **sample median** of the K timings (robust to
one stalled repeat); its interval is a **Student-t interval on log time**,
``exp(mean(log t) ± t_{K-1, 0.975} · sd(log t) / √K)``, widened where needed to contain the sample median.
Load slows a render by a factor, not by an offset, so timing noise is multiplicative; for log-normal
timings the interval is exact: it covers the median of the timing distribution, exp(μ), 95% of the time
at every K ≥ 2 (the t-interval for the mean of a normal sample, e.g. Casella & Berger, *Statistical
Inference*, §9.2.2, applied to log t). Measured with 20 000 simulated experiments per case (checked by
tests/evaluate/test_timing_stats.py):

============================================  ======  ======  ======
timings, truth = the distribution's median     K = 3   K = 5   K = 10
============================================  ======  ======  ======
log-normal, σ = 0.3                            95.3%   95.2%   95.0%
floor + exponential stalls (mean 20%)          93.4%   94.6%   93.6%
floor + rare (10%) large stalls                94.2%   95.9%   97.7%
============================================  ======  ======  ======

It was chosen over the distribution-free interval between order statistics because that one cannot
reach 95% with few repeats: [min, max] of K timings covers the median with probability 1 - 2^(1-K),
75% at the default K = 3 and 94% at K = 5. The price is width: at K = 3 the t quantile is 4.30, so a
timing spread of σ = 0.3 in log gives an interval ~3.5x from end to end (a quiet machine, σ ≈ 0.02,
gives ~1.09x). With one timing there is no interval (NaN bounds); a non-positive timing has no
logarithm, so its samples get none either.

Results rows (:func:`repeat_columns`): ``time_repeats`` K, ``time_s_low`` / ``time_s_high``, the raw
timings as JSON text in ``time_samples_s``; ``cpu_time_s_low`` / ``cpu_time_s_high`` and
``cpu_time_samples_s`` likewise for process CPU time when every timing has it. The medians themselves
are ``time_s`` and ``cpu_time_s`` (:func:`cornell_harness.workflows.runner.RunRecord.row`).
"""

from __future__ import annotations

import json
import math
from typing import Sequence

import numpy as np

#: The level of every timing interval: the 95% of the results columns' contract.
LEVEL = 0.95
#: ``--time-basis``: the clock time-derived figures (time to error, efficiency, slopes against time,
#: equal time) read, and the results column that holds it. Wall by default; CPU time is not inflated by
#: other processes' load (docs/timing.md says when to prefer it).
TIME_BASES = {"wall": "time_s", "cpu": "cpu_time_s"}
#: What ``--time-basis`` takes: a clock of :data:`TIME_BASES`, or ``auto``: cpu where the timings were taken on a
#: machine busy with other work, else wall (:func:`cornell_harness.evaluate.timing_quality.auto_basis`).
TIME_BASIS_CHOICES = (*TIME_BASES, "auto")


def median_interval(samples: Sequence[float], level: float = LEVEL) -> tuple[float, float, float]:
    """(median, low, high) of repeated timings: the sample median and its Student-t interval on log time
    (module docstring: the rule and its measured coverage). NaN bounds for fewer than two timings or for a
    non-positive one; all NaN for none."""
    t = np.asarray([float(s) for s in samples], float)
    if t.size == 0 or not np.isfinite(t).all():
        return math.nan, math.nan, math.nan
    median = float(np.median(t))
    if t.size < 2 or (t <= 0).any():
        return median, math.nan, math.nan
    from scipy import stats  # here: a results row with one timing must not load SciPy

    if np.ptp(t) == 0:  # identical timings (a renderer's own clock): exactly that, not exp(log(t)) ≈ t
        return median, median, median
    logs = np.log(t)
    half = float(stats.t.ppf(0.5 + level / 2, t.size - 1)) * logs.std(ddof=1) / math.sqrt(t.size)
    # Widened to hold the median (it estimates the same exp(μ)); for K ≤ 4 the t quantile already does.
    return median, min(math.exp(logs.mean() - half), median), max(math.exp(logs.mean() + half), median)


def repeat_columns(wall: Sequence[float], cpu: Sequence[float | None] = ()) -> dict:
    """The repeat columns of a results row from its K timings, wall and process CPU (``None`` where a
    timing has no CPU time: then the CPU columns are NaN and ``cpu_time_samples_s`` is ``"[]"``). The
    medians (``time_s``, ``cpu_time_s``) are not among them: :func:`medians`."""
    _, low, high = median_interval(wall)
    out = {"time_repeats": len(wall), "time_s_low": _rounded(low), "time_s_high": _rounded(high),
           "time_samples_s": json.dumps([float(w) for w in wall])}
    cpu = list(cpu)
    known = bool(cpu) and all(c is not None and math.isfinite(c) for c in cpu)
    _, low, high = median_interval(cpu) if known else (math.nan, math.nan, math.nan)
    out.update(cpu_time_s_low=_rounded(low), cpu_time_s_high=_rounded(high),
               cpu_time_samples_s=json.dumps([float(c) for c in cpu] if known else []))
    return out


def medians(wall: Sequence[float], cpu: Sequence[float | None] = ()) -> tuple[float | None, float | None]:
    """The median wall time and median CPU time of K timings (``None`` for what is unknown)."""
    cpu = list(cpu)
    known = bool(cpu) and all(c is not None and math.isfinite(c) for c in cpu)
    return (median_interval(wall)[0] if len(wall) else None), (median_interval(cpu)[0] if known else None)


def _rounded(value: float) -> float:
    """As ``time_s`` is rounded in a results row (monotonic, so low ≤ time_s ≤ high still holds)."""
    return value if math.isnan(value) else round(value, 4)
