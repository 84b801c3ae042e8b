"""The HTML report: one self-contained, interactive file comparing every renderer to the reference.

The file works offline, e.g. opened from a CI artifact: no script, font, style
or image is fetched; CSS, JavaScript, images, charts and data are all inlined.
It shows

1. **Summary table** (:mod:`cornell_harness.reports.tables`), one row per renderer at its
   highest spp; columns sort on click.
2. **Image viewer** (:mod:`cornell_harness.reports.viewer`) on a canvas, with the HDR images
   and false-colour maps of :mod:`cornell_harness.reports.images`.
3. **Convergence plots**, 4. **speed/accuracy chart** and 5. **bias² and
   variance bars** (:mod:`cornell_harness.reports.charts`), with the split per named region
   as a table (:mod:`cornell_harness.reports.regions`) when the summary has it.
6. **Provenance**: versions, machine, seeds, date, scene hash, the
   reference's own provenance and the command line.
7. **Regions** (:mod:`cornell_harness.reports.regions`), for a scene with named regions:
   their masks over the reference and each renderer's metrics inside each.

This module assembles those parts into the Jinja template
``templates/report.html.j2``. Charts are inline SVG drawn by
:mod:`cornell_harness.reports.plots`; :func:`write_report` also writes each as a standalone
SVG, PDF and PNG into ``figures/`` beside the report (:mod:`cornell_harness.reports.figures`)
and links them. The page follows the system's light or dark preference, has a
toggle that overrides it, and prints light. Entry point: :func:`write_report`.
"""

from __future__ import annotations

import datetime as _dt
import json
from pathlib import Path
from typing import Any, Mapping, Sequence

import jinja2
import markupsafe
import numpy as np
import pandas as pd
from markupsafe import Markup

from cornell_harness.evaluate import metrics
from cornell_harness.store.atomic import write_text_atomic
from cornell_harness.reports import plots
from cornell_harness.reports.charts import SINGLE_SPP_NOTE, bias_variance_chart, chart_figures, page_charts
from cornell_harness.reports.figures import WrittenFigures, write_figures
from cornell_harness.reports.image_figure import image_captions, write_image_figure
from cornell_harness.reports.images import JND
from cornell_harness.reports.print_tables import print_tables
from cornell_harness.reports.regions import bias_variance_table, region_section
from cornell_harness.reports.summary_files import write_summary_files
from cornell_harness.reports.timing import timing_badge
from cornell_harness.reports.numbers import OPERATOR_SIGNS, column_label
from cornell_harness.reports.tables import column_or_nan, ok_runs, renderer_info, renderer_order, summary_rows
from cornell_harness.reports.viewer import image_viewer, viewer_legends

#: Swatch colour of renderers that did not run.
NOT_RUN_COLOR = "#5b616d"

_NOT_RUN = ("skipped", "unavailable", "failed")


def _provenance_rows(prov: dict, scene_hash: str) -> list[tuple[str, str]]:
    """The reference's own provenance as (label, value) rows."""
    renderer = " ".join(
        str(x) for x in (prov.get("renderer"), prov.get("renderer_version")) if x not in (None, "")
    ) or "—"
    if prov.get("variant") and str(prov["variant"]) not in renderer:
        renderer += f", variant {prov['variant']}"
    spp = str(prov.get("spp", "—"))
    if prov.get("batches") and prov.get("batch_spp"):
        spp += f" ({prov['batches']} batches × {prov['batch_spp']} spp)"
    rows = [("renderer", renderer), ("spp", spp), ("date", str(prov.get("date", "—")))]
    for key, label in (("wall_time_s", "wall time (s)"), ("machine", "machine"), ("command", "built with"),
                       ("noise_spp", "noise sample spp")):
        if prov.get(key) not in (None, ""):
            rows.append((label, str(prov[key])))
    seeds = prov.get("seeds")
    if isinstance(seeds, (list, tuple)) and seeds:
        rows.append(("seeds", f"{len(seeds)}: {seeds[0]}…{seeds[-1]}" if len(seeds) > 3 else
                     ", ".join(map(str, seeds))))
    ref_hash = prov.get("scene_hash")
    if ref_hash and ref_hash != scene_hash:
        rows.append(("warning", f"reference built for scene hash {ref_hash}, not this scene's"))
    return rows


def _kv(value: Any) -> str:
    if isinstance(value, (dict, list, tuple)):
        return json.dumps(value, default=str)
    return str(value)


