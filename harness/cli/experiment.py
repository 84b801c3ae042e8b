"""``cbox converge`` (convergence experiments, sweeps) and ``cbox report`` (rebuild a report, no rendering)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import List, Optional

import typer
from tqdm import tqdm

from harness.adapters.registry import missing_features, resolve
from harness.cli.common import RenderersOpt, SceneOpt, _command_line, app, out_folder_option
from harness.scenes.library import resolve_scene
from harness.store.experiments import CONFIG_FILE, SUMMARY_FILE, ExperimentError, load_results
from harness.store.references import load_reference
# Heavy modules (SciPy, pandas, the report) are imported inside the commands that use them: `cbox gate` on
# a misspelt config, or `cbox --help`, must answer in a second.


@app.command()
def converge(
    scene: str = SceneOpt,
    renderer: Optional[List[str]] = RenderersOpt,
    spp: str = typer.Option("1,2,4,...,256", "--spp", help="spp checkpoints: 1,2,4,...,256 or 1,4,16 or 1-256 "
                                                         "(powers of two). Progressive renderers give them all "
                                                         "from one render."),
    seeds: int = typer.Option(4, "--seeds", min=1, help="Number of seeds (0 .. N-1); bias and variance need 2 or more."),
    out: Path = out_folder_option(Path("out/converge"), "Experiment folder: results.parquet, "
                                                                      "summary.csv, report.html, cells/, images/."),
    target: Optional[List[str]] = typer.Option(
        None, "--target", help="Target error for the time-to-target figure, METRIC=VALUE (repeatable), the "
                               "metric image-wide or in a region of the scene (region.caustic.rel_mse=0.01); "
                               "default: delta_e2000_mean=2, delta_e2000_mean=1, rel_mse=0.01, rel_mse=0.001."),
    sweep: Optional[str] = typer.Option(
        None, "--sweep", help="Sweep one renderer setting, RENDERER.SETTING=V1,V2,... (e.g. "
                              "pathtracer.rr_depth=3,5,8): each value is its own series in the table and report. "
                              "See `cbox renderers --settings`."),
) -> None:
    """Convergence experiment: every metric at every spp checkpoint, per renderer and seed.

    Results are a tidy table (one row per scene, renderer, settings, seed and
    spp) in OUT/results.parquet. The run is resumable: finished (renderer,
    seed) cells are written atomically, and running the same command again
    renders only the cells that are missing.
    """
    from harness.adapters.registry import sweep as sweep_entries
    from harness.adapters.settings import parse_sweep
    from harness.evaluate.convergence import DEFAULT_TARGETS, parse_target, unknown_target_regions
    from harness.workflows.converge import parse_spp_list, run_experiment
    from reports.experiment import write_experiment_report

    try:
        spps = parse_spp_list(spp)
        targets = [parse_target(t) for t in target] if target else DEFAULT_TARGETS
    except ValueError as e:
        raise typer.BadParameter(str(e)) from None
    sc = resolve_scene(scene)
    if unknown := unknown_target_regions(targets, sc.regions):
        raise typer.BadParameter(f"--target: scene {sc.name!r} has no region {', '.join(map(repr, unknown))}; "
                                 f"its regions: {', '.join(sc.regions) or '(none)'}")
    ref = load_reference(sc)
    entries = resolve(renderer)
    if sweep:
        entries = sweep_entries(entries, *parse_sweep(sweep))
    runnable = [e for e in entries if e.available and not missing_features(e.renderer, sc)]
    cells = sum(1 if getattr(e.renderer, "deterministic", False) else seeds for e in runnable)
    bar = tqdm(total=cells, desc=f"converge {sc.name}", unit="cell", file=sys.stderr,
               dynamic_ncols=True)

    def on_cell(name: str, cached: bool) -> None:
        bar.set_postfix_str(f"{name}{' (stored)' if cached else ''}")
        bar.update(1)

    runs = run_experiment(out, sc, ref, entries, spps, list(range(seeds)), _command_line(), on_cell=on_cell,
                          targets=targets)
    bar.close()
    report = write_experiment_report(out, sc, ref)
    if (out / SUMMARY_FILE).exists():
        _print_summary(out / SUMMARY_FILE)
    for _, r in runs[runs["status"] != "ok"].iterrows():
        typer.echo(f"{r['renderer']}: {r['status']}: {r['reason']}")
    typer.echo(f"report: {report}", err=True)
    raise typer.Exit(1 if (runs["status"] == "failed").any() else 0)


def _print_summary(path: Path) -> None:
    """The summary, image-wide; then, for a scene with regions, bias² and variance per (renderer, region)."""
    import pandas as pd

    from harness.evaluate.regions import REGION_PREFIX
    from harness.workflows.converge import region_split

    summary = pd.read_csv(path)
    fmt = {"float_format": lambda v: f"{v:.4g}", "index": False}
    typer.echo(summary[[c for c in summary.columns if not c.startswith(REGION_PREFIX)]].to_string(**fmt))
    if not (split := region_split(summary)).empty:
        typer.echo("\nbias² and variance per region:\n" + split.to_string(**fmt))


@app.command()
def report(
    folder: Path = typer.Argument(..., help="Folder written by cbox converge or cbox compare."),
) -> None:
    """Rebuild FOLDER/report.html (and summary.csv) from stored results, without rendering."""
    from reports.experiment import write_experiment_report

    config, _ = load_results(folder)
    sc = resolve_scene(config["scene"])
    if sc.content_hash() != config["scene_hash"]:
        raise ExperimentError(
            f"{folder / CONFIG_FILE}: results were made for scene hash {config['scene_hash']}, but "
            f"{config['scene']} now hashes to {sc.content_hash()}; rerun the experiment")
    typer.echo(f"report: {write_experiment_report(folder, sc, load_reference(sc))}", err=True)
