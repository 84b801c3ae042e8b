"""The README's two commands exist, and CI runs exactly the README's test command."""

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEMO = "scripts/setup.sh && .venv/bin/cbox demo"
TEST = "scripts/setup.sh --tests && .venv/bin/python -m pytest"


def test_readme_gives_the_two_commands():
    readme = (ROOT / "README.md").read_text()
    assert DEMO in readme and TEST in readme


def test_ci_runs_the_readme_test_command():
    assert TEST in (ROOT / ".ci" / "run").read_text()
