"""The summary's columns as a paper shows them: header with units (plain and LaTeX), direction, scale.

One table of column specs (:data:`SPECS`) for the readable ``summary.csv``
(:mod:`cornell_harness.reports.summary_files`) and ``summary.tex`` (the same module, with :mod:`cornell_harness.reports.latex`):
the raw summary (:func:`cornell_harness.evaluate.summary.summary_table`, kept with
full precision and raw names in ``summary.parquet``) has machine names such
as ``time_to_delta_e2000_mean_le_1``; here it becomes "time to mean ΔE00 ≤ 1
(s)". Also which columns are decisive (:func:`decisive_columns`, the order of
:data:`cornell_harness.reports.tables.TABLE_GROUPS`: convergence slope, time to a target,
efficiency, the equal-quality and equal-time figures, bias share) and the best
value of a column (:func:`best_rows`), and whether it is clearly best (:func:`clear_best_rows`: its 95%
interval overlaps no other's).

Directions: the registry's (:mod:`cornell_harness.evaluate.registry`) where it has
one; a time to a target and the time at the highest spp (equal quality) are
better low, the spp a time budget buys (equal time) better high. Slopes and
the bias share have none: a slope steeper than −0.5 is noise, not a better
renderer, and a share of bias says nothing about the error's size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Collection, Sequence

from cornell_harness.evaluate import registry
from cornell_harness.reports.latex import escape
from cornell_harness.reports.numbers import parse_time_to


@dataclass(frozen=True)
class Spec:
    """A summary column: ``text`` and ``tex`` headers (units included), ``better`` ("low", "high" or None),
    ``scale`` (shown value = raw × scale: a share as %)."""

    text: str
    tex: str
    better: str | None = None
    scale: float = 1.0


#: Column key → spec, for the columns of fixed name. Time-to-target and region columns: :func:`spec`.
SPECS: dict[str, Spec] = {
    "slope_rmse_spp": Spec("slope of RMSE against spp (log-log)", r"RMSE slope\\vs.\ spp"),
    "slope_rmse_time": Spec("slope of RMSE against time (log-log)", r"RMSE slope\\vs.\ time"),
    "efficiency": Spec("efficiency, 1/(MSE·s)", r"efficiency\\1/(MSE$\cdot$s)", "high"),
    "time_at_max_spp": Spec("time at the highest spp (s)", r"time at\\max.\ spp (s)", "low"),
    "spp_in_budget": Spec("spp in the time budget", r"spp in\\budget", "high"),
    "bias2_fraction": Spec("bias share (%)", r"bias\\share (\%)", None, 100.0),
    "bias2": Spec("bias² (radiance²)", r"bias$^2$", registry.METRICS["bias2"].better),
    "variance": Spec("variance (radiance²)", r"variance", registry.METRICS["variance"].better),
    "renderer": Spec("renderer", "renderer"),
    "seeds": Spec("seeds", "seeds"),
    "max_spp": Spec("highest spp", "max.\\ spp"),
    "time_column": Spec("clock", "clock"),
    "time_repeats": Spec("timing repeats", "timing repeats"),
    "interval_basis": Spec("95% intervals over", "intervals over"),
}

#: A metric's name in a header (plain, LaTeX); others: the registry's label.
_METRIC_NAMES = {
    "delta_e2000_mean": ("mean ΔE00", r"mean $\Delta E_{00}$"),
    "delta_e2000_p95": ("ΔE00 p95", r"$\Delta E_{00}$ p95"),
    "rel_mse": ("relMSE", "relMSE"),
    "rel_mse_trimmed": ("trimmed relMSE", "trim.\\ relMSE"),
    "rmse": ("RMSE", "RMSE"),
    "mse": ("MSE", "MSE"),
    "flip_mean": ("mean FLIP", "FLIP"),
}
_TEX_OPS = {"<=": r"\le", ">=": r"\ge", "<": "<", ">": ">"}
_TEXT_OPS = {"<=": "≤", ">=": "≥", "<": "<", ">": ">"}

#: Decisive figures in table order (a ``*`` ends a prefix), and which to keep first when there are more than
#: a table holds: slope, efficiency and bias share before the third and fourth time to a target. A summary of
#: single images (``cbox compare-image``'s) has none of the convergence figures: its errors are then decisive.
_IMAGE_ERRORS = ("delta_e2000_mean", "delta_e2000_p95", "flip_mean", "rel_mse", "rmse", "psnr", "ssim", "time_s")
DECISIVE = ("slope_rmse_spp", "time_to_*", "efficiency", "time_at_max_spp", "spp_in_budget", "bias2_fraction",
            "slope_rmse_time", *_IMAGE_ERRORS)
_PRIORITY = ("slope_rmse_spp", "efficiency", "bias2_fraction", "time_to_*", "spp_in_budget", "time_at_max_spp",
             "slope_rmse_time", *_IMAGE_ERRORS)


def _metric_names(metric: str) -> tuple[str, str]:
    if metric in _METRIC_NAMES:
        return _METRIC_NAMES[metric]
    if (region := registry.region_metric(metric)) is not None:
        text, tex = _metric_names(region[1])
        return f"{text} in {region[0]}", f"{tex} in {escape(region[0])}"
    label = registry.METRICS[metric].label if metric in registry.METRICS else metric
    return label, escape(label)


def spec(key: str) -> Spec:
    """The spec of any summary column: fixed ones from :data:`SPECS`, time to a target and region split columns
    by their form, anything else by its name (better None)."""
    if key in SPECS:
        return SPECS[key]
    if (parsed := parse_time_to(key)) is not None:
        metric, op, value = parsed
        text, tex = _metric_names(metric)
        return Spec(f"time to {text} {_TEXT_OPS[op]} {value:g} (s)",
                    f"time to\\\\{tex}\\\\${_TEX_OPS[op]} {value:g}$ (s)", "low")
    if key in registry.METRICS:  # a metric of the final image (compare-image's summary)
        text, tex = _metric_names(key)
        return Spec(text, tex, registry.METRICS[key].better)
    if (region := registry.region_metric(key)) is not None and region[1] in SPECS:
        base = SPECS[region[1]]
        return Spec(_in_region(base.text, region[0]), _in_region(base.tex, escape(region[0])), base.better,
                    base.scale)
    return Spec(key.replace("_", " "), escape(key.replace("_", " ")))


def _in_region(header: str, region: str) -> str:
    """``bias² (radiance²)`` → ``bias² in walls (radiance²)``: the region before the unit."""
    head, sep, unit = header.rpartition(" (")
    return f"{head} in {region}{sep}{unit}" if sep and header.endswith(")") else f"{header} in {region}"


def _matches(key: str, pattern: str) -> bool:
    return key.startswith(pattern[:-1]) if pattern.endswith("*") else key == pattern


def is_bound(key: str, columns: Sequence[str]) -> bool:
    """A column that bounds another (``F_low``, ``F_high``, ``F_ci`` beside ``F``): never a column of its own."""
    for suffix in ("_low", "_high", "_ci"):
        if key.endswith(suffix) and key[: -len(suffix)] in columns:
            return True
    return False


def decisive_columns(columns: Sequence[str], max_columns: int = 8, empty: Collection[str] = ()) -> list[str]:
    """The decisive figures among ``columns`` (a summary's) but those ``empty`` (no row has a value), at most
    ``max_columns``, in table order (:data:`DECISIVE`); when more are present, those first in
    :data:`_PRIORITY` are kept."""
    present = [c for c in columns if not is_bound(c, columns) and c not in empty]
    ordered = [c for p in DECISIVE for c in present if _matches(c, p)]
    kept = [c for p in _PRIORITY for c in ordered if _matches(c, p)][:max_columns]
    return [c for c in ordered if c in kept]


def _finite(v: Any) -> bool:
    try:
        return math.isfinite(float(v))
    except (TypeError, ValueError):
        return False


def best_rows(values: Sequence[Any], better: str | None) -> set[int]:
    """Indices of the best finite values (min for "low", max for "high"; all of a tie); none without a direction."""
    finite = [(i, float(v)) for i, v in enumerate(values) if _finite(v)]
    if better not in ("low", "high") or not finite:
        return set()
    best = (min if better == "low" else max)(v for _, v in finite)
    return {i for i, v in finite if v == best}


def clear_best_rows(values: Sequence[Any], lows: Sequence[Any], highs: Sequence[Any], better: str | None) -> set[int]:
    """The row of the one best value (:func:`best_rows`) where its 95% interval ``[low, high]`` overlaps the
    interval of no other row with a value (a value without an interval counts as the point it is); none for
    a tie, a single row, or a best that the others' intervals do not rule out being beaten."""
    best = best_rows(values, better)
    if len(best) != 1 or len(values) < 2:
        return set()

    def interval(j: int) -> tuple[float, float]:
        if _finite(lows[j]) and _finite(highs[j]):
            return float(lows[j]), float(highs[j])
        return float(values[j]), float(values[j])

    (i,) = best
    lo, hi = interval(i)
    for j, v in enumerate(values):
        if j != i and _finite(v):
            other_lo, other_hi = interval(j)
            if lo <= other_hi and other_lo <= hi:
                return set()
    return best
