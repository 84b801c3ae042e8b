"""``cbox``: the command-line interface, the only layer that imports ``src/cornell_harness/reports/`` and names concrete renderers.

Each command lives in the module named for what it does; importing them
registers them on the one typer app (:data:`cornell_harness.cli.common.app`), in the
order ``cbox --help`` lists them.

A command parses its options, calls a workflow (:mod:`cornell_harness.workflows`) and prints what it
returns. Its function is as long as its options' declarations, which typer reads from the signature (and its
docstring is the command's ``--help``, so the reason is said here, once); the body stays under about 40 lines.
"""

from __future__ import annotations

import sys

from cornell_harness.cli.allocator import keep_freed_memory
from cornell_harness.cli import interrupt

with interrupt.starting():  # a Ctrl-C during these imports (seconds): one line and exit 130, no traceback
    from cornell_harness.adapters.registry import use_renderer_files
    from cornell_harness.workflows.foreign_cpu import mark_command_root
    # Importing a command module registers its commands, in this order in `cbox --help` (so not sorted).
    from cornell_harness.cli import listing, run, compare_image, experiment, gate, stress, reference, export, sequence  # isort: skip
    from cornell_harness.cli.common import (PATH_ERRORS, USER_ERRORS, ClickException, NoArgsIsHelpError, UsageError,
                                    check_environment, command_tree, fail, usage_message)
    from cornell_harness.cli.output import Verbosity, close_progress_bars, set_verbosity


#: The command modules, registered on the app by their import above.
COMMAND_MODULES = (listing, run, compare_image, experiment, gate, stress, reference, export, sequence)


def main(args: list[str] | None = None) -> None:
    """Console entry point: bad input of any kind becomes one line on stderr and exit code 2.

    Typer runs in non-standalone mode so that its usage errors (``--spp 0``)
    come here instead of being drawn as a multi-line box; ``--help`` and a
    command's own exit code pass through unchanged. A signal that ends it
    (Ctrl-C, SIGTERM, SIGHUP) ends every process it started, and is one line
    saying what was kept, and exit code 128 + its number: 130, 143, 129
    (:mod:`cornell_harness.cli.interrupt`).
    """
    with interrupt.handling():
        _main(args)


def _main(args: list[str] | None) -> None:
    set_verbosity(Verbosity.NORMAL)  # until --quiet or --verbose says otherwise (tests call main() again and again)
    use_renderer_files(())  # until --renderers gives some (as above)
    cut = False  # a KeyboardInterrupt reached here
    keep_freed_memory()  # a program's choice, made here rather than in a library a user may import
    mark_command_root()  # every process this command starts is its own work, not the machine's load on it
    try:
        check_environment()
        rv = command_tree().main(args=args, prog_name="cbox", standalone_mode=False)
    except NoArgsIsHelpError as e:  # `cbox` or `cbox reference` alone: the help, as typer shows it
        e.show()
        sys.exit(e.exit_code)
    except UsageError as e:
        fail(usage_message(e), e.exit_code)
    except ClickException as e:
        fail(e.format_message(), e.exit_code)
    except USER_ERRORS as e:
        fail(str(e))
    except PATH_ERRORS as e:  # an output path that went bad during the run (checked beforehand where possible)
        fail(f"{e.filename}: {e.strerror}" if e.filename else str(e))
    except KeyboardInterrupt:  # outside typer's own handling (which returns 130): before or after the command
        cut = True
    except Exception:
        if not interrupt.fired():
            raise
        cut = True  # raised by the unwinding after a Ctrl-C (a Dask client cut off mid-call): the Ctrl-C is the news
    if cut or interrupt.fired():
        close_progress_bars()
        interrupt.exit_interrupted()
    sys.exit(rv if isinstance(rv, int) else 0)