def _run_provenance(provenance: Mapping) -> dict:
    prov = dict(provenance or {})
    versions = prov.pop("versions", None) or {}
    seeds = prov.pop("seeds", None)
    machine = prov.pop("machine", None)
    date = prov.pop("date", None)
    return {
        "versions": [(str(k), str(v)) for k, v in (versions.items() if isinstance(versions, Mapping) else [])],
        "seeds": ", ".join(str(s) for s in seeds) if isinstance(seeds, (list, tuple)) else (
            "" if seeds is None else str(seeds)),
        "machine": "" if machine is None else str(machine),
        "date": "" if date is None else str(date),
        "other": [(str(k), _kv(v)) for k, v in prov.items()],
    }


def _json_for_script(data: Any) -> Markup:
    """JSON safe inside a ``<script>`` element: no ``<``, ``>`` or ``&`` characters at all."""
    text = json.dumps(data, separators=(",", ":"), allow_nan=False)
    text = text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")
    text = text.replace("\u2028", "\\u2028").replace("\u2029", "\\u2029")
    return Markup(text)


def _environment() -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.PackageLoader("cornell_harness.reports", "templates"),
        autoescape=True,
        trim_blocks=True,
        lstrip_blocks=True,
        undefined=jinja2.StrictUndefined,
    )


def _asset(env: jinja2.Environment, name: str) -> Markup:
    text = env.loader.get_source(env, name)[0]
    if "</script" in text.lower() or "</style" in text.lower():
        raise ValueError(f"{name} must not contain a closing script or style tag")
    return Markup(text)


def _harness_version() -> str:
    try:
        from importlib.metadata import version

        return version("cornell-harness")
    except Exception:
        return "unknown"


def _max_depth_text(max_depth: int | None) -> str:
    if max_depth is None:  # a reference that is only an image file (cornell_harness.reports.compare_image)
        return "unknown"
    if max_depth < 0:
        return "unbounded (Russian roulette)"
    return f"{max_depth} segments"


def _runs_text(runs: pd.DataFrame) -> str:
    ok = ok_runs(runs)
    if not len(ok):
        return "no successful runs"
    spps = sorted({int(s) for s in ok["spp"]})
    seeds = sorted({int(s) for s in column_or_nan(ok, "seed").dropna()})
    spp_text = f"{spps[0]} spp" if len(spps) == 1 else f"{len(spps)} spp levels, {spps[0]}–{spps[-1]}"
    seed_text = ("seed " + str(seeds[0])) if len(seeds) == 1 else f"{len(seeds)} seeds"
    return f"{spp_text}, {seed_text}"


def _summary_text(summary: pd.DataFrame | None, key: str) -> str:
    """The summary's ``key`` (a text column, one value for all its renderers; the first), "" without it."""
    if summary is None or key not in summary.columns:
        return ""
    values = [str(v) for v in summary[key] if isinstance(v, str) and v]
    return values[0] if values else ""


def _intervals_text(summary: pd.DataFrame | None, time_column: str) -> str:
    """What the figures' intervals are, for the "This run" panel; "" for a summary without them."""
    basis = sorted({str(v) for v in summary["interval_basis"] if isinstance(v, str)}) \
        if summary is not None and "interval_basis" in summary.columns else []
    if not basis:
        return ""
    clock = "CPU time" if time_column == "cpu_time_s" else "wall time"
    return f"95% confidence intervals over {'; '.join(basis)}; times are {clock} ({time_column})"


def _checked_thresholds(thresholds) -> dict:
    thresholds = dict(thresholds or {})
    for key, spec in thresholds.items():
        if not (isinstance(spec, (tuple, list)) and len(spec) == 2 and spec[0] in OPERATOR_SIGNS):
            raise ValueError(f"threshold for {key!r}: expected (op, value) with op in "
                             f"{', '.join(OPERATOR_SIGNS)}, got {spec!r}")
    return thresholds


def renderer_colors(runs: pd.DataFrame, images: Mapping[str, Any], names: Sequence[str]) -> dict[str, str]:
    """Palette colours for renderers with something to show; grey for those that did not run."""
    ran = set(ok_runs(runs).get("renderer", pd.Series(dtype=str)).astype(str))
    shown = [n for n in names if n in images or n in ran]
    colors = {n: plots.color_for(i) for i, n in enumerate(shown)}
    colors.update({n: NOT_RUN_COLOR for n in names if n not in colors})
    return colors


def _scene_context(scene, scene_hash: str) -> dict:
    return {
        "name": scene.name,
        "hash": scene_hash,
        "description": getattr(scene, "description", "") or "",
        "resolution": f"{scene.camera.width} × {scene.camera.height}",
        "max_depth": _max_depth_text(scene.max_depth),
        "pixel_filter": scene.pixel_filter,
    }


