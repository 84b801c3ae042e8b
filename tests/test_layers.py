"""The layers as contracts (pyproject.toml's ``[tool.importlinter]``), checked by import-linter.

The core (``harness`` but its CLI) imports no report and no renderer; the
reports import no workflow; a renderer imports of the harness only the API
(:mod:`harness.adapters.api`) and the scene model; no package or module of
``harness``, ``reports`` or ``renderers`` is in an import cycle with a sibling.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from tests.conftest import ROOT

PACKAGES = ("harness", "reports", "renderers")
LINT = "import sys; from importlinter.cli import lint_imports_command; sys.exit(lint_imports_command())"


def lint_imports(root: Path, *args: str) -> subprocess.CompletedProcess:
    """``lint-imports`` on the packages under ``root`` (its own pyproject.toml), uncached."""
    return subprocess.run([sys.executable, "-c", LINT, "--no-cache", *args], cwd=root, capture_output=True,
                          text=True, timeout=120)


def test_the_layer_contracts_hold():
    proc = lint_imports(ROOT)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]
    assert "0 broken" in proc.stdout


def test_a_forbidden_import_breaks_its_contract(tmp_path):
    """The check can fail: the sources copied, the core made to import a report, its contract is broken."""
    for package in PACKAGES:
        for source in (ROOT / package).rglob("*.py"):
            target = tmp_path / source.relative_to(ROOT)
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(source, target)
    shutil.copyfile(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    metrics = tmp_path / "harness" / "evaluate" / "metrics.py"
    metrics.write_text(metrics.read_text() + "\nimport reports.html  # noqa: E402\n")
    proc = lint_imports(tmp_path, "--contract", "core")
    assert proc.returncode == 1, proc.stdout[-4000:]
    assert "harness.evaluate.metrics -> reports.html" in proc.stdout
