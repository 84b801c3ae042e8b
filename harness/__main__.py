"""``python -m harness`` is ``cbox``."""

from harness.cli.app import main

main()
