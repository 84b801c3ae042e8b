"""``python -m harness`` is ``cbox``."""

from harness.cli import main

main()
