"""``cbox converge`` (convergence experiments, sweeps) and ``cbox report`` (rebuild a report, no rendering)."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from cornell_harness.adapters.api import attribute
from cornell_harness.adapters.registry import missing_features, resolve
from cornell_harness.cli.common import (DashboardOpt, RendererFilesOpt, RenderersOpt, SceneOpt, SchedulerOpt, SetOpt,
                                        TimeLimitOpt, TitleOpt, WorkersOpt, app, command_line, executor_for,
                                        out_folder_option, print_json)
from cornell_harness.cli.figures import CropOpt, SeriesLabelOpt, keep_report_options, parse_crops, series_labels_for
from cornell_harness.cli.output import Progress, info
from cornell_harness.cli.timing import TimeBasisOpt, time_basis_option, time_repeats_option, warn_contention
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.experiments import CONFIG_FILE, SUMMARY_FILE, ExperimentError, load_results
from cornell_harness.store.references import load_reference
from cornell_harness.suggest import did_you_mean
# Heavy modules (SciPy, pandas, the report) are imported inside the commands that use them: `cbox gate` on
# a misspelt config, or `cbox --help`, must answer in a second.

#: The grammar of converge --spp, exactly as cornell_harness.workflows.spp_list.parse_spp_list reads it.
SPP_HELP = ("spp checkpoints, as a list: exactly those spp, in any order (1,4,16 or 1,3,5); a sequence: the "
            "numbers before '...' continued by their one constant ratio or difference to the last number, "
            "which it must reach exactly (1,2,4,...,256 or 10,20,...,50; 1,2,...,8 fits both ×2 and +1 and is "
            "refused: give a third number); or a range A-B: the powers of two from A to B, which must both be "
            "powers of two (1-256). Progressive renderers give them all from one render.")


@app.command()
def converge(
    scene: str = SceneOpt,
    overrides: Optional[List[str]] = SetOpt,
    renderer: Optional[List[str]] = RenderersOpt,
    renderer_files: Optional[List[Path]] = RendererFilesOpt,
    spp: str = typer.Option("1,2,4,...,256", "--spp", help=SPP_HELP),
    seeds: int = typer.Option(4, "--seeds", min=1, help="Number of seeds (0 .. N-1); bias and variance need 2 or more."),
    out: Path = out_folder_option(Path("out/converge"), "Experiment folder: results.parquet, "
                                                                      "summary.parquet, summary.csv, summary.tex, "
                                                                      "summary-wide.tex, report.html, cells/, "
                                                                      "images/."),
    target: Optional[List[str]] = typer.Option(
        None, "--target", help="Target error for the time-to-target figure, METRIC=VALUE (repeatable), the "
                               "metric image-wide or in a region of the scene (region.caustic.rel_mse=0.01); "
                               "default: delta_e2000_mean=2, delta_e2000_mean=1, rel_mse=0.01, rel_mse=0.001."),
    sweep: Optional[str] = typer.Option(
        None, "--sweep", help="Sweep one renderer setting, RENDERER.SETTING=V1,V2,... (e.g. "
                              "pathtracer.rr_depth=3,5,8): each value is its own series in the table and report. "
                              "See `cbox renderers --settings`."),
    as_json: bool = typer.Option(False, "--json", help="Print the results on stdout as one JSON object: folder, "
                                                       "report, runs (one per renderer, seed and spp) and summary "
                                                       "(one per renderer), settings and regions as objects."),
    title: Optional[str] = TitleOpt,
    workers: Optional[int] = WorkersOpt,
    scheduler: Optional[str] = SchedulerOpt,
    dashboard: Optional[str] = DashboardOpt,
    time_repeats: Optional[int] = time_repeats_option(
        "default 1; here the final checkpoint of each renderer and seed, after all cells, in rounds over them; "
        "on Dask in the scheduler's order; a rerun keeps the repeats done"),
    time_basis: str = TimeBasisOpt,
    series_label: Optional[List[str]] = SeriesLabelOpt,
    crop: Optional[List[str]] = CropOpt,
    time_limit: Optional[str] = TimeLimitOpt,  # seconds (float), by the option's callback
) -> None:
    """Convergence experiment: every metric at every spp checkpoint, per renderer and seed.

    Results are a tidy table (one row per scene, renderer, settings, seed and
    spp) in OUT/results.parquet. The run is resumable: finished (renderer,
    seed) cells are written atomically, and running the same command again
    renders only the cells that are missing. With --workers or --scheduler
    the cells render on a Dask cluster; this process alone writes OUT, and
    the table is the same as in-process.
    """
    from cornell_harness.adapters.registry import sweep as sweep_entries
    from cornell_harness.adapters.settings import parse_sweep
    from cornell_harness.evaluate.convergence import DEFAULT_TARGETS, parse_target, unknown_target_regions
    from cornell_harness.workflows.spp_list import parse_spp_list

    try:
        spps = parse_spp_list(spp)
    except ValueError as e:
        raise typer.BadParameter(str(e), param_hint="--spp") from None
    try:
        targets = [parse_target(t) for t in target] if target else DEFAULT_TARGETS
    except ValueError as e:
        raise typer.BadParameter(str(e), param_hint="--target") from None
    sc = resolve_scene(scene, overrides)
    if unknown := unknown_target_regions(targets, sc.regions):
        raise typer.BadParameter(f"scene {sc.name!r} has no region {', '.join(map(repr, unknown))}"
                                 f"{did_you_mean(unknown[0], sc.regions)}; "
                                 f"its regions: {', '.join(sc.regions) or '(none)'}", param_hint="--target")
    ref = load_reference(sc)
    entries = resolve(renderer)
    if sweep:
        entries = sweep_entries(entries, *parse_sweep(sweep))
    entries = [e.with_time_limit(time_limit) for e in entries]
    keep_report_options(out, series_labels_for(series_label, [e.name for e in entries]),
                        parse_crops(crop, sc.camera.width, sc.camera.height))
    with executor_for(workers, scheduler, dashboard) as executor:
        runs, report = run_convergence(out, sc, ref, entries, spps, seeds, targets, title=title, executor=executor,
                                       time_repeats=time_repeats or 1, time_basis=time_basis)
    if as_json:
        _print_json(out, report, runs)
    else:
        print_summary(out, runs)
    warn_contention(runs)
    info(f"report: {report}")
    raise typer.Exit(1 if (runs["status"] == "failed").any() else 0)


def run_convergence(out: Path, sc, ref, entries, spps: list[int], seeds: int, targets=None, title: str | None = None,
                    sections=(), executor=None, time_repeats: int = 1, time_basis: str = "wall"):
    """Run (or resume) a convergence experiment with progress, then write its report: (runs, report path).

    ``executor``: where the cells render (:mod:`cornell_harness.workflows.executor`; default in this process);
    ``time_repeats``: timings of each cell's final checkpoint; ``time_basis``: the clock of the summary."""
    from cornell_harness.evaluate.convergence import DEFAULT_TARGETS
    from cornell_harness.workflows.converge import experiment_results, run_experiment
    from cornell_harness.reports.experiment import write_experiment_report

    runnable = [e for e in entries if e.available and not missing_features(e.renderer, sc)]
    cells = sum(1 if attribute(e.renderer, "deterministic") else seeds for e in runnable)
    failed: set[str] = set()
    # With repeats a unit is one timing: a cell's first, then each repeat of its final checkpoint.
    # kept: each cell is stored as it finishes, and a rerun renders only the rest (what a Ctrl-C says).
    with Progress(cells * time_repeats, f"converge {sc.name}", "cell" if time_repeats == 1 else "timing",
                  slots=getattr(executor, "slots", 1), kept=True) as bar:
        def label(name: str) -> str:  # name: a cell's file stem, pathtracer__seed2
            return name.replace("__seed", " seed ")

        def on_cell(name: str, cached: bool) -> None:
            bar.advance(label(name), stored=cached, failed=name in failed)

        def on_repeat(name: str, cached: bool) -> None:
            bar.advance(f"{label(name)} repeat", stored=cached)

        runs = run_experiment(out, sc, ref, entries, spps, list(range(seeds)), command_line(), on_cell=on_cell,
                              targets=targets or DEFAULT_TARGETS, executor=executor,
                              on_failed=lambda name, reason: failed.add(name), time_repeats=time_repeats,
                              time_basis=time_basis, on_repeat=on_repeat,
                              on_start=lambda name: bar.start(label(name)))
    results = experiment_results(out, sc, ref, summary_dir=out)
    return runs, write_experiment_report(out, sc, ref, results=results, title=title, sections=sections)


