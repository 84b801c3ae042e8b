"""The layers as contracts (pyproject.toml's ``[tool.importlinter]``), checked by import-linter.

The core (``cornell_harness`` but its CLI) imports no report and no renderer;
the reports import no workflow; a renderer imports of the package only the API
(:mod:`cornell_harness.adapters.api`), the scene model and the renderers' own
modules (an allow-list: :mod:`tests.import_contracts`); no package or module of
``cornell_harness`` or ``cornell_harness.renderers`` is in an import cycle with a sibling.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

from tests.conftest import ROOT

LINT = "import sys; from importlinter.cli import lint_imports_command; sys.exit(lint_imports_command())"


def lint_imports(root: Path, *args: str) -> subprocess.CompletedProcess:
    """``lint-imports`` on the package under ``root/src`` (with ``root``'s pyproject.toml), uncached."""
    # root/src before the installed package; ROOT for the allow-list's contract type (tests.import_contracts).
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root / "src"), str(ROOT)])}
    return subprocess.run([sys.executable, "-c", LINT, "--no-cache", *args], cwd=root, capture_output=True,
                          text=True, timeout=120, env=env)


def copy_package(tmp_path: Path) -> Path:
    """The package's sources and pyproject.toml copied under ``tmp_path``; returns the copy's package folder."""
    for source in (ROOT / "src").rglob("*.py"):
        target = tmp_path / source.relative_to(ROOT)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(source, target)
    shutil.copyfile(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    return tmp_path / "src" / "cornell_harness"


def test_the_layer_contracts_hold():
    proc = lint_imports(ROOT)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]
    assert "0 broken" in proc.stdout


def test_a_forbidden_import_breaks_its_contract(tmp_path):
    """The check can fail: the sources copied, the core made to import a report, its contract is broken."""
    metrics = copy_package(tmp_path) / "evaluate" / "metrics.py"
    metrics.write_text(metrics.read_text() + "\nimport cornell_harness.reports.html  # noqa: E402\n")
    proc = lint_imports(tmp_path, "--contract", "core")
    assert proc.returncode == 1, proc.stdout[-4000:]
    assert "cornell_harness.evaluate.metrics -> cornell_harness.reports.html" in proc.stdout


def test_a_renderer_outside_its_allow_list_breaks_its_contract(tmp_path):
    """The renderers' allow-list can fail: a renderer importing the command renderers (a module no deny-list
    named) breaks it, and the message names the import."""
    ao = copy_package(tmp_path) / "renderers" / "ao.py"
    ao.write_text(ao.read_text() + "\nimport cornell_harness.adapters.commands  # noqa: E402\n")
    proc = lint_imports(tmp_path, "--contract", "renderers")
    assert proc.returncode == 1, proc.stdout[-4000:]
    assert "cornell_harness.renderers.ao -> cornell_harness.adapters.commands" in proc.stdout
