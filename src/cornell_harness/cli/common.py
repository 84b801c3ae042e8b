"""What every ``cbox`` command shares: the typer apps, common options, user errors.

Bad input (a malformed scene, an unknown renderer or setting, a stale
reference, a bad option value, an unusable ``--out``, a bad ``$CBOX_THREADS``,
a bad renderers file) ends with a one-line ``cbox: error: ...`` on stderr
and exit code 2, never a traceback: commands raise one of :data:`USER_ERRORS` or a typer usage error
(``typer.BadParameter``), and :func:`cornell_harness.cli.app.main` prints it.

Outputs are checked before any rendering: :func:`check_output_file` for
``cbox render --out`` (an ``.exr`` path that is not a folder, in a writable
place) and :func:`check_output_folder` for every folder ``--out``
(:func:`out_folder_option`: a folder, or a path one can create, not a file).

What a command says besides its results (verbosity, remarks, progress) is :mod:`cornell_harness.cli.output`'s;
errors close any progress bar first, so they start a line.
"""

from __future__ import annotations

import contextlib
import copy
import functools
import json
import math
import os
import re
import shlex
import sys
import tempfile
from pathlib import Path
from typing import Any, Iterator, NoReturn

import numpy as np
import typer

from cornell_harness.adapters.renderers_file import RenderersFileError
from cornell_harness.adapters.registry import RendererError
from cornell_harness.adapters.settings import SettingsError
from cornell_harness.durations import parse_duration
from cornell_harness.cli.output import QuietOpt, VerboseOpt, close_progress_bars, info
from cornell_harness.extras import MissingExtraError
from cornell_harness.gate.config import GateConfigError
from cornell_harness.scenes.model import SceneError, one_line
from cornell_harness.store.experiments import ExperimentError
from cornell_harness.store.exr import ImageFileError
from cornell_harness.store.references import ReferenceError
from cornell_harness.suggest import did_you_mean
from cornell_harness.workflows.executor import ExecutorError

#: The harness's reference renderer: references are built with it, and the stress suite's variant references.
REFERENCE_RENDERER = "mitsuba"
#: The exit code of a check that is neither shown to hold nor to fail (``cbox gate`` with a margin, ``cbox
#: reference verify``): an interval straddles its margin, and more samples would resolve it.
EXIT_INCONCLUSIVE = 3

app = typer.Typer(
    help="Validation harness for renderers on the Cornell box: render, score against a trusted reference, report."
         "\n\nLong commands show progress as a bar when stderr is a terminal, else (a CI log) as a line when the "
         "work starts and one plain line per finished run, without carriage returns, so TQDM_DISABLE is not "
         "needed; -q hides it. Ctrl-C ends a command with exit code 130 and a line saying what was kept.",
    no_args_is_help=True,
    add_completion=True,  # --install-completion / --show-completion; typer builds them without slow imports
    pretty_exceptions_enable=False,
)
reference_app = typer.Typer(help="Build, inspect and verify stored reference images.", no_args_is_help=True)
app.add_typer(reference_app, name="reference")

USER_ERRORS = (SceneError, ReferenceError, RendererError, RenderersFileError, ImageFileError, ExperimentError,
               GateConfigError, SettingsError, ExecutorError, MissingExtraError)
#: OS errors about a path the user named (an output folder that is a file, no permission), reported as one
#: line; outputs are checked before a command runs, so these are for what changes during the run.
PATH_ERRORS = (PermissionError, NotADirectoryError, IsADirectoryError, FileExistsError)

SceneOpt = typer.Option(..., "--scene", "-s", help="Stored scene name (see `cbox scenes`) or path to a scene .toml file or folder.")
SppOpt = typer.Option(64, "--spp", min=1, help="Samples per pixel.")
RenderersOpt = typer.Option(None, "--renderer", "-r", help="Renderer to run (repeatable), with settings as "
                            "NAME\\[setting=value,...]; default: every registered renderer (and every one --renderers "
                            "declares).")


def _use_renderer_files(ctx: Any, value: list[Path] | None) -> list[Path] | None:
    if value and not ctx.resilient_parsing:  # resilient: completion and --help, nothing runs
        from cornell_harness.adapters.registry import use_renderer_files

        use_renderer_files(value)  # read and checked now: a misspelt placeholder fails before anything runs
    return value


#: The help of ``--renderers`` (gate's takes the value itself, to report a bad file in its CI files).
RENDERER_FILES_HELP = ("Renderers file (TOML, repeatable) declaring command-line renderers as [renderer.NAME] "
                       "tables (see examples/renderers.toml): their names can then be given to -r; also "
                       "$CBOX_RENDERERS (paths separated by ':').")
RendererFilesOpt = typer.Option(None, "--renderers", metavar="FILE", callback=_use_renderer_files,
                                expose_value=False, help=RENDERER_FILES_HELP)