def print_summary(out: Path, runs) -> None:
    """The summary table (and the per-region split), then a line per renderer that did not run."""
    if (out / SUMMARY_FILE).exists():
        _print_summary(out / SUMMARY_FILE)
    for _, r in runs[runs["status"] != "ok"].iterrows():
        typer.echo(f"{r['renderer']}: {r['status']}: {r['reason']}")


def _print_json(out: Path, report: Path, runs) -> None:
    """``cbox converge --json``: every run and the summary, rows as objects (:func:`runner.json_row`)."""
    import pandas as pd

    from cornell_harness.workflows.runner import json_row

    summary = pd.read_parquet(out / SUMMARY_FILE) if (out / SUMMARY_FILE).exists() else pd.DataFrame()
    print_json({"folder": out, "report": report,
                "runs": [json_row(r) for r in runs.to_dict("records")],
                "summary": [json_row(r) for r in summary.to_dict("records")]})


def _print_summary(path: Path) -> None:
    """The summary, image-wide; then, for a scene with regions, bias² and variance per (renderer, region)."""
    import pandas as pd

    from cornell_harness.evaluate.regions import REGION_PREFIX
    from cornell_harness.evaluate.summary import region_split, with_intervals

    summary = pd.read_parquet(path)
    fmt = {"float_format": lambda v: f"{v:.4g}", "index": False}
    image_wide = summary[[c for c in summary.columns if not c.startswith(REGION_PREFIX)]]
    typer.echo(with_intervals(image_wide).to_string(**fmt))
    if not (split := region_split(summary)).empty:
        typer.echo("\nbias² and variance per region (95% intervals):\n" + with_intervals(split).to_string(**fmt))


