"""What every ``cbox`` command shares: the typer apps, common options, user errors, progress bars.

Bad input (a malformed scene, an unknown renderer or setting, a stale
reference) ends with a one-line ``cbox: error: ...`` on stderr and exit code
2, never a traceback: commands raise one of :data:`USER_ERRORS` and
:func:`harness.cli.app.main` prints it.
"""

from __future__ import annotations

import shlex
import sys

import typer
from tqdm import tqdm

from harness.adapters.registry import RendererError
from harness.adapters.settings import SettingsError
from harness.gate.config import GateConfigError
from harness.scenes.model import SceneError
from harness.store.experiments import ExperimentError
from harness.store.exr import ImageFileError
from harness.store.references import ReferenceError

#: The harness's reference renderer: references are built with it.
REFERENCE_RENDERER = "mitsuba"

app = typer.Typer(
    help="Validation harness for renderers on the Cornell box: render, score against a trusted reference, report.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
reference_app = typer.Typer(help="Build and inspect stored reference images.", no_args_is_help=True)
app.add_typer(reference_app, name="reference")

USER_ERRORS = (SceneError, ReferenceError, RendererError, ImageFileError, ExperimentError, GateConfigError,
               SettingsError)

SceneOpt = typer.Option(..., "--scene", "-s", help="Stored scene name (see `cbox scenes`) or path to a scene .toml file or folder.")
SppOpt = typer.Option(64, "--spp", min=1, help="Samples per pixel.")
RenderersOpt = typer.Option(None, "--renderer", "-r", help="Renderer to run (repeatable), with settings as "
                            "NAME\\[setting=value,...]; default: every registered renderer.")
SeedOpt = typer.Option(0, "--seed", min=0, help="Random seed; the same seed gives the same image.")


def _command_line() -> str:
    return " ".join(shlex.quote(a) for a in ["cbox", *sys.argv[1:]])


def _progress(total: int, desc: str) -> tqdm:
    return tqdm(total=total, desc=desc, unit="run", file=sys.stderr, dynamic_ncols=True, leave=False)