def _context(
    *,
    scene,
    reference,
    runs: pd.DataFrame,
    images: Mapping[str, Any],
    summary: pd.DataFrame | None = None,
    thresholds: Mapping[str, tuple[str, float]] | None = None,
    provenance: Mapping,
    command: str = "",
    title: str | None = None,
    sections: Sequence[tuple] = (),
    labels: Sequence[str] = (),
    cores: int | None = None,
    series_labels: Mapping[str, str] | None = None,
) -> dict:
    """What the template shows (see :func:`write_report`), with the charts as ``figures``; not the links to
    figure files, which exist only once written.

    ``sections`` are extra (id, title, HTML fragment[, chart rows]) sections
    other parts of the harness add (e.g. the gate's verdicts), placed after
    the summary; the fragments must be built with escaping already done. A
    section's chart rows (:func:`cornell_harness.reports.charts.chart_rows`) are drawn below
    its fragment and written to ``figures/`` with the report's own charts.
    """
    ref_img = np.asarray(reference.image, dtype=np.float32)
    exposure = metrics.display_exposure(ref_img, scene.quantity)
    scene_hash = scene.content_hash()
    runs = runs if runs is not None else pd.DataFrame()
    images = dict(images or {})
    thresholds = _checked_thresholds(thresholds)
    provenance = dict(provenance or {})

    names = renderer_order(runs, images)
    colors = renderer_colors(runs, images, names)
    shown = {n: (series_labels or {}).get(n, n) for n in names}  # what a series is called on the page
    info = [{**i, "label": shown[i["name"]]} for i in renderer_info(runs, names, colors)]
    table_head, table_rows = summary_rows(runs, summary, names, info, thresholds)
    _label_rows(table_rows, shown)
    time_column = _summary_text(summary, "time_column") or "time_s"
    charts = page_charts(runs, names, colors, time_column=time_column, labels=shown)
    bias_variance = bias_variance_chart(summary, names, colors, labels=shown)
    run_seeds = provenance.get("seeds") or []
    error_arrays: dict = {}  # the viewer's error maps, reused by the image figure
    viewer, viewer_notes = image_viewer(ref_img, exposure, images, names, colors, runs, run_seeds, error_arrays,
                                        time_column)
    for entry in viewer.get("renderers", ()):
        entry["label"] = shown.get(entry["name"], entry["name"])
    ref_prov = dict(reference.provenance or {})
    counts = {s: sum(i["status"] == s for i in info) for s in ("ok", *_NOT_RUN)}
    sections = list(sections)
    if (regions := region_section(scene, ref_img, exposure, runs, colors)) is not None:
        sections.append(("regions", "Regions", regions))
    section_charts = {s[0]: list(s[3]) if len(s) > 3 else [] for s in sections}

    return {
        "scene": _scene_context(scene, scene_hash),
        "sections": [(s[0], s[1], markupsafe.Markup(s[2])) for s in sections],
        "section_charts": section_charts,
        "title": title or f"Renderer comparison — {scene.name}",
        "labels": list(labels),
        "reference_rows": _provenance_rows(ref_prov, scene_hash),
        "reference_spp": ref_prov.get("spp", "—"),
        "run": _run_provenance(provenance),
        "command": command,
        "runs_text": _runs_text(runs),
        "timing_badge": timing_badge(runs, cores, figures=False),
        "timing_line": timing_badge(runs, cores),
        "intervals": _intervals_text(summary, time_column),
        "generated": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "harness_version": _harness_version(),
        "exposure": f"{exposure:.4g}",
        "counts": counts,
        "renderers": info,
        "table_head": table_head[0],
        "table_rows": table_rows,
        "print_tables": print_tables(table_head[0], table_rows),  # the summary split for A4 (report.css)
        "thresholds": [
            {"key": k, "label": column_label(k)[0], "op": OPERATOR_SIGNS[op], "value": f"{float(v):g}"}
            for k, (op, v) in thresholds.items()
        ],
        "charts": charts,
        "single_spp_note": SINGLE_SPP_NOTE,
        "bias_variance": bias_variance,
        "figures": chart_figures(charts, bias_variance) + [
            figure for rows in section_charts.values() for row in rows for _, figure in row["boxes"]],
        "region_bias_variance": Markup(bias_variance_table(summary, scene, colors) or ""),
        "viewer": viewer,
        "image_figure": {"reference_image": ref_img, "exposure": exposure, "maps": error_arrays,
                         "images": {n: images[n] for n in names if n in images},
                         "captions": image_captions(viewer, ref_prov.get("spp"), time_column)},
        "viewer_json": _json_for_script(viewer),
        "viewer_notes": viewer_notes,
        "legends": viewer_legends(),
        "jnd": JND,
        "rel_mse_eps": metrics.REL_MSE_EPS,
    }


