"""Several experiment folders in one report (``cbox report DIR1 DIR2 ... --out OUT``); no rendering.

Each experiment becomes a section of the report (:func:`experiment_section`):
its timing-quality badge (:mod:`cornell_harness.reports.timing`), its scene, its reference and images side by side, its per-renderer table
(:func:`cornell_harness.reports.scenes.scene_section`), its charts, and a link to its own full
report. The report leads with the experiments of the first folder's scene,
their results concatenated: one summary table, one image viewer and one set of
convergence charts across them, so sweeps of one scene (other renderers, other
settings) compare directly. Renderer names already carry their settings
(``pathtracer[rr_depth=3]``); a name two experiments share gets the
experiment's label (:func:`distinct_names`). Every chart is also a file in
``OUT/figures/``, a section's named after its experiment's label. Every
experiment's summary is in ``OUT/summary.csv`` (an ``experiment`` column) and
``OUT/summary.tex`` and ``OUT/summary-wide.tex`` (one table per experiment).
"""

from __future__ import annotations

import os
import re
from collections import Counter
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from cornell_harness.evaluate.summary import ExperimentResults
from cornell_harness.scenes.model import Scene
from cornell_harness.store.provenance import provenance
from cornell_harness.store.references import Reference
from cornell_harness.reports.charts import bias_variance_chart, chart_rows, page_charts
from cornell_harness.reports.html import renderer_colors, write_report
from cornell_harness.reports.scenes import scene_section
from cornell_harness.reports.summary_files import write_summary_files
from cornell_harness.reports.tables import renderer_order
from cornell_harness.reports.timing import timing_badge


@dataclass(frozen=True, eq=False)
class Experiment:
    """One experiment folder as a merged report uses it: what is stored there, and the label it goes by."""

    label: str
    folder: Path
    scene: Scene
    reference: Reference
    config: dict
    runs: pd.DataFrame
    images: dict[str, list[np.ndarray]]  # highest-spp images per renderer, in seed order
    summary: pd.DataFrame | None


def load_experiment(label: str, folder: Path, scene: Scene, reference: Reference,
                    results: ExperimentResults) -> Experiment:
    """The experiment in ``folder`` (checked by the caller to be of ``scene``): its stored and derived ``results``."""
    config, runs, images, summary = results
    return Experiment(label, Path(folder), scene, reference, config, runs, images,
                      summary if not summary.empty else None)


def distinct_names(names: Sequence[Sequence[str]], labels: Sequence[str]) -> list[dict[str, str]]:
    """Per experiment, each renderer name → its name in the merged report: unchanged, or ``NAME (LABEL)``
    where another experiment has a renderer of the same name (names include non-default settings)."""
    shared = Counter(n for ns in names for n in set(ns))
    return [{n: f"{n} ({label})" if shared[n] > 1 else n for n in ns} for ns, label in zip(names, labels)]


def renamed(exp: Experiment, names: dict[str, str]) -> Experiment:
    """``exp`` with its renderers called by ``names`` in its results, images and summary."""
    def rename(frame: pd.DataFrame | None) -> pd.DataFrame | None:
        if frame is None:
            return None
        return frame.assign(renderer=[names.get(str(n), str(n)) for n in frame["renderer"]])

    return replace(exp, runs=rename(exp.runs), summary=rename(exp.summary),
                   images={names.get(n, n): imgs for n, imgs in exp.images.items()})


def file_prefixes(labels: Sequence[str]) -> list[str]:
    """A file- and id-safe prefix per label (``paper run 2`` → ``paper_run_2``), distinct even where two
    labels make the same one (a number is added)."""
    out: list[str] = []
    for label in labels:
        base = re.sub(r"[^A-Za-z0-9_-]+", "_", label).strip("_") or "experiment"
        prefix, k = base, 2
        while prefix in out:
            prefix, k = f"{base}-{k}", k + 1
        out.append(prefix)
    return out


def _first_images(exp: Experiment) -> dict[str, np.ndarray]:
    """The image each renderer shows: its first seed's (as :func:`cornell_harness.reports.experiment.write_experiment_report`)."""
    return {name: imgs[0] for name, imgs in exp.images.items() if imgs}


