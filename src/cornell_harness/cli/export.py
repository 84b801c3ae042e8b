"""``cbox export``: a scene written for another renderer, in its own format (:mod:`cornell_harness.scenes.export`)."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from cornell_harness.cli.choices import choice_callback
from cornell_harness.cli.common import SceneOpt, SetOpt, app, out_folder_option
from cornell_harness.scenes.export import FORMATS
from cornell_harness.scenes.library import resolve_scene

FORMAT_HELP = ("Format to write: mitsuba (scene.xml and meshes/*.ply, Mitsuba 3 XML: `mitsuba DIR/scene.xml -o "
               "out.exr -D spp=64 -D seed=3`, with `-m llvm_ad_spectral` for a spectral scene), luxcore "
               "(LuxCore SDL: scene.scn and scene.cfg), pbrt-v4 "
               "(scene.pbrt: `pbrt DIR/scene.pbrt --spp 64 --seed 3`), json (scene.json, a neutral "
               "description for a renderer of your own, ambient occlusion included; its schema: "
               "src/cornell_harness/schemas/json-scene.schema.json), gltf (glTF 2.0: scene.gltf and "
               "scene.bin, for real-time engines; needs the [gltf] extra) or usd (scene.usda, OpenUSD: the "
               "[usd] extra). How each maps our scene model: "
               "docs/export.md.")


@app.command("export")
def export(
    scene: str = SceneOpt,
    fmt: str = typer.Option(..., "--format", "-f", help=FORMAT_HELP, show_default=False, metavar="|".join(FORMATS),
                            callback=choice_callback("--format", lambda: FORMATS,
                                                     "unknown export format {value!r}{hint}; formats: {listed}")),
    out: Path = out_folder_option(Path("out/export"), "Folder to write the scene into (created if missing); "
                                                      "files of an earlier export there are replaced."),
    overrides: Optional[List[str]] = SetOpt,
    frame: Optional[int] = typer.Option(None, "--frame", min=0, metavar="N", help=(
        "Write frame N of an animated scene as a still scene (the formats that cannot express an animation "
        "refuse the animated scene without it).")),
) -> None:
    """Write the scene, with its meshes, in another renderer's format.

    Prints the path of the main file, the one a renderer is given, and on
    stderr the command that renders it where the format needs more than the
    file (a spectral scene's Mitsuba variant). A scene the format cannot
    express (a feature it lacks, or a quantity it does not carry: only json
    and usd carry cornell-box-ao's ambient occlusion) is refused before
    anything is written: one line naming the scene file and field, exit 2.
    """
    from cornell_harness.scenes.export import export_scene, render_command

    resolved = resolve_scene(scene, overrides)
    if frame is not None:
        try:
            resolved = resolved.at_frame(frame)
        except IndexError as e:
            raise typer.BadParameter(str(e), param_hint="--frame") from None
    main = export_scene(resolved, fmt, out)
    typer.echo(main)
    if command := render_command(resolved, fmt, main):
        typer.echo(f"cbox: render it with: {command}", err=True)