def _label_rows(rows: list[dict], shown: Mapping[str, str]) -> None:
    """The summary table's renderer cells show the series' label; the recorded name is their tooltip."""
    for row in rows:
        for cell in row.get("cells", ()):
            if cell["key"] == "renderer" and shown.get(row["renderer"], row["renderer"]) != row["renderer"]:
                cell["text"], cell["title"] = shown[row["renderer"]], row["renderer"]


def _render(ctx: dict, written: WrittenFigures) -> str:
    env = _environment()
    return env.get_template("report.html.j2").render(
        **ctx, figure_files=written.files, figures_note=written.note,
        css=_asset(env, "report.css"), js=_asset(env, "report.js"))


def render_html(**kwargs) -> str:
    """The report's HTML text, from the keywords of :func:`write_report` (but ``path``); no figure files."""
    return _render(_context(**kwargs), WrittenFigures())


def write_report(
    path,
    *,
    scene,
    reference,
    runs: pd.DataFrame,
    images: Mapping[str, Any],
    summary: pd.DataFrame | None = None,
    thresholds: Mapping[str, tuple[str, float]] | None = None,
    provenance: Mapping,
    command: str = "",
    title: str | None = None,
    sections: Sequence[tuple] = (),
    labels: Sequence[str] = (),
    figures: bool = True,
    cores: int | None = None,
    series_labels: Mapping[str, str] | None = None,
    crops: Sequence[Sequence[int]] | None = None,
    summary_files: bool = True,
) -> Path:
    """Write the self-contained HTML report to ``path`` atomically; return the path.

    - ``scene``: the :class:`cornell_harness.scenes.model.Scene`;
    - ``reference``: the :class:`cornell_harness.store.references.Reference` (its ``image`` and
      ``provenance`` are used);
    - ``runs``: the tidy results, one row per (renderer, seed, spp), with
      ``status`` and ``reason`` for renderers that did not run;
    - ``images``: renderer → (H, W, 3) linear-sRGB image shown in the viewer
      (the highest-spp image of the first seed);
    - ``summary``: optional per-renderer figures (slopes, ``time_to_*``,
      efficiency, bias², variance);
    - ``thresholds``: optional metric → (op, value), op in ``<= >= < >``, for
      pass/fail colouring of the summary table;
    - ``provenance``: ``versions``, ``machine``, ``seeds``, ``date`` and any
      other key/value to show; ``command``: the command line;
    - ``sections``: extra (id, title, escaped HTML fragment[, chart rows])
      sections, shown after the summary (the gate's verdicts, ``cbox demo``'s
      second scene and a merged report's experiments use this);
    - ``labels``: the names of the experiments shown, for the header
      (``cbox report --label``);
    - ``cores``: the cores of the machine the runs were timed on, for the timing-quality badge
      (:mod:`cornell_harness.reports.timing`); default this machine's;
    - ``series_labels``: recorded series name → the text legends, tables and figures show for it
      (``--series-label``); ``crops``: (x, y, w, h) rectangles the image figure enlarges (``--crop``).

    Every chart is also written as a standalone SVG, PDF and PNG into
    ``figures/`` beside ``path`` (:func:`cornell_harness.reports.figures.write_figures`), and
    the report links them; so is the image grid, ``figures/images.*``, with each
    of its images in ``images/`` (:func:`cornell_harness.reports.image_figure.write_image_figure`).
    ``figures=False`` writes the page alone (a few seconds quicker: converting
    every chart to PDF and 300 dpi PNG takes that).
    With a summary, ``summary.csv``, ``summary.tex`` and ``summary-wide.tex`` are written beside ``path`` too
    (:func:`cornell_harness.reports.summary_files.write_summary_files`), unless ``summary_files=False`` (a merged report
    writes every experiment's itself).
    """
    path = Path(path)
    ctx = _context(
        scene=scene, reference=reference, runs=runs, images=images, summary=summary, thresholds=thresholds,
        provenance=provenance, command=command, title=title, sections=sections, labels=labels, cores=cores,
        series_labels=series_labels,
    )
    written = write_figures(path.parent, ctx["figures"]) if figures else WrittenFigures()
    if figures:  # the image grid and images/*.png (cornell_harness.reports.image_figure); its links: written.files["images"]
        grid = write_image_figure(path.parent, scene=scene, series_labels=series_labels, crops=crops,
                                  **ctx["image_figure"])
        written = WrittenFigures({**written.files, "images": grid["figure"]} if grid["figure"] else written.files,
                                 written.note)
    write_text_atomic(path, _render(ctx, written))
    if summary_files:
        write_summary_files(path.parent, [(None, summary)], series_labels)
    return path
