"""``cbox scenes``, ``cbox renderers``, ``cbox features``: what is here, and what can run."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from cornell_harness.adapters.api import attribute
from cornell_harness.adapters.registry import quantities_of, resolve
from cornell_harness.adapters.settings import declared, describe
from cornell_harness.cli.common import HomeOpt, RendererFilesOpt, app, home_line, print_json
from cornell_harness.scenes.library import references_root, resolve_scene, scene_names
from cornell_harness.scenes.model import FEATURES, SceneError
from cornell_harness.store.references import (ReferenceError, load_reference, recorded_verdicts, stored_verdicts,
                                               user_folder, verdict_line)


JsonOpt = typer.Option(False, "--json", help="Print a JSON array of objects on stdout instead of the text.")


@app.command()
def scenes(as_json: bool = JsonOpt, home: Optional[Path] = HomeOpt) -> None:
    """List the stored scenes: file, size, what is computed, features, named regions, reference and its verdicts:
    those it ships with and those `cbox reference verify` recorded in the user store (--home)."""
    listing = [_scene_entry(name, home) for name in scene_names()]
    if as_json:
        print_json(listing)
        return
    typer.echo(home_line(home))
    w = max((len(s["name"]) for s in listing), default=0)
    for s in listing:
        if s["error"]:
            typer.echo(f"{s['name']:{w}s} INVALID: {s['error']}")
            typer.echo(f"{'':{w}s} file: {s['path']}")
            continue
        ao = s["ambient_occlusion"]
        # max_depth means nothing to an AO image; its definition does.
        what = (f"max_depth={s['max_depth']}" if ao is None else
                f"ambient_occlusion ({ao['weighting']}, max_distance={ao['max_distance']:g}, {ao['normal']} normal, "
                f"miss={ao['miss_value']:g})")
        ref = s["reference"]
        status = (f"reference {ref['spp']} spp{' (user store)' if ref['in_user_store'] else ''}" if ref else
                  f"no usable reference ({s['reference_problem']})")
        if s["frames"] > 1:  # an animated scene: the reference shown is frame 0's; frames at one state share one
            status = f"{s['frames']} frames, {s['references']} references, frame 0's {status}"
        typer.echo(f"{s['name']:{w}s} {s['width']}x{s['height']}  {what}  {status}")
        typer.echo(f"{'':{w}s} features: {', '.join(s['features'])}")
        if s["regions"]:
            typer.echo(f"{'':{w}s} regions: {', '.join(s['regions'])}")
        if ref:
            typer.echo(f"{'':{w}s} reference: {ref['verdict']}")
        if ref and ref["recorded"]:
            typer.echo(f"{'':{w}s} recorded (user store): {ref['recorded_verdict']}")
        typer.echo(f"{'':{w}s} file: {s['path']}")


def _scene_entry(name: str, home: Path | None = None) -> dict:
    """What ``cbox scenes`` says of one stored scene, as plain data (its text and its JSON).

    ``verified`` are the verdicts the reference ships with (its provenance), ``recorded`` those recorded in the
    user store (``user_folder``) on the same images; an engine can have one of each."""
    folder = references_root() / name
    entry: dict = {"name": name, "path": _shown(folder / "scene.toml"), "user_folder": _shown(user_folder(folder, home)),
                   "error": None}
    try:
        scene = resolve_scene(name)
    except SceneError as e:
        return {**entry, "error": str(e)}
    try:
        ref = load_reference(scene.at_frame(0), home=home)  # an animated scene's first frame's
        stored, recorded = stored_verdicts(ref.provenance), recorded_verdicts(ref.folder, home)
        reference, problem = {"spp": ref.spp, "renderer_version": ref.provenance.get("renderer_version"),
                              "folder": _shown(ref.folder), "in_user_store": ref.folder.resolve() != folder.resolve(),
                              "verdict": verdict_line(stored), "verified": _verdicts(stored),
                              "recorded_verdict": verdict_line(recorded), "recorded": _verdicts(recorded)}, None
    except ReferenceError as e:
        reference, problem = None, str(e).split(";")[0].split(": ", 1)[-1]
    ao = scene.ambient_occlusion
    return {**entry, "path": _shown(scene.path), "width": scene.camera.width, "height": scene.camera.height,
            "max_depth": scene.max_depth, "frames": scene.frame_count,
            "references": 1 if scene.animation is None else len(scene.animation.reference_frames()),
            "ambient_occlusion": None if ao is None else {"weighting": ao.weighting, "max_distance": ao.max_distance,
                                                          "normal": ao.normal, "miss_value": ao.miss_value},
            "features": sorted(scene.features), "regions": list(scene.regions),
            "reference": reference, "reference_problem": problem}


def _verdicts(verified: dict) -> dict:
    """Each engine's verdict in brief (``cbox reference verify``): passed, max |z|, regions, spp."""
    return {engine: {k: r.get(k) for k in ("passed", "max_abs_z", "chi2", "dof", "chi2_p", "spp", "date")}
            | {"regions": len(r.get("regions", {}))} for engine, r in verified.items()}


def _shown(path: Path) -> str:
    """A path as a user would type it here: relative to the working folder when under it."""
    path = Path(path).resolve()
    try:
        return str(path.relative_to(Path.cwd()))
    except ValueError:
        return str(path)


@app.command()
def renderers(
    renderer_files: Optional[List[Path]] = RendererFilesOpt,
    settings: bool = typer.Option(False, "--settings", help="Also list each renderer's settings: name, default, "
                                                            "allowed values and what it does."),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON array of objects on stdout instead of the "
                                                       "text, settings always included."),
) -> None:
    """List the registered renderers (and those --renderers and $CBOX_RENDERERS declare), whether each can run
    here, and why not."""
    entries = resolve(None)
    listing = [_renderer_entry(entry) for entry in entries]
    if as_json:
        print_json(listing)
        return
    w = max([12, *(len(r["name"]) for r in listing)])  # the names' column
    for entry, r in zip(entries, listing):
        if r["available"]:
            typer.echo(f"{r['name']:{w}s} available    {r['version']}")
        else:
            typer.echo(f"{r['name']:{w}s} unavailable  {r['reason']}")
        if r["loaded"]:
            typer.echo(f"{'':{w}s} models: {', '.join(r['models'])}")
            typer.echo(f"{'':{w}s} computes: {', '.join(r['computes'])}")
            for a in r["approximations"]:
                typer.echo(f"{'':{w}s} approximates: {a}")
            if settings:
                for line in describe(declared(entry.renderer)) or ["(no settings)"]:
                    typer.echo(f"{'':{w}s} setting: {line}")


def _renderer_entry(entry) -> dict:
    """What ``cbox renderers`` says of one registered renderer, as plain data (its text and its JSON)."""
    r = entry.renderer
    out: dict = {"name": entry.name, "available": entry.available, "version": None,
                 "reason": None if entry.available else entry.reason, "loaded": r is not None}
    if entry.available:
        try:
            out["version"] = r.version()
        except Exception as e:  # a version probe must not break the listing
            out["version"] = f"version unknown ({type(e).__name__})"
    if r is not None:
        out.update(models=sorted(r.features), computes=list(quantities_of(r)),
                   approximations=list(attribute(r, "approximations")),
                   settings=[{"name": s.name, "type": s.kind.__name__, "default": s.default, "allowed": s.allowed(),
                              "doc": s.doc} for s in declared(r)])
    return out


@app.command()
def features() -> None:
    """List the scene features a scene can declare and a renderer can model."""
    for name, meaning in FEATURES.items():
        typer.echo(f"{name:16s} {meaning}")
