"""How a report shows an experiment: ``--series-label`` (a series' display text) and ``--crop`` (image insets).

Both only change how the report looks. They are checked before anything renders (a series label must name
a series of the run, a crop must lie in the image) and kept in the experiment folder
(:func:`cornell_harness.store.experiments.write_report_options`), so ``cbox report`` redraws the report the same
way; given again, they replace what is kept, label by label.
"""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional, Sequence

import typer

from cornell_harness.adapters.registry import declared_series_labels
from cornell_harness.adapters.settings import SettingsError, match_series_labels, parse_series_label, series_key
from cornell_harness.store.experiments import read_report_options, write_report_options

SeriesLabelOpt = typer.Option(
    None, "--series-label", metavar="SPEC=TEXT",
    help="Text shown for a series in legends, tables and the image figure instead of its recorded name "
         "(repeatable): 'pathtracer[sampler=\"independent\"]=PT (independent)'. SPEC is the series as -r or "
         "--sweep names it; a renderers file's [series_labels] table gives the same. Kept for `cbox report`.")
CropOpt = typer.Option(
    None, "--crop", metavar="X,Y,W,H",
    help="A rectangle in pixels (x, y from the top left) shown enlarged as an inset in figures/images.pdf "
         "(repeatable); given, the crops replace the scene's named regions there. Kept for `cbox report`.")


def given_series_labels(texts: Optional[List[str]]) -> dict[str, str]:
    """Spec → text from ``--series-label``; each is checked for its SPEC=TEXT form."""
    out = {}
    for text in texts or ():
        try:
            spec, shown = parse_series_label(text)
        except SettingsError as e:
            raise typer.BadParameter(str(e), param_hint="--series-label") from None
        out[spec] = shown
    return out


def series_labels_for(texts: Optional[List[str]], names: Sequence[str]) -> dict[str, str]:
    """Display text per series name of ``names``: the renderers files' ``[series_labels]`` that match a series
    (a file serves many runs), then ``--series-label``, each of which must match one."""
    keys = {series_key(n) for n in names}
    from_files = {spec: shown for spec, shown in declared_series_labels().items() if series_key(spec) in keys}
    try:
        return {**match_series_labels(from_files, names), **match_series_labels(given_series_labels(texts), names)}
    except SettingsError as e:
        raise typer.BadParameter(str(e), param_hint="--series-label") from None


def parse_crops(texts: Optional[List[str]], width: int, height: int) -> list[list[int]]:
    """``--crop X,Y,W,H`` rectangles, each inside a ``width`` × ``height`` image and at least 2 pixels wide."""
    out = []
    for text in texts or ():
        try:
            x, y, w, h = (int(v) for v in text.split(","))
        except ValueError:
            raise typer.BadParameter(f"{text!r}: expected X,Y,W,H, four whole numbers of pixels",
                                     param_hint="--crop") from None
        if x < 0 or y < 0 or w < 2 or h < 2 or x + w > width or y + h > height:
            raise typer.BadParameter(f"{text!r}: the rectangle must lie in the {width}x{height} image and be at "
                                     "least 2 pixels wide and high", param_hint="--crop")
        out.append([x, y, w, h])
    return out


def keep_report_options(folder: Path, labels: dict[str, str], crops: list[list[int]], save: bool = True) -> dict:
    """The folder's kept options with these given ones over them (labels by series, crops as a whole); saved
    when anything was given and ``save``. The result is what the report is drawn with."""
    options = read_report_options(folder)
    merged = {"series_labels": {**options.get("series_labels", {}), **labels},
              "crops": crops or options.get("crops", [])}
    if save and (labels or crops):
        Path(folder).mkdir(parents=True, exist_ok=True)
        write_report_options(folder, merged)
    return merged