SeedOpt = typer.Option(0, "--seed", min=0, help="Random seed; the same seed gives the same image.")


def time_limit_seconds(value: str | None) -> float | None:
    """--time-limit's seconds (None without it); a bad duration is a usage error naming the option."""
    if value is None:
        return None
    try:
        return parse_duration(value, "time limit")
    except ValueError as e:
        raise typer.BadParameter(str(e)) from None


TIME_LIMIT_HELP = ("End a render that runs longer than this (e.g. 90s, 10m), with every process it started, and "
                   "record it as failed, saying so; each render then runs in a child process. Default: none, but "
                   "a command-line renderer's program has its own limit (its renderers file's time_limit, else "
                   "60 s plus 10 microseconds per sample).")
TimeLimitOpt = typer.Option(None, "--time-limit", metavar="DURATION", callback=time_limit_seconds, help=TIME_LIMIT_HELP)
TitleOpt = typer.Option(None, "--title", help="Title of the report (default: \"Renderer comparison — SCENE\").")
SetOpt = typer.Option(None, "--set", metavar="KEY=VALUE", help=(
    "Override a value of the scene file (repeatable), by its TOML path: --set render.max_depth=3 --set "
    "camera.resolution=64,64 (a comma list is an array). The result is a derived scene, named after its "
    "overrides, with its own content hash and its own reference (cbox reference build ... --set ...)."))
HomeOpt = typer.Option(None, "--home", metavar="DIR", help=(
    "The user store: where what is built or recorded for the stored scenes is kept (references of their --set "
    "variants, verdicts of cbox reference verify), the package's own files staying read-only; a scene file of "
    "yours keeps these beside it. Default: $CBOX_HOME, else the platform's user data folder (cbox --version "
    "shows it)."))

# Where a command's independent units of work run (cornell_harness.workflows.executor): here by default.
WorkersOpt = typer.Option(None, "--workers", min=1, metavar="N",
                          help="Run the work on a Dask LocalCluster of N worker processes on this machine, each "
                               "one task at a time on its share of the cores (CBOX_THREADS). Default: in this "
                               "process.")
SchedulerOpt = typer.Option(None, "--scheduler", metavar="tcp://HOST:PORT",
                            help="Run the work on the existing Dask cluster of this scheduler (the same dask "
                                 "version and cbox on every worker; no shared filesystem needed).")
DashboardOpt = typer.Option(None, "--dashboard", metavar="ADDRESS",
                            help="With --workers: serve Dask's dashboard at ADDRESS (e.g. :8787); none by default.")


_SCHEDULER_ADDRESS = re.compile(r"(tcp|tls|ws|wss)://(\[[0-9A-Fa-f:.]+\]|[^\s/:\[\]]+)(:\d+)?/?")


@contextlib.contextmanager
def executor_for(workers: int | None, scheduler: str | None, dashboard: str | None) -> Iterator[Any]:
    """The backend of ``--workers`` / ``--scheduler`` / ``--dashboard`` (:func:`open_executor`), options checked."""
    from cornell_harness.workflows.executor import open_executor

    if workers is not None and scheduler is not None:
        raise typer.BadParameter("give --workers N (a cluster on this machine) or --scheduler (an existing one), "
                                 "not both", param_hint="--scheduler")
    if dashboard is not None and workers is None:
        raise typer.BadParameter("the dashboard of an existing cluster is its scheduler's; --dashboard goes "
                                 "with --workers", param_hint="--dashboard")
    if scheduler is not None and not _SCHEDULER_ADDRESS.fullmatch(scheduler):
        raise typer.BadParameter(f"{scheduler!r} is not a scheduler address; give tcp://HOST:PORT",
                                 param_hint="--scheduler")
    with open_executor(workers, scheduler, dashboard) as executor:
        if executor.name != "in-process":
            info(f"running on {executor.name} ({executor.slots} worker thread{'s' if executor.slots > 1 else ''})")
        yield executor


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


_NO_SUCH_COMMAND = re.compile(r"No such command (?P<name>.+?)\.(?: Did you mean .*)?$")


def usage_message(e: Any) -> str:
    """One line for a typer/click usage error: ``--spp: Input should be ...``, naming the option; a misspelt
    option or sub-command gets its did-you-mean (:mod:`cornell_harness.suggest`, as every other misspelt name)."""
    ctx = getattr(e, "ctx", None)
    if isinstance(e, _click_exceptions.NoSuchOption) and ctx is not None:
        known = [o for p in ctx.command.get_params(ctx) for o in (*p.opts, *p.secondary_opts)]
        return f"no such option: {e.option_name}" + did_you_mean(e.option_name, known)
    if (m := _NO_SUCH_COMMAND.match(e.message)) and ctx is not None and hasattr(ctx.command, "list_commands"):
        name = m.group("name").strip("'\"")
        commands = ctx.command.list_commands(ctx)
        return f"no such command {name!r}" + did_you_mean(name, commands) + f"; commands: {', '.join(commands)}"
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
    """Print ``cbox: error: MESSAGE`` (one line, on a line of its own: any progress bar is closed first) on
    stderr and exit with ``code``."""
    close_progress_bars()
    print(f"cbox: error: {one_line(message, limit=None)}", file=sys.stderr)
    sys.exit(code)


