"""cornell_harness.extras: pyproject's extras and the map of renderers and options to them agree, and what needs
a missing extra says its pip line (the renderers' listing, --workers). A missing module is faked here (the
core install itself is tests/test_packaging.py's, slow)."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import tomllib

import pytest

from tests.conftest import ROOT, cbox_in_process
from cornell_harness import extras
from cornell_harness.adapters.registry import resolve
from cornell_harness.workflows.executor import open_executor

PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def _hide(monkeypatch, *modules: str) -> None:
    """Make ``modules`` look uninstalled to extras.missing_modules (and to nothing else)."""
    real = importlib.util.find_spec
    monkeypatch.setattr(extras.importlib.util, "find_spec", lambda name, *a: None if name in modules else real(name, *a))


def test_every_extra_is_pyprojects_and_all_holds_them_all():
    optional = PYPROJECT["project"]["optional-dependencies"]
    listed = [extra for extra in extras.MODULES if extra not in extras.COMMANDS]
    assert set(listed) | {"all", "test", "docs"} == set(optional)
    assert optional["all"] == [f"cornell-harness[{','.join(listed)}]"]
    assert not any(dep.startswith(("numba", "mitsuba", "pyluxcore", "dask", "embreex", "pyoidn", "pyrender"))
                   for dep in PYPROJECT["project"]["dependencies"])


def test_every_registered_renderer_names_its_extras():
    registered = PYPROJECT["project"]["entry-points"]["cbox.renderers"]
    assert set(extras.RENDERERS) == set(registered)
    assert all(set(needs) <= set(extras.MODULES) for needs in extras.RENDERERS.values())


def test_a_renderer_whose_extra_is_missing_is_unavailable_with_its_pip_line(monkeypatch):
    _hide(monkeypatch, "pyluxcore", "pyoidn")
    luxcore, denoised, mitsuba = resolve(["luxcore", "mitsuba+oidn", "mitsuba"])
    assert not luxcore.available and luxcore.reason == "pyluxcore not installed: pip install 'cornell-harness[luxcore]'"
    assert not denoised.available and denoised.reason.endswith("pip install 'cornell-harness[oidn]'")
    assert "cornell-harness[" not in (mitsuba.reason or "")  # its own extra is there


def test_cycles_without_bpy_names_the_command_that_installs_it(monkeypatch):
    """bpy is no pyproject extra (it pins numpy<2): its line is its own pip command, without dependencies."""
    from cornell_harness.renderers.cycles import Cycles

    _hide(monkeypatch, "bpy")
    assert extras.renderer_problem("cycles") == "bpy not installed: pip install --no-deps 'bpy==5.0.1'"
    assert Cycles().unavailable_reason() == extras.renderer_problem("cycles")
    assert extras.install_line(["luxcore", "cycles"]) == ("pip install 'cornell-harness[luxcore]' && "
                                                          "pip install --no-deps 'bpy==5.0.1'")


def test_cbox_renderers_lists_it_so(monkeypatch, capsys):
    _hide(monkeypatch, "numba")
    code, out, _ = cbox_in_process(capsys, "renderers")
    lines = {line.split()[0]: line for line in out.splitlines() if line and not line[0].isspace()}
    assert code == 0
    assert lines["sppm"].split()[1:] == ["unavailable", "numba", "not", "installed:", "pip", "install",
                                         "'cornell-harness[ours]'"]
    assert "cornell-harness[" not in lines["luxcore"]  # numba is not its extra's


@pytest.mark.parametrize("option", ["--workers", "--scheduler"])
def test_a_cluster_without_dask_is_one_line_naming_the_extra(monkeypatch, capsys, tmp_path, option):
    _hide(monkeypatch, "distributed")
    with pytest.raises(extras.MissingExtraError, match=r"pip install 'cornell-harness\[dask\]'$"):
        with open_executor(**({"workers": 2} if option == "--workers" else {"scheduler": "tcp://127.0.0.1:1"})):
            pass
    value = "2" if option == "--workers" else "tcp://127.0.0.1:1"
    code, _, err = cbox_in_process(capsys, "gate", option, value, "--out", str(tmp_path / "out"))
    assert code == 2
    assert err.splitlines() == [f"cbox: error: {option} needs the [dask] extra (distributed not installed): "
                                "pip install 'cornell-harness[dask]'"]


def test_cbox_luxcore_without_pyluxcore_names_its_extra(tmp_path):
    (tmp_path / "scene.cfg").write_text("")
    hidden = ("import sys; sys.modules['pyluxcore'] = None; from cornell_harness.renderers.luxcore_cli import main; "
              f"main([{str(tmp_path / 'scene.cfg')!r}, '--out', 'x.exr', '--spp', '1', '--seed', '0'])")
    proc = subprocess.run([sys.executable, "-c", hidden], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 2
    (line,) = proc.stderr.splitlines()  # one line, the import's error and the pip line, no traceback
    assert line.startswith("cbox-luxcore: ") and "pyluxcore" in line
    assert line.endswith(": pip install 'cornell-harness[luxcore]'")


def test_the_demo_without_any_renderer_stops_with_the_all_line(monkeypatch, capsys, tmp_path):
    """In a core install every renderer of ours is unavailable: the demo says how to get them instead of writing
    an empty report; with one extra there it runs (not tried here: the demo's own tests run it)."""
    _hide(monkeypatch, *[m for modules in extras.MODULES.values() for m in modules])
    code, out, err = cbox_in_process(capsys, "demo", "--out", str(tmp_path / "out"))
    assert code == 2 and not (tmp_path / "out" / "report.html").exists()
    assert err.splitlines() == ["cbox: error: cbox demo runs the harness's own renderers and Mitsuba, and none is "
                                "installed here: pip install 'cornell-harness[all]'"]
    monkeypatch.undo()
    _hide(monkeypatch, "pyluxcore")
    extras.require_a_renderer("cbox demo")  # one extra missing is no reason to stop
