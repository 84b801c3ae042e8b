"""An experiment folder's report: the HTML report of what the workflow stored and derived. No rendering, no
computing: the summary is :func:`cornell_harness.workflows.converge.experiment_results`'s."""

from __future__ import annotations

from pathlib import Path

from cornell_harness.evaluate.summary import ExperimentResults
from cornell_harness.scenes.model import Scene
from cornell_harness.store.experiments import read_report_options
from cornell_harness.store.provenance import provenance
from cornell_harness.store.references import Reference
from cornell_harness.reports.html import write_report


def write_experiment_report(out: Path, scene: Scene, reference: Reference, results: ExperimentResults,
                            thresholds: dict | None = None, sections=(), title: str | None = None, labels=(),
                            report_dir: Path | None = None, options: dict | None = None) -> Path:
    """(Re)build ``report.html`` from ``results``, what the experiment folder ``out`` holds, into ``report_dir``
    (default ``out``). ``labels``: the experiment's name, shown in the report's header; ``options``: series
    labels and crops (:func:`cornell_harness.store.experiments.read_report_options`; default those kept in ``out``)."""
    options = read_report_options(out) if options is None else options
    config, runs, images, summary = results
    dest = Path(out if report_dir is None else report_dir)
    shown = {r: imgs[0] for r, imgs in images.items() if imgs}
    return write_report(dest / "report.html", scene=scene, reference=reference, runs=runs, images=shown,
                        summary=summary if not summary.empty else None, thresholds=thresholds,
                        provenance=provenance(config, runs), command=config.get("command", ""),
                        sections=sections, title=title, labels=labels,
                        series_labels=options.get("series_labels"), crops=options.get("crops"))
