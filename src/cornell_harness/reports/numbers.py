"""How the report prints a number: metric labels, value formatting, the notes beside a value, and thresholds.

Shared by every table of the report and the terminal's (:mod:`cornell_harness.reports.tables`,
:mod:`~cornell_harness.reports.regions`, :mod:`~cornell_harness.reports.scenes`): one format per key, so
the same value reads the same everywhere.
"""

from __future__ import annotations

import math
import re
from typing import Any, Mapping

import numpy as np
import pandas as pd

from cornell_harness.evaluate import registry
from cornell_harness.evaluate.convergence import bias_significant

# Metric key -> (short label, definition, better: "low" | "high" | None), from the harness's one registry.
METRICS: dict[str, tuple[str, str, str | None]] = {
    k: (m.label, m.definition, m.better) for k, m in registry.METRICS.items()}

#: A column whose interval the summary holds under another name.
_BOUNDS_OF = {"time_s": "time_at_max_spp"}

#: A threshold's comparison as the page prints it.
OPERATOR_SIGNS = {"<=": "≤", ">=": "≥", "<": "<", ">": ">"}




def is_number(v: Any) -> bool:
    """A number (Python's or numpy's), not a bool."""
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)


def is_finite(v: Any) -> bool:
    """A finite number (not a string, None or NaN)."""
    return is_number(v) and math.isfinite(float(v))


def is_missing(v: Any) -> bool:
    """None, NaN or pandas' NA: a cell with nothing to show."""
    if v is None:
        return True
    try:
        return bool(pd.isna(v))
    except (TypeError, ValueError):
        return False


def _generic(v: float) -> str:
    if v == 0:
        return "0"
    a = abs(v)
    if a >= 1e5 or a < 1e-3:
        return f"{v:.3e}"
    return f"{v:.4g}"


def _seconds(v: float) -> str:
    if v < 0.01:
        return f"{v:.2e}"
    return f"{v:.3f}" if v < 100 else f"{v:.1f}"


def format_value(key: str, v: Any) -> str:
    """A table cell: sensible precision per metric, "—" for missing values."""
    if v is None:
        return "—"
    if not is_number(v):
        return str(v)
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    v = float(v)
    if math.isnan(v):
        return "NaN"
    if math.isinf(v):
        return "∞" if v > 0 else "−∞"
    if key.endswith("_count") or key in ("spp", "seeds", "max_spp", "pixels"):
        return str(int(v)) if v.is_integer() else _generic(v)
    if key == "time_s" or key.startswith("time_to_"):
        return _seconds(v)
    if key == "psnr":
        return f"{v:.2f}"
    if key == "ssim":
        return f"{v:.4f}"
    if "frac" in key:
        return f"{100 * v:.1f} %"
    if key == "mean_radiance_rel_error":
        return f"{100 * v:+.2f} %"
    if key.endswith("_z") or key.startswith("slope_"):
        return f"{v:+.2f}"
    if key.startswith("delta_e2000") or key.startswith("noise_delta_e2000"):
        return f"{v:.2f}"
    if _is_negative_bias2(key, v):
        return "≈ 0"  # see value_note
    return _generic(v)


def _is_negative_bias2(key: str, v: float) -> bool:
    return key.endswith("bias2") and v < 0


def value_note(key: str, v: Any) -> str:
    """A cell's tooltip when its text alone would mislead: a negative bias² estimate; else "".

    bias² is estimated as the squared error of the mean over seeds less the noise that mean still
    has (and the reference's own variance): unbiased, so for a renderer without bias it falls below
    zero about half the time. A true bias² cannot be negative, so the cell says "≈ 0" (no bias
    measurable above the noise) rather than "-8.6e-06", which reads as a value, or "< 0", which reads
    as an impossibility; the tooltip keeps the raw estimate, and the column sorts on it.
    """
    if not is_finite(v) or not _is_negative_bias2(key, float(v)):
        return ""
    raw = "−" + f"{-float(v):.2g}"  # a typographic minus for the sign; the exponent's stays ASCII (−8.6e-06)
    return f"estimate {raw}: below zero by noise alone; no bias measurable above the noise"