def experiment_section(exp: Experiment, report_dir: Path, prefix: str, colors: dict[str, str],
                       labels: dict[str, str] | None = None) -> tuple:
    """The report section of one experiment: (id, title, escaped HTML, chart rows); its charts' files and
    element ids start with ``prefix``, its renderers keep the colours of the whole report."""
    images = _first_images(exp)
    link = os.path.relpath(exp.folder / "report.html", report_dir)
    html = scene_section(exp.scene, exp.reference.image, exp.runs.to_dict("records"), images, link,
                         summary=exp.summary, link_text=f"Full report of {exp.label}")
    html = f'<p class="timing-line">{timing_badge(exp.runs)}</p>\n{html}'  # each experiment's own timing verdict
    names = renderer_order(exp.runs, images)
    time_column = str(exp.summary["time_column"].iloc[0]) if exp.summary is not None and \
        "time_column" in exp.summary.columns else "time_s"
    charts = page_charts(exp.runs, names, colors, prefix=prefix, time_column=time_column, labels=labels)
    bias_variance = bias_variance_chart(exp.summary, names, colors, prefix=prefix, labels=labels)
    return (f"experiment-{prefix}", f"{exp.label} · {exp.scene.name}", html, chart_rows(charts, bias_variance))


def _concat(frames: Sequence[pd.DataFrame | None]) -> pd.DataFrame | None:
    frames = [f for f in frames if f is not None and len(f)]
    return pd.concat(frames, ignore_index=True) if frames else None


def write_merged_report(out: Path, inputs: Sequence[tuple[str, Path, Scene, Reference, ExperimentResults]],
                        title: str | None = None, options: dict | None = None) -> Path:
    """Write ``out/report.html`` (and ``out/figures/``) for the experiments ``inputs``, each (label, folder,
    scene, reference, results) with distinct labels, the scenes checked against the folders by the caller,
    the results :func:`cornell_harness.workflows.converge.experiment_results`'s; and every experiment's summary as
    ``out/summary.csv`` and ``out/summary.tex`` (:func:`cornell_harness.reports.summary_files.write_summary_files`).
    ``options``: ``series_labels`` (by an experiment's own series name; a name made distinct keeps its
    experiment's label after the text) and ``crops``, as :func:`cornell_harness.reports.experiment.write_experiment_report`
    takes them."""
    options = options or {}
    out = Path(out)
    experiments = stored = [load_experiment(*i) for i in inputs]
    labels = [e.label for e in experiments]
    names = distinct_names([renderer_order(e.runs, e.images) for e in experiments], labels)
    experiments = [renamed(e, n) for e, n in zip(experiments, names)]
    given = options.get("series_labels") or {}
    series_labels = {new: given[old] + new[len(old):] for ns in names for old, new in ns.items() if old in given}
    lead_hash = experiments[0].scene.content_hash()
    lead = [e for e in experiments if e.scene.content_hash() == lead_hash]
    others = [e for e in experiments if e.scene.content_hash() != lead_hash]

    # One colour per renderer across the page; the lead's first, so its charts and the sections agree.
    all_runs = pd.concat([e.runs for e in lead + others], ignore_index=True)
    all_images = {n: img for e in lead + others for n, img in _first_images(e).items()}
    colors = renderer_colors(all_runs, all_images, renderer_order(all_runs, all_images))
    sections = [experiment_section(e, out, prefix, colors, series_labels)
                for e, prefix in zip(experiments, file_prefixes(labels))]

    runs = pd.concat([e.runs for e in lead], ignore_index=True)
    prov = provenance(lead[0].config, runs)
    prov["experiments"] = {e.label: str(e.folder) for e in experiments}
    scenes = ", ".join(dict.fromkeys(e.scene.name for e in experiments))
    path = write_report(out / "report.html", scene=lead[0].scene, reference=lead[0].reference, runs=runs,
                        images={n: img for e in lead for n, img in _first_images(e).items()},
                        summary=_concat([e.summary for e in lead]), provenance=prov,
                        command="\n".join(e.config.get("command", "") for e in lead),
                        sections=sections, title=title or f"Renderer comparison — {scenes}", labels=labels,
                        series_labels=series_labels, crops=options.get("crops"), summary_files=False)
    # Every experiment's summary, the lead's and the others', each under its label with its own names:
    # one CSV with an experiment column, one LaTeX table each.
    write_summary_files(out, [(e.label, e.summary) for e in stored], options.get("series_labels") or {})
    return path
