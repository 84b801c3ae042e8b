"""Standalone figures: every chart of the report as its own SVG, PDF and PNG in ``OUT/figures/``, for papers.

The figures are the page's charts (:class:`cornell_harness.reports.charts.Figure`) drawn again
by the same code (:mod:`cornell_harness.reports.plots`) with :data:`PRINT`: a layout sized for
one column of a two-column paper, 3.3 in (8.5 cm) wide, whose text is 7–9 pt
at that width, with the legend below the plot inside the figure, and a light
stylesheet embedded in the SVG, so the file looks the same in a browser, a
vector editor or LaTeX as on paper.

PDF and PNG are converted from the SVG by CairoSVG (https://cairosvg.org, on
the cairo library). Without it, or without libcairo, the SVGs are still
written and the report says, once, why the others are not: a missing
converter never fails a run. :func:`write_figures` is called by
:func:`cornell_harness.reports.html.write_report`, so every command that writes a report
writes its figures beside it.
"""

from __future__ import annotations

import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

from cornell_harness.scenes.model import one_line
from cornell_harness.store.atomic import atomic_path, write_text_atomic
from cornell_harness.reports.charts import FIGURE_KINDS, Figure
from cornell_harness.reports.plots import Layout

#: The folder beside report.html that holds the figures.
FIGURES_DIR = "figures"
#: One column of a two-column paper (IEEE, ACM, Eurographics: 3.3–3.5 in).
COLUMN_WIDTH_IN = 3.3
#: Print resolution of the PNGs.
PNG_DPI = 300

# Text sizes in viewBox units; at 380 units across 3.3 in, one unit is 0.625 pt, so 11.5–14 units are
# 7.2–8.8 pt in print. Colours: dark text and axes on white; the guide and the frontier darker than on
# the page, where they sit on a dark plot area.
_STYLE = (
    'text{font-family:Helvetica,Arial,"Liberation Sans","DejaVu Sans",sans-serif;font-size:13px;fill:#222}'
    ".label{font-size:14px;fill:#000}.legend-label{font-size:13px;fill:#000}"
    ".figure-bg,.plot-bg{fill:#fff}.grid{stroke:#e3e3e3;stroke-width:0.8}.axis{stroke:#333;fill:none}"
    ".guide{stroke:#444;stroke-width:1.4}.guide-mark{stroke:#444}"
    ".point{stroke:#fff;stroke-width:0.8}.point.on-front{stroke:#000;stroke-width:1.6}"
    ".frontier{stroke:#f2b300;stroke-opacity:0.45}.frontier-mark{stroke:#f2b300}"
    ".point-tag{font-size:11.5px;fill:#555}.bar-note{font-size:12px;fill:#000}.bar-missing{font-size:12px;fill:#555}"
)

#: The standalone figures' layout: column width, print-size text, legend below the plot.
PRINT = Layout(width=380, height=290, left=76, right=22, top=14, bottom=50, font=13, label_font=14, legend_row=18,
               legend_below=True, style=_STYLE, width_in=COLUMN_WIDTH_IN)

# A figure file of some report: a kind, perhaps after a section's prefix (a merged report's experiment label).
_STALE = re.compile(rf"([\w-]+-)?({'|'.join(map(re.escape, FIGURE_KINDS))})(-[\w.-]+)?\.(svg|pdf|png)")
_said: set[str] = set()  # notes already printed by this process


@dataclass(frozen=True)
class WrittenFigures:
    """What :func:`write_figures` wrote: per figure stem, (format, path relative to the report); and a note."""

    files: dict[str, list[tuple[str, str]]] = field(default_factory=dict)
    note: str = ""  # why some formats are missing, or ""


def standalone_svg(figure: Figure) -> str | None:
    """The figure as a standalone SVG document; None when the chart has nothing to plot."""
    svg = figure.draw(layout=PRINT)
    if not svg.startswith("<svg"):  # the chart's "no positive values" note
        return None
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + svg + "\n"


def _converter():
    """(the cairosvg module, "") or (None, why it cannot be used)."""
    try:
        import cairosvg
    except ImportError:
        return None, "cairosvg is not installed (pip install cairosvg)"
    except OSError as e:  # cairocffi loads libcairo when imported
        first = (str(e).splitlines() or [""])[0]
        return None, f"cairosvg cannot load the cairo library (apt-get install libcairo2): {one_line(first, 160)}"
    return cairosvg, ""


def write_svg_pdf_png(folder: Path, stem: str, svg: str, cairosvg) -> tuple[list[str], list[str]]:
    """Write ``stem.svg`` into ``folder`` and, with ``cairosvg`` (:func:`_converter`'s module; None: the SVG
    alone), ``stem.pdf`` and ``stem.png`` (at :data:`PNG_DPI`) converted from it, each atomically; return
    (formats written, failures as "file: why"); never raises for a failing conversion."""
    write_text_atomic(folder / f"{stem}.svg", svg)
    done, failed = ["svg"], []
    for fmt in ("pdf", "png") if cairosvg is not None else ():
        try:
            with atomic_path(folder / f"{stem}.{fmt}") as tmp:
                if fmt == "pdf":
                    cairosvg.svg2pdf(bytestring=svg.encode("utf-8"), write_to=str(tmp))
                else:
                    cairosvg.svg2png(bytestring=svg.encode("utf-8"), write_to=str(tmp), dpi=PNG_DPI)
            done.append(fmt)
        except Exception as e:  # whatever cairo makes of one figure, the report and the run go on
            failed.append(f"{stem}.{fmt}: {one_line(str(e), 160)}")
    return done, failed


def no_converter_note(why_not: str) -> str:
    """What is said when :func:`_converter` finds no converter (``why_not``), by every writer of figures."""
    return f"PDF and PNG figures were not written: {why_not}; the SVG figures are in {FIGURES_DIR}/"


def say_once(note: str) -> None:
    """Print ``cbox: note: NOTE`` to stderr, once per process."""
    if note and note not in _said:
        _said.add(note)
        print(f"cbox: note: {note}", file=sys.stderr)


def write_figures(report_dir: Path, figures: Sequence[Figure]) -> WrittenFigures:
    """Write each figure as SVG, PDF and PNG into ``report_dir/figures/``, atomically; never raises for a
    missing or failing converter (the note says what was skipped). Figure files of an earlier report that
    this one no longer has are removed, so the folder matches the report."""
    folder = Path(report_dir) / FIGURES_DIR
    cairosvg, why_not = _converter()
    files: dict[str, list[tuple[str, str]]] = {}
    failed: list[str] = []
    for figure in figures:
        svg = standalone_svg(figure)
        if svg is None:
            continue
        done, failures = write_svg_pdf_png(folder, figure.stem, svg, cairosvg)
        failed += failures
        files[figure.stem] = [(fmt.upper(), f"{FIGURES_DIR}/{figure.stem}.{fmt}") for fmt in done]
    _remove_stale(folder, {f"{stem}.{fmt.lower()}" for stem, done in files.items() for fmt, _ in done})
    note = ""
    if files and cairosvg is None:
        note = no_converter_note(why_not)
    elif failed:
        note = f"{len(failed)} figure file(s) could not be converted, e.g. {failed[0]}"
    say_once(note)
    return WrittenFigures(files, note)


def _remove_stale(folder: Path, keep: set[str]) -> None:
    """Remove figure files (by their names) that the report now being written does not link."""
    if folder.is_dir():
        for path in folder.iterdir():
            if path.is_file() and _STALE.fullmatch(path.name) and path.name not in keep:
                path.unlink()
