"""``cbox``: the command-line interface, the only layer that imports ``reports/`` and names concrete renderers.

Each command lives in the module named for what it does; importing them
registers them on the one typer app (:data:`harness.cli.common.app`), in the
order ``cbox --help`` lists them.
"""

from __future__ import annotations

import sys

# Importing a command module registers its commands, in this order in `cbox --help` (so not sorted).
from harness.cli import listing, run, compare_image, experiment, gate, stress, reference, export  # isort: skip
from harness.cli.common import (PATH_ERRORS, USER_ERRORS, ClickException, NoArgsIsHelpError, UsageError, Verbosity,
                                check_environment, close_progress_bars, command_tree, fail, set_verbosity,
                                usage_message)


#: The command modules, registered on the app by their import above.
COMMAND_MODULES = (listing, run, compare_image, experiment, gate, stress, reference, export)


def main(args: list[str] | None = None) -> None:
    """Console entry point: bad input of any kind becomes one line on stderr and exit code 2.

    Typer runs in non-standalone mode so that its usage errors (``--spp 0``)
    come here instead of being drawn as a multi-line box; ``--help`` and a
    command's own exit code pass through unchanged.
    """
    set_verbosity(Verbosity.NORMAL)  # until --quiet or --verbose says otherwise (tests call main() again and again)
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
    except KeyboardInterrupt:
        close_progress_bars()
        print("cbox: interrupted", file=sys.stderr)
        sys.exit(130)
    sys.exit(rv if isinstance(rv, int) else 0)
