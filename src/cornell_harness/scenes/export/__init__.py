"""Scene export: a scene written in another renderer's own format, with its meshes, for ``cbox export``
and the command-line renderers (:mod:`cornell_harness.adapters.commands`).

One module per format (``mitsuba``, ``luxcore``, ``pbrt_v4``, ``json_scene``, ``gltf``, ``usd``), each with the
same interface:

- ``NAME``: the format's name, as ``cbox export --format`` and a renderer file's ``scene_format`` give it;
- ``FEATURES``: the scene features (:data:`cornell_harness.scenes.model.FEATURES`) the format can express;
- ``MAPPING``: the rows of the format's mapping table, ``(aspect, ours, theirs)``: camera, fov axis,
  handedness, emitter side, two-sidedness, filter, depth, IOR (:func:`mapping_table` prints it; the
  format's page in ``docs/export.md`` shows it);
- ``write(scene, folder) -> Path``: writes the scene into ``folder`` (which exists and is empty) and
  returns the main file a renderer is given (``scene.xml``, ``scene.cfg``, ``scene.pbrt``, ``scene.json``).
- optionally ``QUANTITIES``: the scene quantities (:data:`cornell_harness.scenes.quantities.QUANTITIES`)
  the format carries, with their definitions (``json`` carries ambient occlusion's distance, weighting
  and miss value); ``("radiance",)`` when absent (:func:`quantities`);
- optionally ``refusal(scene) -> SceneError | None``: why the format cannot express a scene whose
  features it has (e.g. luxcore and ``render.max_depth = 1``).
- optionally ``ANIMATION = True``: the format carries an animated scene's ``[animation]``
  (:mod:`cornell_harness.scenes.animation`); every other format refuses an animated scene, whose single frames
  (``Scene.at_frame``, ``cbox export --frame N``) it writes as still scenes.
- optionally ``render_command(scene, main) -> str``: the command that renders the written ``main`` file,
  where running it needs more than the file (Mitsuba's spectral variant for a spectral scene); ``cbox export``
  prints it.

A scene the format cannot express (a feature it lacks, a quantity it does not carry) is refused
before anything is written, with one :class:`~cornell_harness.scenes.model.SceneError` naming the scene file
and the field (``features``, ``quantity``): the CLI's one line and exit 2.
"""

from __future__ import annotations

import importlib
import os
import shutil
import tempfile
from pathlib import Path
from types import ModuleType

from cornell_harness.extras import export_format_problem, require_export_format
from cornell_harness.scenes.model import SceneError, Scene
from cornell_harness.scenes.quantities import DEFAULT_QUANTITY

#: Every export format, by name, and the module that writes it (imported when used).
FORMATS: dict[str, str] = {
    "mitsuba": "cornell_harness.scenes.export.mitsuba",
    "luxcore": "cornell_harness.scenes.export.luxcore",
    "pbrt-v4": "cornell_harness.scenes.export.pbrt_v4",
    "json": "cornell_harness.scenes.export.json_scene",
    "gltf": "cornell_harness.scenes.export.gltf",  # the extras of cornell_harness.extras.EXPORT_FORMATS
    "usd": "cornell_harness.scenes.export.usd",
}


def format_module(name: str) -> ModuleType:
    """The module that writes format ``name``; KeyError-free: an unknown name is a SceneError-free ValueError."""
    if name not in FORMATS:
        raise ValueError(f"unknown export format {name!r}; formats: {', '.join(FORMATS)}")
    if problem := export_format_problem(name):  # an ImportError: the format cannot be written here
        raise ModuleNotFoundError(problem, name=FORMATS[name])
    return importlib.import_module(FORMATS[name])


def quantities(name: str) -> tuple[str, ...]:
    """The scene quantities format ``name`` carries (its module's ``QUANTITIES``, radiance when it says none)."""
    return tuple(getattr(format_module(name), "QUANTITIES", (DEFAULT_QUANTITY,)))


def refusal(scene: Scene, name: str) -> SceneError | None:
    """Why format ``name`` cannot express ``scene`` (a SceneError naming file and field), or None."""
    module = format_module(name)
    if scene.quantity not in (carried := quantities(name)):
        return SceneError(scene.path, "quantity", f"{scene.quantity} cannot be exported to {name}: the format "
                                                  f"carries {', '.join(carried)} only")
    if missing := sorted(scene.features - set(module.FEATURES)):
        return SceneError(scene.path, "features", f"{name} cannot express {', '.join(missing)}")
    if scene.animation is not None and not getattr(module, "ANIMATION", False):
        return SceneError(scene.path, "animation", f"{name} cannot express an animated scene "
                                                   f"({scene.frame_count} frames); export one frame with --frame N")
    if hasattr(module, "refusal"):
        return module.refusal(scene)
    return None


def export_scene(scene: Scene, name: str, out: Path | str) -> Path:
    """Write ``scene`` in format ``name`` into the folder ``out``; return the main file's path.

    Refused (SceneError) before anything is written when the format cannot express the scene. The files
    are written into a temporary folder beside ``out`` and moved into place, so an interrupted export
    leaves no half-written scene; files already in ``out`` that the export writes are replaced. A format whose
    extra is not installed (``usd``) is a MissingExtraError naming the pip line.
    """
    require_export_format(name)  # before anything is imported or written: one line with the pip command
    if (why := refusal(scene, name)) is not None:
        raise why
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".export-", dir=out))
    try:
        main = format_module(name).write(scene, tmp)
        for item in sorted(tmp.rglob("*")):
            target = out / item.relative_to(tmp)
            if item.is_dir():
                target.mkdir(exist_ok=True)
            else:
                os.replace(item, target)
        return out / main.relative_to(tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def render_command(scene: Scene, name: str, main: Path) -> str | None:
    """The command that renders ``scene`` written as ``main`` in format ``name``, where the format says one."""
    module = format_module(name)
    return module.render_command(scene, main) if hasattr(module, "render_command") else None


def mapping_table(name: str) -> str:
    """Format ``name``'s mapping table as Markdown: how each aspect of our scene model is written."""
    rows = format_module(name).MAPPING
    lines = ["| aspect | cornell-harness | " + name + " |", "| --- | --- | --- |"]
    lines += [f"| {a} | {ours} | {theirs} |" for a, ours, theirs in rows]
    return "\n".join(lines)