def _checked_scene(folder: Path, overrides: Optional[List[str]]):
    """The scene the experiment in ``folder`` was made for, as it is now: refused if it no longer hashes the same."""
    config, _ = load_results(folder)
    sc = resolve_scene(config["scene"], overrides)
    if sc.content_hash() != config["scene_hash"]:
        raise ExperimentError(
            f"{folder / CONFIG_FILE}: results were made for scene hash {config['scene_hash']}, but "
            f"{config['scene']} now hashes to {sc.content_hash()}; rerun the experiment"
            + (f" or give the --set it was run with ({config['scene_name']})"
               if "[" in config.get("scene_name", "") and config["scene_name"] != sc.name else ""))
    return sc


def _report_labels(folders: List[Path], labels: Optional[List[str]], out: Optional[Path]) -> list[str]:
    """One label per folder (given, or the folder's name), distinct; the usage errors of several folders."""
    n = len(folders)
    if n > 1 and out is None:
        raise typer.BadParameter(f"{n} folders make one merged report: give --out FOLDER for it",
                                 param_hint="--out")
    if labels and len(labels) != n:
        raise typer.BadParameter(f"{len(labels)} label{'s' if len(labels) > 1 else ''} for {n} folder"
                                 f"{'s' if n > 1 else ''}: give one --label per folder, in order",
                                 param_hint="--label")
    names = list(labels) if labels else [f.resolve().name for f in folders]
    if "" in (name.strip() for name in names):
        raise typer.BadParameter("a label cannot be empty", param_hint="--label")
    if (dup := next((x for i, x in enumerate(names) if x in names[:i]), None)) is not None:
        raise typer.BadParameter(f"{dup!r} names two experiments; labels must differ (default: the folder's name)",
                                 param_hint="--label")
    if n > 1 and any(out.resolve() == f.resolve() for f in folders):
        raise typer.BadParameter(f"{out} is one of the experiment folders; the merged report needs a folder of "
                                 "its own", param_hint="--out")
    return names


@app.command()
def report(
    folders: List[Path] = typer.Argument(..., metavar="DIR", help="Folder written by cbox converge or cbox "
                                                                  "compare; several: one merged report in --out."),
    overrides: Optional[List[str]] = typer.Option(None, "--set", metavar="KEY=VALUE",
                                                  help="The --set the experiments were run with (repeatable); "
                                                       "applies to every DIR."),
    out: Optional[Path] = out_folder_option(None, "Folder of report.html and figures/ (default: DIR); required "
                                                  "with several DIRs, for the merged report."),
    title: Optional[str] = TitleOpt,
    label: Optional[List[str]] = typer.Option(None, "--label", help="Name of each experiment in the report, one "
                                                                    "per DIR in order (default: the folder's name); "
                                                                    "a renderer name two DIRs share gets it too."),
    time_basis: Optional[str] = time_basis_option(
        None, "The clock time-derived figures read: wall (time_s) or cpu (cpu_time_s). Default: the one each "
              "experiment was run with (its experiment.json), else wall."),
    series_label: Optional[List[str]] = SeriesLabelOpt,
    crop: Optional[List[str]] = CropOpt,
) -> None:
    """Rebuild a report from stored results, without rendering: DIR/report.html (and summary.parquet, .csv, .tex).

    Several DIRs make one report in --out: each experiment a section (scene,
    images, table, charts, a link to its own report), led by the experiments
    of the first DIR's scene combined in one summary table, image viewer and
    set of convergence charts.
    """
    from cornell_harness.workflows.converge import experiment_results
    from cornell_harness.reports.experiment import write_experiment_report

    labels = _report_labels(folders, label, out)
    checked = [(folder, _checked_scene(folder, overrides)) for folder in folders]
    if len(folders) == 1:
        (folder, sc), ref = checked[0], load_reference(checked[0][1])
        results = experiment_results(folder, sc, ref, summary_dir=out or folder, time_basis=time_basis)
        names = list(dict.fromkeys(results.runs["renderer"].astype(str)))
        options = keep_report_options(folder, series_labels_for(series_label, names),
                                      parse_crops(crop, sc.camera.width, sc.camera.height),
                                      save=out is None or out.resolve() == folder.resolve())
        path = write_experiment_report(folder, sc, ref, results=results, title=title, labels=label or (),
                                       report_dir=out, options=options)
    else:
        from cornell_harness.reports.merge import write_merged_report

        refs = [load_reference(sc) for _, sc in checked]
        experiments = [(name, folder, sc, ref, experiment_results(folder, sc, ref, time_basis=time_basis))
                       for name, (folder, sc), ref in zip(labels, checked, refs)]
        lead = checked[0][1]
        names = list(dict.fromkeys(str(n) for e in experiments for n in e[4].runs["renderer"]))
        path = write_merged_report(out, experiments, title=title, options={
            "series_labels": series_labels_for(series_label, names),
            "crops": parse_crops(crop, lead.camera.width, lead.camera.height)})
    info(f"report: {path}")
