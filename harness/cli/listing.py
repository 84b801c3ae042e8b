"""``cbox scenes``, ``cbox renderers``, ``cbox features``: what is here, and what can run."""

from __future__ import annotations

import typer

from harness.adapters.registry import quantities_of, resolve
from harness.adapters.settings import declared, describe
from harness.cli.common import app
from harness.scenes.library import resolve_scene, scene_names
from harness.scenes.model import FEATURES, SceneError
from harness.store.references import ReferenceError, load_reference


@app.command()
def scenes() -> None:
    """List the stored scenes, with the features each uses, its named regions and whether it has a reference."""
    names = scene_names()
    w = max((len(n) for n in names), default=0)
    for name in names:
        try:
            scene = resolve_scene(name)
        except SceneError as e:
            typer.echo(f"{name:{w}s} INVALID: {e}")
            continue
        try:
            ref = load_reference(scene)
            status = f"reference {ref.spp} spp"
        except ReferenceError as e:
            status = f"no usable reference ({str(e).split(';')[0].split(': ', 1)[-1]})"
        cam = scene.camera
        ao = scene.ambient_occlusion
        # max_depth means nothing to an AO image; its definition does.
        what = (f"max_depth={scene.max_depth}" if ao is None else
                f"ambient_occlusion ({ao.weighting}, max_distance={ao.max_distance:g}, {ao.normal} normal, "
                f"miss={ao.miss_value:g})")
        typer.echo(f"{name:{w}s} {cam.width}x{cam.height}  {what}  {status}")
        typer.echo(f"{'':{w}s} features: {', '.join(sorted(scene.features))}")
        if scene.regions:
            typer.echo(f"{'':{w}s} regions: {', '.join(scene.regions)}")


@app.command()
def renderers(
    settings: bool = typer.Option(False, "--settings", help="Also list each renderer's settings: name, default, "
                                                            "allowed values and what it does."),
) -> None:
    """List the registered renderers, whether each can run here, and why not."""
    for entry in resolve(None):
        r = entry.renderer
        if entry.available:
            try:
                version = r.version()
            except Exception as e:  # a version probe must not break the listing
                version = f"version unknown ({type(e).__name__})"
            typer.echo(f"{entry.name:12s} available    {version}")
        else:
            typer.echo(f"{entry.name:12s} unavailable  {entry.reason}")
        if r is not None:
            typer.echo(f"{'':12s} models: {', '.join(sorted(r.features))}")
            typer.echo(f"{'':12s} computes: {', '.join(quantities_of(r))}")
            for a in getattr(r, "approximations", ()):
                typer.echo(f"{'':12s} approximates: {a}")
            if settings:
                for line in describe(declared(r)) or ["(no settings)"]:
                    typer.echo(f"{'':12s} setting: {line}")


@app.command()
def features() -> None:
    """List the scene features a scene can declare and a renderer can model."""
    for name, meaning in FEATURES.items():
        typer.echo(f"{name:16s} {meaning}")
