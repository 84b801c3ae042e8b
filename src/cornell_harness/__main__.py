"""``python -m cornell_harness`` is ``cbox``."""

from cornell_harness.cli.app import main

main()
