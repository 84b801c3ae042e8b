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
- ``summary.tex`` and ``summary-wide.tex``: a booktabs table float, ``table`` to fit one column of a
  two-column page and ``table*`` to fit the full text width (:data:`TEX_LAYOUTS`), of the decisive
  columns (:func:`cornell_harness.reports.summary_columns.decisive_columns`; at most 4 and 8) that some
  renderer has a value of, with their 95% intervals (the rule: :mod:`cornell_harness.reports.latex`);
  a column's best value is in bold only where its interval overlaps no other renderer's
  (:func:`cornell_harness.reports.summary_columns.clear_best_rows`; the direction:
  :data:`cornell_harness.reports.summary_columns.SPECS`), and the caption says so; a merged
  report's has one float per experiment, its caption led by the experiment's label.

Renderers are shown by ``series_labels.get(name, name)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from cornell_harness.evaluate.convergence import bias_significant
from cornell_harness.store.atomic import write_text_atomic
from cornell_harness.reports import latex
from cornell_harness.reports.summary_columns import clear_best_rows, decisive_columns, is_bound, spec

CSV_FILE, TEX_FILE, WIDE_TEX_FILE = "summary.csv", "summary.tex", "summary-wide.tex"
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


@dataclass(frozen=True)
class TexLayout:
    """How a ``summary.tex`` variant fits its width: the float (``wide``: ``table*``) and the width it is laid
    out for (``width_pt``), at most ``figures`` columns after the renderer's, names wrapped at about
    ``name_chars`` characters, the font (``size`` of ``font_pt``)."""

    file: str
    wide: bool
    width_pt: float
    figures: int
    name_chars: int
    size: str = "footnotesize"
    font_pt: float = 8.0


#: One column of a two-column page, and the full text width: a standard two-column ``article``'s (229.5 pt and
#: 469 pt; ACM's and IEEE's two-column formats are wider).
TEX_LAYOUTS = (TexLayout(TEX_FILE, False, 229.5, 8, 14), TexLayout(WIDE_TEX_FILE, True, 469.0, 8, 24))
_GAP_PT = 6.0  # between two columns: twice the float's \tabcolsep


def _has_value(records: Sequence[Mapping], key: str) -> bool:
    return any(latex.value_cell(r.get(key)) != latex.MISSING for r in records)


def _column(records: Sequence[Mapping], key: str) -> list[str]:
    """``key``'s cells, one per record: a value with its 95% interval, in bold where clearly best."""
    s = spec(key)
    bounds = [_bounds(r, key) for r in records]
    best = clear_best_rows([r.get(key) for r in records], [b[0] for b in bounds], [b[1] for b in bounds], s.better)
    cells = []
    for i, (r, (low, high)) in enumerate(zip(records, bounds)):
        if key.endswith("bias2_fraction") and bias_significant(r.get(key + "_low")) is False:
            cells.append(_NOT_SIGNIFICANT)
            continue
        cells.append(latex.value_cell(_scaled(r.get(key), s.scale), _scaled(low, s.scale), _scaled(high, s.scale),
                                      bold=i in best))
    return cells


def summary_tex(summary: pd.DataFrame, series_labels: Mapping[str, str] | None = None,
                layout: TexLayout = TEX_LAYOUTS[0], title: str | None = None, label: str = "tab:cbox-summary") -> str:
    """A booktabs table float: a renderer column, then as many of the decisive figures that some row has a
    value of as ``layout``'s width holds, with units, 95% intervals, and a column's best value in bold where
    its interval overlaps no other row's; the caption (``title`` first) says what the numbers and marks are."""
    labels = dict(series_labels or {})
    records = summary.to_dict("records")
    cols, empty = list(summary.columns), [c for c in summary.columns if not _has_value(records, c)]
    names = [[latex.escape(line) for line in latex.break_lines(labels.get(str(r["renderer"]), str(r["renderer"])),
                                                               layout.name_chars)] for r in records]
    columns = {k: _column(records, k) for k in decisive_columns(cols, layout.figures, empty)}

    def width(cells: Sequence[str], header: str) -> float:
        return _GAP_PT + max(latex.approx_width(t, layout.font_pt) for t in [*cells, *header.split("\\\\")])

    widths = {k: width(c, spec(k).tex) for k, c in columns.items()}
    room = layout.width_pt - width([line for n in names for line in n], "renderer")
    n = len(columns)
    while n > 1 and sum(widths[k] for k in decisive_columns(cols, n, empty)) > room:
        n -= 1
    keys = decisive_columns(cols, n, empty)
    header = ["renderer"] + [spec(k).tex for k in keys]
    rows = [[latex.stacked_cell(name)] + [columns[k][i] for k in keys] for i, name in enumerate(names)]
    table = latex.tabular(header, rows, "l" + "r" * len(keys))
    marks = {c for k in keys for c in columns[k] if c in (latex.MISSING, _NOT_SIGNIFICANT)}
    return latex.table_float(table, _caption(title, marks), label, layout.wide, layout.size)


def _caption(title: str | None, marks: set[str]) -> str:
    """What the table shows, for its caption: the bold rule always, the marks only where cells carry them."""
    parts = [f"\\textbf{{{latex.escape(title)}}}." if title else "",
             "One row per renderer at its highest spp; $v \\pm h$ and $v^{+a}_{-b}$: 95\\% intervals over seeds and "
             "timing repeats. Bold: a column's best value where its 95\\% interval overlaps no other renderer's."]
    if latex.MISSING in marks:
        parts.append(f"{latex.MISSING}: no value (a target not reached).")
    if _NOT_SIGNIFICANT in marks:
        parts.append(f"{_NOT_SIGNIFICANT}: a bias share whose 95\\% interval reaches 0.")
    return " ".join(p for p in parts if p)


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
    "% Written by cbox (src/cornell_harness/reports/summary_files.py). Needs \\usepackage{booktabs} and\n"
    "% \\usepackage{graphicx} (which shrinks the table only where the page is narrower than it is laid out for).\n"
    "% No bold where a column has no better direction: slopes, bias share.\n")


def write_summary_files(folder, tables: Sequence[tuple[str | None, pd.DataFrame]],
                        series_labels: Mapping[str, str] | None = None) -> list[Path]:
    """Write ``folder/summary.csv``, ``folder/summary.tex`` (one column of a two-column page) and
    ``folder/summary-wide.tex`` (a ``table*`` of the full text width) atomically for ``tables``, each
    (experiment label or None, raw summary); empty summaries are left out, and nothing is written without any.
    One unlabelled table: its own; several: an ``experiment`` column in the CSV, one float each in the TeX,
    its caption led by its label."""
    tables = [(label, s) for label, s in tables if s is not None and len(s)]
    if not tables:
        return []
    folder = Path(folder)
    labelled = len(tables) > 1 or tables[0][0] is not None
    frames = []
    for label, s in tables:
        frame = readable_summary(s, series_labels)
        if labelled:
            frame.insert(0, "experiment", label)
        frames.append(frame)
    csv_path = folder / CSV_FILE
    write_text_atomic(csv_path, pd.concat(frames, ignore_index=True).to_csv(index=False))
    paths = [csv_path]
    for layout in TEX_LAYOUTS:
        base = "tab:cbox-summary" + ("-wide" if layout.wide else "")
        blocks = [summary_tex(s, series_labels, layout, title=label,
                              label=f"{base}-{i + 1}" if labelled else base) for i, (label, s) in enumerate(tables)]
        paths.append(folder / layout.file)
        write_text_atomic(paths[-1], _TEX_NOTE + "\n".join(blocks))
    return paths
