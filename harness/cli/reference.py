"""``cbox reference build`` and ``cbox reference show``: the stored references."""

from __future__ import annotations

import json
import sys

import typer
from tqdm import tqdm

from harness.adapters.registry import RendererError, resolve
from harness.cli.common import REFERENCE_RENDERER, SceneOpt, reference_app
from harness.scenes.library import resolve_scene
from harness.store.references import load_reference
# Heavy modules (SciPy, pandas, the report) are imported inside the commands that use them: `cbox gate` on
# a misspelt config, or `cbox --help`, must answer in a second.


@reference_app.command("build")
def reference_build(
    scene: str = SceneOpt,
    spp: int = typer.Option(16384, "--spp", min=2, help="Total samples per pixel of the reference."),
    batches: int = typer.Option(128, "--batches", min=2, help="Independent batches; their spread gives the variance image."),
) -> None:
    """Render the scene's reference with Mitsuba and store image, variance and provenance beside the scene."""
    sc = resolve_scene(scene)
    if spp % batches:
        raise typer.BadParameter(f"--spp ({spp}) must be a multiple of --batches ({batches})")
    from harness.workflows.reference_build import build_reference

    (entry,) = resolve([REFERENCE_RENDERER])
    if not entry.available:
        raise RendererError(f"renderer {entry.name!r} builds references but is unavailable: {entry.reason}")
    bar = tqdm(total=batches + 1, desc=f"reference {sc.name}", unit="batch", file=sys.stderr, dynamic_ncols=True)
    ref = build_reference(sc, spp, batches, entry, progress=lambda b, n: bar.update(1))
    bar.close()
    typer.echo(f"wrote {ref.folder} ({spp} spp in {ref.provenance['wall_time_s']:.0f} s, {ref.provenance['renderer_version']})")


@reference_app.command("show")
def reference_show(scene: str = SceneOpt) -> None:
    """Print the provenance of a scene's stored reference (refused if the scene changed)."""
    ref = load_reference(resolve_scene(scene))
    typer.echo(json.dumps(ref.provenance, indent=1))
