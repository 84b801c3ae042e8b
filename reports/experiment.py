"""An experiment folder's report: derived figures from what is stored, then the HTML report. No rendering."""

from __future__ import annotations

from pathlib import Path

from harness.evaluate import convergence
from harness.scenes.model import Scene
from harness.store.atomic import atomic_path
from harness.store.experiments import SUMMARY_FILE, final_images, load_results
from harness.store.provenance import provenance
from harness.store.references import Reference
from harness.workflows.converge import summary_table
from reports.html import write_report


def experiment_results(out: Path, scene: Scene, reference: Reference) -> tuple:
    """What the experiment folder ``out`` holds, and what is derived from it: (config, results, highest-spp
    images per renderer in seed order, summary table, empty when nothing ran); no rendering."""
    config, runs = load_results(out)
    images = final_images(out, runs)
    targets = [tuple(t) for t in config.get("targets", convergence.DEFAULT_TARGETS)]
    summary = summary_table(runs, images, reference, scene, targets, config.get("deterministic", ()))
    return config, runs, images, summary


def write_experiment_report(out: Path, scene: Scene, reference: Reference, thresholds: dict | None = None,
                            sections=(), title: str | None = None, labels=(), report_dir: Path | None = None) -> Path:
    """(Re)build ``report.html`` and ``summary.csv`` from what is stored in ``out``, into ``report_dir``
    (default ``out``); no rendering. ``labels``: the experiment's name, shown in the report's header."""
    config, runs, images, summary = experiment_results(out, scene, reference)
    dest = Path(out if report_dir is None else report_dir)
    if not summary.empty:
        with atomic_path(dest / SUMMARY_FILE) as tmp:
            summary.to_csv(tmp, index=False)
    shown = {r: imgs[0] for r, imgs in images.items() if imgs}
    return write_report(dest / "report.html", scene=scene, reference=reference, runs=runs, images=shown,
                        summary=summary if not summary.empty else None, thresholds=thresholds,
                        provenance=provenance(config, runs), command=config.get("command", ""),
                        sections=sections, title=title, labels=labels)