def interval_note(key: str, row: Mapping) -> tuple[str, str]:
    """(text after a cell's value, tooltip) for a figure with a 95% interval in ``row`` (``<key>_low`` /
    ``_high``, or a slope's ``_ci`` half-width); ("", "") without one.

    A slope's interval is symmetric: ± its half-width. Others (times, efficiencies) are asymmetric, on the log
    scale: the bounds in brackets. The tooltip says what the interval covers (the summary's ``interval_basis``).
    """
    base = _BOUNDS_OF.get(key, key)
    lo, hi = row.get(base + "_low"), row.get(base + "_high")
    basis = row.get("interval_basis")
    over = f" over {basis}" if isinstance(basis, str) and basis else ""
    if is_finite(lo) and is_finite(hi):
        lo, hi = float(lo), float(hi)
        if key.endswith("bias2") and lo < 0:
            lo = 0.0  # a bias² is not negative: its interval ends at 0 (the estimate itself may dip below)
        title = f"95% confidence interval {format_value(key, lo)} to {format_value(key, hi)}{over}"
        if key.startswith("slope_"):
            return f" ± {(hi - lo) / 2:.2f}", title
        return f" ({format_value(key, lo)}–{format_value(key, hi)})", title
    ci = row.get(key + "_ci")
    if key.startswith("slope_") and is_finite(ci):
        return f" ± {float(ci):.2f}", "95% confidence half-width over seeds"
    return "", ""


def bias_share_note(row: Mapping, key: str = "bias2_fraction") -> tuple[str, str] | None:
    """("not significant", why) for a bias share whose 95% interval reaches 0; None otherwise (a number is then
    shown). A share whose interval reaches 0 says nothing about bias: its point estimate (14.5% for the
    reference renderer at 2 seeds) would suggest one."""
    if bias_significant(row.get(key + "_low")) is not False:
        return None
    v, hi = row.get(key), row.get(key + "_high")
    est = f"estimate {format_value(key, v)}, " if is_finite(v) else ""
    upto = f"95% interval 0 to {format_value(key, hi)}" if is_finite(hi) else "its 95% interval reaches 0"
    return "not significant", f"{est}{upto}: no bias measurable above the noise"


def parse_time_to(key: str) -> tuple[str, str, float] | None:
    """``time_to_rel_mse_le_0.001`` → ("rel_mse", "<=", 0.001); None if not of that form."""
    m = re.fullmatch(r"time_to_(.+)_(le|lt|ge|gt)_([-+0-9.eE]+)", key)
    if not m:
        return None
    op = {"le": "<=", "lt": "<", "ge": ">=", "gt": ">"}[m.group(2)]
    try:
        return m.group(1), op, float(m.group(3))
    except ValueError:
        return None


def column_label(key: str) -> tuple[str, str]:
    """(header, definition) of a table column."""
    if key in METRICS:
        return METRICS[key][0], METRICS[key][1]
    if key.startswith("noise_"):
        return key.removeprefix("noise_").replace("_", " ") + " (noise)", "noise yardstick at this spp"
    parsed = parse_time_to(key)
    if parsed:
        metric, op, value = parsed
        label = METRICS.get(metric, (metric,))[0]
        return (f"time to {label} {OPERATOR_SIGNS[op]} {value:g}",
                f"seconds to reach {metric} {OPERATOR_SIGNS[op]} {value:g} (median over seeds; — if never reached)")
    return key.replace("_", " "), key


def check_threshold(value: Any, op: str, limit: float) -> bool:
    """Does ``value`` meet ``op limit``? A missing or NaN value does not."""
    if op not in OPERATOR_SIGNS:
        raise ValueError(f"threshold operator {op!r}: expected one of {', '.join(OPERATOR_SIGNS)}")
    if is_missing(value) or not is_number(value) or math.isnan(float(value)):
        return False
    v = float(value)
    return {"<=": v <= limit, ">=": v >= limit, "<": v < limit, ">": v > limit}[op]
