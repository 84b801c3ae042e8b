"""What the CLI's tests share."""

import pytest

from cornell_harness.cli import output


@pytest.fixture(autouse=True)
def _normal_verbosity():
    """``cbox -q`` in this process sets the verbosity for the process: back to normal after each test."""
    yield
    output.set_verbosity(output.Verbosity.NORMAL)
