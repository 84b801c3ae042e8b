"""``cbox``: the command-line interface, the only layer that imports ``reports/`` and names concrete renderers.

Each command lives in the module named for what it does; importing them
registers them on the one typer app (:data:`harness.cli.common.app`), in the
order ``cbox --help`` lists them.
"""

from __future__ import annotations

import sys

# Importing a command module registers its commands, in this order in `cbox --help`.
from harness.cli import listing, run, experiment, gate, stress, reference  # noqa: F401, I001
from harness.cli.common import USER_ERRORS, app


def main() -> None:
    """Console entry point: user errors become one line on stderr and exit code 2."""
    try:
        app()
    except USER_ERRORS as e:
        print(f"cbox: error: {e}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        print("cbox: interrupted", file=sys.stderr)
        sys.exit(130)
