"""The optional extras of ``cornell-harness``: which one each registered renderer and each option needs, and the
``pip install`` line that adds it.

The core install scores images (scenes, export, command-line renderers, the metrics, the gate, reports, the
stored references, the CLI); an extra adds renderers or a backend (pyproject.toml's
``[project.optional-dependencies]``, whose lists this module's :data:`MODULES` must name, but for the extras
:data:`COMMANDS` installs with a command of their own). Whether an extra is installed is asked of the import
system (``importlib.util.find_spec``), without importing anything.
"""

from __future__ import annotations

import importlib.util
from typing import Iterable

DISTRIBUTION = "cornell-harness"

#: Each extra's top-level import names, one per distribution it installs.
MODULES: dict[str, tuple[str, ...]] = {
    "ours": ("numba", "embreex"),
    "mitsuba": ("mitsuba",),
    "luxcore": ("pyluxcore",),
    "raster": ("pyrender", "OpenGL"),
    "oidn": ("pyoidn",),
    "dask": ("dask", "distributed"),
    "gltf": ("pygltflib",),
    "usd": ("pxr",),
    "cycles": ("bpy",),
}

#: Extras that are not pyproject's, each with the command that installs it. ``bpy`` 5.0.1 (Blender, for the
#: ``cycles`` renderer) requires numpy<2 and the core numpy>=2, so pip cannot resolve it as an extra; Blender
#: runs only in the renderer's child process, where it works on NumPy 2
#: (:mod:`cornell_harness.renderers.cycles_cli`), so it is installed without its dependencies (it needs none
#: of them there).
COMMANDS: dict[str, str] = {"cycles": "pip install --no-deps 'bpy==5.0.1'"}

#: The extras each of our registered renderers (pyproject.toml's ``cbox.renderers`` entry points) runs on.
RENDERERS: dict[str, tuple[str, ...]] = {
    **{name: ("ours",) for name in ("pathtracer", "photonmap", "sppm", "ao", "ambient", "ssao", "probes", "whitted")},
    "mitsuba": ("mitsuba",),
    "luxcore": ("luxcore",),
    "pyrender": ("raster",),
    "pathtracer+oidn": ("ours", "oidn"),
    "pathtracer+temporal": ("ours",),
    "pathtracer+svgf": ("ours",),
    "mitsuba+oidn": ("mitsuba", "oidn"),
    "cycles": ("cycles",),
}

#: The export formats (cornell_harness.scenes.export) that need an extra to be written.
EXPORT_FORMATS: dict[str, str] = {"gltf": "gltf", "usd": "usd"}

#: Command-line options that need an extra: a cluster's executor (cornell_harness.workflows.executor).
OPTIONS: dict[str, str] = {"--workers": "dask", "--scheduler": "dask"}


class MissingExtraError(RuntimeError):
    """Something asked for needs an extra that is not installed; ``str()`` ends with the pip line."""


def install_line(extras: Iterable[str]) -> str:
    """The command that installs ``extras``: ``pip install 'cornell-harness[luxcore]'`` (and, joined by
    ``&&``, the :data:`COMMANDS` of those pip cannot install as extras)."""
    extras = list(extras)
    listed = [extra for extra in extras if extra not in COMMANDS]
    lines = [f"pip install '{DISTRIBUTION}[{','.join(listed)}]'"] if listed else []
    return " && ".join(lines + [COMMANDS[extra] for extra in extras if extra in COMMANDS])


def missing_modules(extras: Iterable[str]) -> list[str]:
    """The import names of ``extras`` that cannot be imported here (none: they are all installed)."""
    return [m for extra in extras for m in MODULES[extra] if importlib.util.find_spec(m) is None]


def renderer_problem(name: str) -> str | None:
    """Why the registered renderer ``name`` cannot run here for want of an extra, with the pip line; None when
    its extras are installed (or it is not one of ours)."""
    extras = RENDERERS.get(name, ())
    missing = missing_modules(extras)
    if not missing:
        return None
    wanting = [extra for extra in extras if missing_modules([extra])]
    return f"{', '.join(missing)} not installed: {install_line(wanting)}"


def require(option: str) -> None:
    """Raise MissingExtraError, naming the pip line, when the extra ``option`` needs (:data:`OPTIONS`) is missing."""
    extra = OPTIONS[option]
    if missing := missing_modules([extra]):
        raise MissingExtraError(f"{option} needs the [{extra}] extra ({', '.join(missing)} not installed): "
                                f"{install_line([extra])}")


def export_format_problem(name: str) -> str | None:
    """Why the export format ``name`` cannot be written here for want of an extra, with the pip line; None when
    it can (its extra is installed, or it needs none)."""
    extra = EXPORT_FORMATS.get(name)
    if extra is None or not (missing := missing_modules([extra])):
        return None
    return (f"the {name} export format needs the [{extra}] extra ({', '.join(missing)} not installed): "
            f"{install_line([extra])}")


def require_export_format(name: str) -> None:
    """Raise MissingExtraError, naming the pip line, when the export format ``name`` needs a missing extra."""
    if problem := export_format_problem(name):
        raise MissingExtraError(problem)


def require_a_renderer(command: str) -> None:
    """Raise MissingExtraError, with the ``[all]`` pip line, when none of our registered renderers can run here
    (the core install): ``command`` runs them, and would only list each as unavailable."""
    if all(renderer_problem(name) for name in RENDERERS):
        raise MissingExtraError(f"{command} runs the harness's own renderers and Mitsuba, and none is installed "
                                f"here: {install_line(['all'])}")
