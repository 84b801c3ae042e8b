"""Confidence intervals of time-derived figures: a bootstrap over seeds and over timing repeats.

A figure such as the time to a target error or the efficiency is an
aggregate over seeds (median or mean) of a per-seed value computed from the
seed's error curve and its rows' times. It varies for two reasons:

- **seeds**: another seed gives another error curve (and was timed on its own);
- **timing**: the same render timed again takes another time. A row re-timed
  K times (``time_repeats``) carries its K timings as JSON text in
  ``time_samples_s`` (``cpu_time_samples_s`` for CPU time), its time being their
  median.

Each source's variance is estimated by a bootstrap (Efron & Tibshirani 1993,
*An Introduction to the Bootstrap*, ch. 6: the bootstrap estimate of standard
error): seeds resampled with replacement, the aggregate recomputed; and, apart,
every row's K timings resampled with replacement, the row's time their median,
the figure recomputed. The two variances add; the interval is Student-t with
Welch–Satterthwaite degrees of freedom (n_seeds − 1 and K − 1), on the log
scale for a positive figure (times and efficiencies are ratios: their spread
is multiplicative). The plain percentile bootstrap (Efron & Tibshirani ch. 13)
is not used: with the 2-5 seeds and 3 repeats an experiment has, a
percentile interval cannot leave the range of the data, so it covers a median
of 2 seeds half the time; the t quantile on few degrees of freedom is what
makes the interval honest there (``tests/evaluate/test_bootstrap.py``:
20 simulated experiments with a known truth). The bootstrap variance of a
mean of n is (n − 1)/n of the usual one; it is scaled back by n/(n − 1).

A row without repeats (K = 1, results written before repeats existed) adds
no timing spread: its interval then covers the seeds only, and
:func:`basis` says so. Resampling uses a fixed RNG seed
(:data:`RNG_SEED`): the same results give the same summary.
"""

from __future__ import annotations

import json
import math
from typing import Callable

import numpy as np
from scipy import stats as _st

#: Confidence level of every interval.
LEVEL = 0.95
#: Bootstrap resamples per variance component.
RESAMPLES = 1000
#: Seed of the resampling RNG: summaries are reproducible.
RNG_SEED = 20261203


def rng() -> np.random.Generator:
    return np.random.default_rng(RNG_SEED)


def samples_column(time_column: str) -> str:
    """Where a time column's raw repeats are: ``time_s`` → ``time_samples_s``, ``cpu_time_s`` → ``cpu_time_samples_s``."""
    return time_column[:-2] + "_samples_s" if time_column.endswith("_s") else time_column + "_samples"


def parse_samples(text, fallback: float) -> np.ndarray:
    """A row's timings from its JSON text (finite, positive ones); ``[fallback]`` where there are none."""
    values: list = []
    if isinstance(text, (list, tuple, np.ndarray)):
        values = list(text)
    elif isinstance(text, str) and text.strip():
        try:
            parsed = json.loads(text)
            values = parsed if isinstance(parsed, list) else [parsed]
        except ValueError:
            values = []
    v = np.array([x for x in values if isinstance(x, (int, float)) and math.isfinite(x) and x > 0], float)
    return v if v.size else np.array([fallback], float)


def resampled_times(samples: list[np.ndarray], resamples: int, gen: np.random.Generator) -> np.ndarray:
    """(resamples, rows): per row, the median of its timings resampled with replacement (its one time when K = 1)."""
    out = np.empty((resamples, len(samples)))
    for j, s in enumerate(samples):
        if s.size < 2:
            out[:, j] = s[0] if s.size else math.nan
        else:
            out[:, j] = np.median(s[gen.integers(0, s.size, (resamples, s.size))], axis=1)
    return out


def basis(n_seeds: int, repeats: int) -> str:
    """What an interval covers, in words (the summary's ``interval_basis``)."""
    seeds = n_seeds >= 2
    if seeds and repeats >= 2:
        return "seeds and timing repeats"
    if seeds:
        return "seeds only (one timing per render: timing spread unknown)"
    if repeats >= 2:
        return "timing repeats only (one seed)"
    return "none (one seed, one timing)"


def interval(point: float, seed_values: np.ndarray, timing_values: np.ndarray | None,
             aggregate: Callable[..., np.ndarray], repeats: int, log: bool = True,
             gen: np.random.Generator | None = None, level: float = LEVEL) -> tuple[float, float]:
    """(low, high) around ``point`` from the per-seed values of a figure.

    ``seed_values``: (n,) the figure per seed at the rows' times;
    ``timing_values``: (B, n) the same with resampled timings (:func:`resampled_times`), or None without repeats;
    ``aggregate(values, axis)``: how seeds combine (``np.nanmedian``, ``np.nanmean``); ``repeats``: K;
    ``log``: the interval of a positive figure, on the log scale. NaN, NaN when no source of spread is known.
    """
    gen = gen or rng()
    g = _log if log else (lambda v: v)
    if not np.isfinite(point) or (log and point <= 0):
        return math.nan, math.nan
    seed_values = np.asarray(seed_values, float)
    ok = np.isfinite(seed_values) & ((seed_values > 0) if log else True)
    terms = []  # (variance, degrees of freedom)
    n = int(ok.sum())
    if n >= 2:
        v = seed_values[ok]
        reps = aggregate(v[gen.integers(0, n, (RESAMPLES, n))], axis=1)
        terms.append((_var(g(reps)) * n / (n - 1), n - 1))
    if timing_values is not None and repeats >= 2:
        reps = aggregate(np.asarray(timing_values, float)[:, ok] if n else timing_values, axis=1)
        terms.append((_var(g(reps)) * repeats / (repeats - 1), repeats - 1))
    terms = [(v, d) for v, d in terms if np.isfinite(v)]
    if not terms:
        return math.nan, math.nan
    var = sum(v for v, _ in terms)
    if var <= 0:
        return float(point), float(point)
    df = var**2 / sum(v**2 / d for v, d in terms if v > 0)
    half = _st.t.ppf(0.5 + level / 2, df) * math.sqrt(var)
    centre = g(np.array([point]))[0]
    lo, hi = centre - half, centre + half
    return (math.exp(lo), math.exp(hi)) if log else (float(lo), float(hi))


def _log(v):
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.log(np.where(np.asarray(v, float) > 0, v, np.nan))


def _var(v: np.ndarray) -> float:
    v = np.asarray(v, float)
    total = v.size
    v = v[np.isfinite(v)]
    # A figure most resamples cannot compute (a target most resampled seeds miss) has no usable spread.
    if v.size < max(2, total // 2):
        return math.nan
    return 0.0 if np.ptp(v) == 0 else float(v.var(ddof=1))  # identical values: exactly no spread, not round-off


def median_interval(values, samples: list[np.ndarray] | None = None, log: bool = True) -> tuple[float, float, float]:
    """(median, low, high) over seeds of per-seed ``values`` (e.g. one checkpoint's error or time), with the
    interval of :func:`interval`; ``samples``: per seed, the timing repeats whose median its value is."""
    values = np.asarray(values, float)
    if not np.isfinite(values).any():
        return math.nan, math.nan, math.nan
    point = float(np.nanmedian(values))
    gen = rng()
    repeats = max((s.size for s in samples), default=1) if samples is not None else 1
    timing = resampled_times(samples, RESAMPLES, gen) if repeats >= 2 else None
    return (point, *interval(point, values, timing, np.nanmedian, repeats, log, gen))
