"""The summary table for print: the same header and rows (:func:`cornell_harness.reports.tables.summary_rows`) split into tables
of at most :data:`MAX_COLUMNS` columns each, the renderer column repeated in each.

On screen the summary is one wide table that scrolls (~30 columns); an A4 page (about 718 CSS px between 15 mm
margins) cannot hold it, so the report also carries these tables, hidden on screen and shown in print in its
place (``report.css``, ``@media print``). Columns are packed in table order, a group (convergence, bias /
variance, run, ...) kept in one table where it fits; a group wider than a table is cut. A renderer that did not
run shows its reason in the first table only.
"""

from __future__ import annotations

from typing import Mapping, Sequence

#: Columns of one printed table besides the renderer column.
MAX_COLUMNS = 8


def column_chunks(groups: Sequence[tuple[str, int]], max_columns: int = MAX_COLUMNS) -> list[list[int]]:
    """Indices of the columns (after the first: the renderer) of each printed table, from the header's
    (group title, span) in order; a group is kept whole where it fits in the table being filled or a new one."""
    chunks: list[list[int]] = [[]]
    start = 0
    for _, span in groups:
        idx = list(range(start, start + span))
        start += span
        if len(chunks[-1]) + len(idx) > max_columns and chunks[-1]:
            chunks.append([])
        while idx:
            room = max_columns - len(chunks[-1])
            chunks[-1].extend(idx[:room])
            idx = idx[room:]
            if idx:
                chunks.append([])
    return [c for c in chunks if c]


def print_tables(head: Mapping, rows: Sequence[Mapping], max_columns: int = MAX_COLUMNS,
                 series_labels: Mapping[str, str] | None = None) -> list[dict]:
    """The printed tables of :func:`cornell_harness.reports.tables.summary_rows`'s ``head`` (its ``head`` groups and ``cols``)
    and ``rows``: per table its group header cells, its columns and its rows (each row's cells for those
    columns, its ``renderer_cell`` shown as ``series_labels.get(name, name)``; a renderer that did not run:
    ``reason`` in the first table, left out of the others)."""
    labels = dict(series_labels or {})
    cols = list(head["cols"])
    if not cols or cols[0]["key"] != "renderer":
        raise ValueError("print_tables: the summary's first column must be the renderer")
    groups = [(g["title"], g["span"]) for g in head["head"]]
    first_title, first_span = groups[0]
    groups[0] = (first_title, first_span - 1)  # the renderer column, in every table
    chunks = column_chunks(groups, max_columns)
    titles = [t for t, span in groups for _ in range(span)]
    out = []
    for n, chunk in enumerate(chunks):
        spans: list[dict] = []
        for i in chunk:
            if spans and spans[-1]["title"] == titles[i]:
                spans[-1]["span"] += 1
            else:
                spans.append({"title": titles[i], "span": 1})
        table_rows = []
        for row in rows:
            if row["status"] != "ok" and n:
                continue
            cells = list(row["cells"])
            name = str(row["renderer"])
            table_rows.append({**row, "renderer_cell": {**cells[0], "text": labels.get(name, cells[0]["text"])},
                               "cells": [cells[i + 1] for i in chunk]})
        out.append({"head": spans, "cols": [cols[i + 1] for i in chunk], "rows": table_rows})
    return out
