"""An experiment's summary: derived figures per renderer and the bias/variance split, image-wide and per region.

Computed from an experiment's results table and its stored highest-spp
images (:mod:`cornell_harness.store.experiments`); the workflow writes it as
``summary.parquet`` (:func:`cornell_harness.workflows.converge.experiment_results`) and
the reports draw it. Nothing here reads or writes files.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple, Sequence

import numpy as np
import pandas as pd

from cornell_harness.evaluate import convergence
from cornell_harness.evaluate.regions import nested_regions, region_columns, region_masks
from cornell_harness.scenes.model import Scene

if TYPE_CHECKING:
    from cornell_harness.store.references import Reference

#: The per-region columns :func:`summary_table` adds, in table order.
REGION_SPLIT = ("bias2", "variance", "bias2_fraction")
#: Their 95% intervals (:func:`cornell_harness.evaluate.convergence.bias_variance`), also per region.
REGION_SPLIT_BOUNDS = tuple(f"{k}_{end}" for k in REGION_SPLIT for end in ("low", "high"))


class ExperimentResults(NamedTuple):
    """What an experiment folder holds and what is derived from it: what a report draws."""

    config: dict  # experiment.json
    runs: pd.DataFrame  # results.parquet
    images: dict[str, list[np.ndarray]]  # highest-spp images per renderer, in seed order
    summary: pd.DataFrame  # summary_table's; empty when nothing ran


def summary_table(runs: pd.DataFrame, images: dict[str, list[np.ndarray]], reference: Reference, scene: Scene,
                  targets=convergence.DEFAULT_TARGETS, deterministic: Sequence[str] = (),
                  time_column: str = "time_s") -> pd.DataFrame:
    """Derived figures per renderer, with the bias/variance split from the stored images.

    Time-derived figures read ``time_column`` (``time_s`` or ``cpu_time_s``) and come with ``_low`` /
    ``_high`` 95% bounds (:func:`cornell_harness.evaluate.convergence.summarize`); so do ``bias2``, ``variance``
    and ``bias2_fraction``. For a scene with named regions the split is also given per region, as
    columns ``region.<name>.bias2``, ``.variance``, ``.bias2_fraction`` and their bounds
    (:func:`cornell_harness.evaluate.convergence.region_bias_variance`).
    """
    summary = convergence.summarize(runs, targets, time_column)
    if summary.empty:
        return summary
    masks = region_masks(scene)
    rows = []
    for r in summary["renderer"]:
        finals, det = images.get(r, []), r in deterministic
        row = convergence.bias_variance(finals, reference.image, reference.variance, det)
        if masks:
            row.update(region_columns(convergence.region_bias_variance(finals, reference.image, reference.variance,
                                                                       masks, det)))
        rows.append(row)
    return pd.concat([summary, pd.DataFrame(rows)], axis=1)


def region_split(summary: pd.DataFrame) -> pd.DataFrame:
    """The per-region bias/variance columns of a summary as long rows: renderer, region, bias2, variance,
    bias2_fraction and their bounds (empty without them); in summary order, regions in column order."""
    rows = []
    keys = (*REGION_SPLIT, *REGION_SPLIT_BOUNDS)
    for rec in summary.to_dict("records") if summary is not None else []:
        for region, values in nested_regions(rec).items():
            if any(k in values for k in REGION_SPLIT):
                rows.append({"renderer": rec["renderer"], "region": region,
                             **{k: values.get(k, math.nan) for k in keys}})
    return pd.DataFrame(rows, columns=["renderer", "region", *keys])


def with_intervals(table: pd.DataFrame) -> pd.DataFrame:
    """A summary (or :func:`region_split`) for printing: each figure with a 95% interval as one text cell,
    ``value (low–high)``; the bound columns (``_low``, ``_high``, ``_ci``) dropped; a bias share whose
    interval reaches 0 as "not significant" (:func:`cornell_harness.evaluate.convergence.bias_significant`)."""
    out = {}
    bounds = {c for c in table.columns if c.endswith(("_low", "_high", "_ci"))
              and c.rsplit("_", 1)[0] in table.columns}
    for col in table.columns:
        if col in bounds:
            continue
        if f"{col}_low" not in table.columns or f"{col}_high" not in table.columns:
            out[col] = table[col]
            continue
        cells = []
        for v, lo, hi in zip(table[col], table[f"{col}_low"], table[f"{col}_high"]):
            if col.endswith("bias2_fraction") and convergence.bias_significant(lo) is False:
                cells.append("not significant")
            elif _finite(v) and _finite(lo) and _finite(hi):
                cells.append(f"{v:.4g} ({lo:.4g}–{hi:.4g})")
            else:
                cells.append(f"{v:.4g}" if _finite(v) else "NaN")
        out[col] = cells
    return pd.DataFrame(out, index=table.index)


def _finite(v) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and math.isfinite(float(v))
