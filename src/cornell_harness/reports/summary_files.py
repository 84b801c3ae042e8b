"""The summary as files people use as they are: ``summary.csv`` (readable) and ``summary.tex`` (a paper table).

The raw summary (:func:`cornell_harness.evaluate.summary.summary_table`: machine
names, full precision) is ``summary.parquet``, written by the workflow
(:func:`cornell_harness.workflows.converge.experiment_results`). Beside every report
(:func:`cornell_harness.reports.html.write_report`; for a merged report,
:func:`cornell_harness.reports.merge.write_merged_report`) this module writes

- ``summary.csv``: every column under a header with its unit ("time to mean
  ΔE00 ≤ 1 (s)"), values at 4 significant digits, each 95% interval as two
  columns of its own ("… 95% low", "… 95% high"), a bias share in %; a merged
  report's has an ``experiment`` column first;
- ``summary.tex``: a booktabs ``tabular`` of the decisive columns
  (:func:`cornell_harness.reports.summary_columns.decisive_columns`, at most 8) with their 95%
  intervals (the rule: :mod:`cornell_harness.reports.latex`) and the best value of each column
  in bold (its direction: :data:`cornell_harness.reports.summary_columns.SPECS`); a merged
  report's has one table per experiment, each titled with its label.

Renderers are shown by ``series_labels.get(name, name)``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from cornell_harness.evaluate.convergence import bias_significant
from cornell_harness.store.atomic import write_text_atomic
from cornell_harness.reports import latex
from cornell_harness.reports.summary_columns import best_rows, decisive_columns, is_bound, spec

CSV_FILE, TEX_FILE = "summary.csv", "summary.tex"
#: Significant digits of the readable CSV: more than a table shows, far fewer than the 17 of a float.
CSV_DIGITS = 4
_CLOCKS = {"time_s": "wall", "cpu_time_s": "CPU"}
_NOT_SIGNIFICANT = "n.s."


def _round(v, digits: int = CSV_DIGITS):
    """A number at ``digits`` significant digits (integers as they are); anything else unchanged."""
    if v is None or isinstance(v, (bool, str)):
        return v
    if isinstance(v, (int, np.integer)):
        return int(v)
    try:
        f = float(v)
    except (TypeError, ValueError):
        return v
    return latex.round_sig(f, digits) if math.isfinite(f) else f


def readable_summary(summary: pd.DataFrame, series_labels: Mapping[str, str] | None = None) -> pd.DataFrame:
    """The summary with readable headers and units, rounded values, each interval as two columns; the renderer
    column by its label (and a ``recorded name`` column where a label differs from it)."""
    labels = dict(series_labels or {})
    cols = list(summary.columns)
    out: dict[str, list] = {}
    for c in cols:
        if is_bound(c, cols):
            continue
        values = list(summary[c])
        if c == "renderer":
            out["renderer"] = [labels.get(str(n), str(n)) for n in values]
            if out["renderer"] != [str(n) for n in values]:
                out["recorded name"] = [str(n) for n in values]
            continue
        s = spec(c)
        if c == "time_column":
            out[s.text] = [_CLOCKS.get(str(v), v) for v in values]
            continue
        out[s.text] = [_round(_scaled(v, s.scale)) for v in values]
        for end in ("low", "high"):
            if f"{c}_{end}" in cols:
                out[f"{s.text} 95% {end}"] = [_round(_scaled(v, s.scale)) for v in summary[f"{c}_{end}"]]
        if f"{c}_ci" in cols and f"{c}_low" not in cols:  # a slope's Student-t half-width alone
            out[f"{s.text} 95% half-width"] = [_round(_scaled(v, s.scale)) for v in summary[f"{c}_ci"]]
    return pd.DataFrame(out)


def _scaled(v, scale: float):
    if scale == 1.0:
        return v
    try:
        return float(v) * scale
    except (TypeError, ValueError):
        return v


def summary_tex(summary: pd.DataFrame, series_labels: Mapping[str, str] | None = None,
                max_columns: int = 8) -> str:
    """A booktabs ``tabular``: a renderer column, then the decisive figures with units, 95% intervals and the
    best value per column in bold (see the module)."""
    labels = dict(series_labels or {})
    records = summary.to_dict("records")
    keys = decisive_columns(list(summary.columns), max_columns)
    header = ["renderer"] + [spec(k).tex for k in keys]
    columns = []
    for k in keys:
        s = spec(k)
        best = best_rows([r.get(k) for r in records], s.better)
        cells = []
        for i, r in enumerate(records):
            if k.endswith("bias2_fraction") and bias_significant(r.get(k + "_low")) is False:
                cells.append(_NOT_SIGNIFICANT)
                continue
            low, high = _bounds(r, k)
            cells.append(latex.value_cell(_scaled(r.get(k), s.scale), _scaled(low, s.scale), _scaled(high, s.scale),
                                          bold=i in best))
        columns.append(cells)
    rows = [[latex.escape(labels.get(str(r["renderer"]), str(r["renderer"])))] + [c[i] for c in columns]
            for i, r in enumerate(records)]
    return latex.tabular(header, rows, "l" + "r" * len(keys))


def _bounds(row: Mapping, key: str) -> tuple:
    """``key``'s 95% interval in ``row``: its ``_low`` / ``_high``, else value ± its ``_ci`` half-width."""
    if key + "_low" in row and key + "_high" in row:
        return row[key + "_low"], row[key + "_high"]
    try:
        v, ci = float(row[key]), float(row[key + "_ci"])
    except (KeyError, TypeError, ValueError):
        return None, None
    return v - ci, v + ci


_TEX_NOTE = (
    "% Written by cbox (src/cornell_harness/reports/summary_files.py). Needs \\usepackage{booktabs}.\n"
    "% One row per renderer at its highest spp; best value per column in bold (no bold where a column has no\n"
    "% better direction: slopes, bias share). v \\pm h and v^{+a}_{-b}: 95% intervals over seeds and timing\n"
    f"% repeats; {latex.MISSING}: no value (a target not reached); {_NOT_SIGNIFICANT}: a bias share whose 95% "
    "interval reaches 0.\n")


def write_summary_files(folder, tables: Sequence[tuple[str | None, pd.DataFrame]],
                        series_labels: Mapping[str, str] | None = None) -> list[Path]:
    """Write ``folder/summary.csv`` and ``folder/summary.tex`` atomically for ``tables``, each (experiment label
    or None, raw summary); empty summaries are left out, and nothing is written without any. One unlabelled
    table: its own; several: an ``experiment`` column in the CSV, one titled ``tabular`` each in the TeX."""
    tables = [(label, s) for label, s in tables if s is not None and len(s)]
    if not tables:
        return []
    folder = Path(folder)
    labelled = len(tables) > 1 or tables[0][0] is not None
    frames, blocks = [], []
    for label, s in tables:
        frame = readable_summary(s, series_labels)
        if labelled:
            frame.insert(0, "experiment", label)
            blocks.append(f"\\noindent\\textbf{{{latex.escape(label)}}}\\par\\smallskip\n"
                          f"{summary_tex(s, series_labels)}\\par\\bigskip\n")
        else:
            blocks.append(summary_tex(s, series_labels))
        frames.append(frame)
    csv_path, tex_path = folder / CSV_FILE, folder / TEX_FILE
    write_text_atomic(csv_path, pd.concat(frames, ignore_index=True).to_csv(index=False))
    write_text_atomic(tex_path, _TEX_NOTE + "\n".join(blocks))
    return [csv_path, tex_path]
