"""``cbox reference build`` and ``cbox reference show``: the stored references."""

from __future__ import annotations

import json
from typing import List, Optional

import typer

from harness.adapters.registry import RendererError, resolve
from harness.cli.common import (REFERENCE_RENDERER, DashboardOpt, Progress, SceneOpt, SchedulerOpt, SetOpt, WorkersOpt,
                                executor_for, reference_app)
from harness.scenes.library import resolve_scene
from harness.store.references import load_reference
# Heavy modules (SciPy, pandas, the report) are imported inside the commands that use them: `cbox gate` on
# a misspelt config, or `cbox --help`, must answer in a second.


@reference_app.command("build")
def reference_build(
    scene: str = SceneOpt,
    overrides: Optional[List[str]] = SetOpt,
    spp: int = typer.Option(16384, "--spp", min=2, help="Total samples per pixel of the reference."),
    batches: int = typer.Option(128, "--batches", min=2, help="Independent batches; their spread gives the variance image."),
    workers: Optional[int] = WorkersOpt,
    scheduler: Optional[str] = SchedulerOpt,
    dashboard: Optional[str] = DashboardOpt,
) -> None:
    """Render the scene's reference with Mitsuba and store image, variance and provenance beside the scene.

    With --set, the derived scene's reference goes to derived/<content hash>/ beside the scene; the
    scene's own reference is left as it is. With --workers or --scheduler the batches render on a Dask
    cluster and are combined here in batch order: the same reference as a build in this process.
    """
    sc = resolve_scene(scene, overrides)
    if spp % batches:
        raise typer.BadParameter(f"--spp ({spp}) must be a multiple of --batches ({batches})")
    from harness.workflows.reference_build import build_reference

    (entry,) = resolve([REFERENCE_RENDERER])
    if not entry.available:
        raise RendererError(f"renderer {entry.name!r} builds references but is unavailable: {entry.reason}")
    with executor_for(workers, scheduler, dashboard) as executor, \
            Progress(batches + 1, f"reference {sc.name}", "batch", slots=executor.slots) as bar:  # +1: the noise image
        ref = build_reference(sc, spp, batches, entry, executor=executor,
                              progress=lambda done, total, label: bar.advance(label))
    typer.echo(f"wrote {ref.folder} ({spp} spp in {ref.provenance['wall_time_s']:.0f} s, {ref.provenance['renderer_version']})")


@reference_app.command("show")
def reference_show(scene: str = SceneOpt, overrides: Optional[List[str]] = SetOpt) -> None:
    """Print the provenance of a scene's stored reference (refused if the scene changed)."""
    ref = load_reference(resolve_scene(scene, overrides))
    typer.echo(json.dumps(ref.provenance, indent=1))
