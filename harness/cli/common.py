"""What every ``cbox`` command shares: the typer apps, common options, user errors, progress bars.

Bad input (a malformed scene, an unknown renderer or setting, a stale
reference, a bad option value, an unusable ``--out``, a bad ``$CBOX_THREADS``)
ends with a one-line ``cbox: error: ...`` on stderr and exit code 2, never a
traceback: commands raise one of :data:`USER_ERRORS` or a typer usage error
(``typer.BadParameter``), and :func:`harness.cli.app.main` prints it.

Outputs are checked before any rendering: :func:`check_output_file` for
``cbox render --out`` (an ``.exr`` path that is not a folder, in a writable
place) and :func:`check_output_folder` for every folder ``--out``
(:func:`out_folder_option`: a folder, or a path one can create, not a file).
"""

from __future__ import annotations

import os
import shlex
import sys
import tempfile
from pathlib import Path
from typing import Any, NoReturn

import typer
from tqdm import tqdm

from harness.adapters.registry import RendererError
from harness.adapters.settings import SettingsError
from harness.gate.config import GateConfigError
from harness.scenes.model import SceneError, one_line
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
#: OS errors about a path the user named (an output folder that is a file, no permission), reported as one
#: line; outputs are checked before a command runs, so these are for what changes during the run.
PATH_ERRORS = (PermissionError, NotADirectoryError, IsADirectoryError, FileExistsError)

SceneOpt = typer.Option(..., "--scene", "-s", help="Stored scene name (see `cbox scenes`) or path to a scene .toml file or folder.")
SppOpt = typer.Option(64, "--spp", min=1, help="Samples per pixel.")
RenderersOpt = typer.Option(None, "--renderer", "-r", help="Renderer to run (repeatable), with settings as "
                            "NAME\\[setting=value,...]; default: every registered renderer.")
SeedOpt = typer.Option(0, "--seed", min=0, help="Random seed; the same seed gives the same image.")

#: File extensions ``cbox render --out`` accepts: the image is written as OpenEXR (float32
#: linear sRGB); any other extension (.png, .jpg) is refused, not written as EXR bytes under it.
IMAGE_SUFFIXES = (".exr",)

try:  # recent typer carries its own copy of click
    from typer._click import exceptions as _click_exceptions
except ImportError:  # older typer depends on click
    from click import exceptions as _click_exceptions  # type: ignore[no-redef]

ClickException = _click_exceptions.ClickException
UsageError = _click_exceptions.UsageError
#: Raised by a group with ``no_args_is_help`` (click >= 8.2): shows the help, not an error line.
NoArgsIsHelpError: Any = getattr(_click_exceptions, "NoArgsIsHelpError", ())


def usage_message(e: Any) -> str:
    """One line for a typer/click usage error: ``--spp: Input should be ...``, naming the option."""
    param, hint = getattr(e, "param", None), getattr(e, "param_hint", None)
    if isinstance(e, _click_exceptions.MissingParameter) or not (param is not None or hint):
        return e.format_message()
    if hint is None:
        opts = list(getattr(param, "opts", None) or [])
        hint = next((o for o in opts if o.startswith("--")), opts[0] if opts else param.name)
    elif not isinstance(hint, str):
        hint = " / ".join(hint)
    return f"{hint}: {e.message}"


def _writable_folder(folder: Path, option: str, what: Path) -> None:
    """Refuse ``what`` unless ``folder``, or its nearest existing ancestor, is a folder we can create files in."""
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise typer.BadParameter(f"{what}: {existing} is not a folder", param_hint=option)
    try:  # a real probe: os.access says yes to root even where creating a file fails
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as e:
        raise typer.BadParameter(f"{what}: cannot write in {existing}: {e.strerror or e}", param_hint=option) from None


def check_output_file(path: Path, option: str = "--out", suffixes: tuple[str, ...] = IMAGE_SUFFIXES) -> None:
    """Refuse an output file path before any work: wrong extension, an existing folder, or unwritable."""
    path = Path(path)
    if path.is_dir():
        raise typer.BadParameter(f"{path}: is an existing folder; give a file name ending in "
                                 f"{' or '.join(suffixes)}", param_hint=option)
    if path.suffix.lower() not in suffixes:
        raise typer.BadParameter(f"{path}: unsupported extension {path.suffix or '(none)'!r}; the image is written "
                                 f"as OpenEXR, give a name ending in {' or '.join(suffixes)}", param_hint=option)
    _writable_folder(path.parent, option, path)


def check_output_folder(path: Path, option: str = "--out") -> None:
    """Refuse an output folder path before any work: an existing file, or a place we cannot write."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise typer.BadParameter(f"{path}: is an existing file, not a folder", param_hint=option)
    _writable_folder(path, option, path)


def out_folder_option(default: Path, help: str) -> Any:
    """The ``--out`` option of a command that writes a folder, checked (:func:`check_output_folder`) as it is parsed."""
    return typer.Option(default, "--out", "-o", help=help, callback=_checked_folder)


def _checked_folder(ctx: Any, value: Path | None) -> Path | None:
    if value is not None and not ctx.resilient_parsing:  # resilient: completion and --help, nothing runs
        check_output_folder(Path(value))
    return value


def fail(message: str, code: int = 2) -> NoReturn:
    """Print ``cbox: error: MESSAGE`` (one line) on stderr and exit with ``code``."""
    print(f"cbox: error: {one_line(message, limit=None)}", file=sys.stderr)
    sys.exit(code)


def check_environment() -> None:
    """Refuse a bad ``$CBOX_THREADS`` up front; renderers read it mid-run, where it would be a failed row."""
    if os.environ.get("CBOX_THREADS"):
        from renderers.core.schedule import default_threads

        default_threads()


def _command_line() -> str:
    return " ".join(shlex.quote(a) for a in ["cbox", *sys.argv[1:]])


def _progress(total: int, desc: str) -> tqdm:
    return tqdm(total=total, desc=desc, unit="run", file=sys.stderr, dynamic_ncols=True, leave=False)
