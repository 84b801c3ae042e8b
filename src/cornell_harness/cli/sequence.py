"""``cbox sequence``: an animated scene's frames with each renderer at each seed, scored per frame against the
per-frame references, the temporal figures (flicker, lag, ghosting) and their report."""

from __future__ import annotations

import math
from pathlib import Path
from typing import List, Optional

import typer

from cornell_harness.cli.common import (DashboardOpt, RendererFilesOpt, RenderersOpt, SceneOpt, SchedulerOpt,
                                        TimeLimitOpt, WorkersOpt, app, command_line, executor_for, out_folder_option)
from cornell_harness.cli.output import info


@app.command()
def sequence(
    scene: str = SceneOpt,
    renderer: Optional[List[str]] = RenderersOpt,
    renderer_files: Optional[List[Path]] = RendererFilesOpt,
    spp: int = typer.Option(1, "--spp", min=1, help="Samples per pixel of every frame."),
    seeds: int = typer.Option(3, "--seeds", min=1, help="Seeds 0 .. K-1: the report's confidence bands are over them."),
    frames: Optional[str] = typer.Option(None, "--frames", help="Consecutive frames A-B to render and score "
                                         "(default all); a stateful renderer still renders from frame 0."),
    out: Path = out_folder_option(Path("out/sequence"), "Folder for frames.csv, sequences.csv, sequences.json, "
                                                        "sequence.html and the animations."),
    time_limit: Optional[str] = TimeLimitOpt,  # seconds (float), by the option's callback: a whole sequence's
    workers: Optional[int] = WorkersOpt,
    scheduler: Optional[str] = SchedulerOpt,
    dashboard: Optional[str] = DashboardOpt,
) -> None:
    """Render every frame of an animated scene, score each against its frame's reference, and measure flicker
    (beside the reference's floor), lag after the scene's change and ghosting where motion uncovers surfaces.

    A renderer with a temporal state renders the sequence itself; any other renders each frame on its own. A
    sweep of a setting (-r 'probes[hysteresis=0.9]' -r 'probes[hysteresis=0.97]') traces the lag/flicker curve.
    Exit code 1 if a renderer failed. --time-limit bounds a whole sequence.
    """
    from cornell_harness.adapters.registry import resolve
    from cornell_harness.reports.sequence import lag_text, write_sequence_report
    from cornell_harness.scenes.library import resolve_scene
    from cornell_harness.workflows.sequence_run import run_sequence, sequence_references, write_sequence_results

    sc = resolve_scene(scene)
    chosen = _frames(frames, sc.frame_count)
    references = sequence_references(sc, chosen)
    with executor_for(workers, scheduler, dashboard) as executor:
        result = run_sequence(resolve(renderer), sc, spp, list(range(seeds)), references, chosen, time_limit,
                              executor)
    written = write_sequence_results(out, result)
    report = write_sequence_report(out, sc.name, result.frame_rows, result.sequence_rows, result.images,
                                   [r.image for r in references], command_line())
    for row in result.sequence_rows:
        lag = lag_text(row.get("lag", math.nan), row.get("lag_bound"), "frames")
        info(f"{row['renderer']} seed {row['seed']}: {row['status']}" + (
            f", flicker {row['flicker']:.3g} (floor {row['flicker_floor']:.3g}), lag {lag}, "
            f"ghosting {row['ghosting']:.3g}" if row["status"] == "ok" else f" ({row['reason']})"))
    info(f"wrote {', '.join(str(p) for p in written)} and {report}")
    raise typer.Exit(1 if any(r["status"] == "failed" for r in result.sequence_rows) else 0)


def _frames(text: str | None, count: int) -> list[int]:
    """The frames ``--frames`` names (:func:`cornell_harness.scenes.animation.frame_list`), every frame without
    it; a usage error (exit 2) unless they are consecutive: flicker and lag compare each frame with the one before."""
    from cornell_harness.scenes.animation import frame_list

    if text is None:
        return list(range(count))
    try:
        chosen = frame_list(text, count)
    except ValueError as e:
        raise typer.BadParameter(str(e), param_hint="--frames") from None
    if chosen != list(range(chosen[0], chosen[-1] + 1)):
        raise typer.BadParameter(f"{text!r}: the frames must be consecutive (A-B): flicker and lag compare each "
                                 "frame with the one before", param_hint="--frames")
    return chosen