@contextlib.contextmanager
def render_failed(name: str) -> Iterator[None]:
    """A render of renderer ``name`` that failed in this process: one line, ``renderer 'X' failed: why``, exit 1.

    The harness's own render errors (past its time limit, an unusable result, a sandboxed child's failure) say
    why in their message; any other exception is the renderer's own, named by its type. A user's error
    (:data:`USER_ERRORS`) and an interrupt go on to their own handlers.
    """
    from cornell_harness.workflows.render import RenderError, RenderTimeout

    try:
        yield
    except USER_ERRORS:
        raise
    except (RenderTimeout, RenderError) as e:
        fail(f"renderer {name!r} failed: {e}", 1)
    except Exception as e:  # the renderer's failure, not a bug of ours
        fail(f"renderer {name!r} failed: {type(e).__name__}: {e}", 1)


def check_environment() -> None:
    """Refuse a bad ``$CBOX_THREADS`` up front; renderers read it mid-run, where it would be a failed row."""
    if os.environ.get("CBOX_THREADS"):
        from cornell_harness.adapters.api import default_threads  # not at the top: `cbox --help` loads no NumPy

        default_threads()


def command_line() -> str:
    return " ".join(shlex.quote(a) for a in ["cbox", *sys.argv[1:]])


#: The versions that decide what a run computes, for ``cbox --version`` (read from package metadata:
#: importing Mitsuba or Numba to ask would take seconds).
KEY_DISTRIBUTIONS = (("Mitsuba", "mitsuba"), ("NumPy", "numpy"), ("Embree", "embreex"), ("Numba", "numba"),
                     ("typer", "typer"))


def version_line() -> str:
    """``cbox 0.1.0 (Python 3.11.9, Mitsuba 3.9.1, NumPy 2.2.6, ...)``: one line."""
    import platform
    from importlib.metadata import PackageNotFoundError, version

    def of(dist: str) -> str:
        try:
            return version(dist)
        except PackageNotFoundError:
            return "not installed"

    keys = ", ".join(f"{name} {of(dist)}" for name, dist in KEY_DISTRIBUTIONS)
    return f"cbox {of('cornell-harness')} (Python {platform.python_version()}, {keys})"


def home_line(home: Path | None = None) -> str:
    """``user store: DIR (from $CBOX_HOME)``: where what users build or record goes (cornell_harness.store.home)."""
    from cornell_harness.store.home import home_source, user_home

    return f"user store: {user_home(home)} (from {home_source(home)})"


def _show_version(ctx: typer.Context, value: bool) -> None:
    if value and not ctx.resilient_parsing:
        typer.echo(version_line())
        typer.echo(home_line())
        raise typer.Exit()


@app.callback()
def _everywhere(
    quiet: bool = QuietOpt,
    verbose: bool = VerboseOpt,
    version: bool = typer.Option(False, "--version", callback=_show_version, is_eager=True, expose_value=False,
                                 help="Print the version of cbox and of the packages that decide its results, then "
                                      "the user store's folder."),
) -> None:
    """The options before any command: ``cbox -q converge ...``, ``cbox --version``."""


@functools.cache  # built once per process: ~60 ms, paid again by every in-process call of main() otherwise
def command_tree() -> Any:
    """The app as a click command, every sub-command also taking the app's ``--quiet/-q`` and ``--verbose/-v``.

    Copied here rather than declared in each command's signature: one definition, every command (those
    added later too) takes them, and ``cbox converge -q`` works as well as ``cbox -q converge``. A short
    flag a command already uses for something else stays that (``cbox stress -v`` is ``--variant``).
    """
    root = typer.main.get_command(app)
    shared = [p for p in root.params if p.name in ("quiet", "verbose")]

    def visit(group: Any) -> None:
        for command in group.commands.values():
            if hasattr(command, "commands"):
                visit(command)
            taken = {o for p in command.params for o in (*p.opts, *p.secondary_opts)}
            for p in shared:
                if (opts := [o for o in p.opts if o not in taken]) and p.name not in {q.name for q in command.params}:
                    own = copy.copy(p)
                    own.opts = opts
                    command.params.append(own)

    visit(root)
    return root


def print_json(value: Any) -> None:
    """``value`` as strict JSON on stdout, the ``--json`` of a command: nested objects, never JSON inside a string;
    NaN and infinities (a PSNR of identical images) as null."""
    typer.echo(json.dumps(_strict(value), indent=1, allow_nan=False))


def _strict(value: Any) -> Any:
    if isinstance(value, np.generic):  # a value read back from a results table
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {str(k): _strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    return value
