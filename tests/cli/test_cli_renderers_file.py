"""Command-line renderers on the command line: ``--renderers FILE`` on the commands that take ``-r``, errors
before anything runs, failures recorded, and ``mitsuba-cli`` through ``cbox gate`` (the fake programs and the
fake format are tests/adapters/test_commands.py's)."""

from __future__ import annotations

import importlib
import json
import textwrap

import pytest

from tests.conftest import cbox_in_process as cbox
from cornell_harness.adapters import registry
from cornell_harness.scenes import export
from tests.adapters import test_commands as fakes
from tests.adapters.test_commands import EXAMPLES, renderers_file, runs


@pytest.fixture
def fake_format(monkeypatch):
    monkeypatch.setitem(export.FORMATS, fakes.NAME, fakes.__name__)


@pytest.fixture(autouse=True)
def no_files():
    """A test's --renderers and $CBOX_RENDERERS end with it."""
    yield
    registry.use_renderer_files(())


def test_a_misspelt_placeholder_stops_the_command_before_anything_runs(tmp_path, fake_format, capsys):
    path = renderers_file(tmp_path, command_extra=("--seed={sede}",))
    code, out, err = cbox(capsys, "compare", "--scene", "furnace", "--renderers", str(path), "-r", "fake-cli",
                          "--spp", "1", "--out", str(tmp_path / "out"))
    assert code == 2 and out == ""
    assert err == (f"cbox: error: {path}: renderer.fake-cli.command[11]: unknown placeholder {{sede}} (did you "
                   "mean {seed}?); placeholders: {scene}, {out}, {spp}, {seed}, {width}, {height}, {threads}\n")
    assert runs(tmp_path) == [] and not (tmp_path / "out").exists()


def test_cbox_renderers_lists_the_declared_ones(tmp_path, fake_format, capsys):
    code, out, _ = cbox(capsys, "renderers", "--renderers", str(renderers_file(tmp_path)), "--json")
    assert code == 0
    (mine,) = [r for r in json.loads(out) if r["name"] == "fake-cli"]
    assert mine["available"] and mine["computes"] == ["radiance"] and "fake-cli.toml#fake-cli" in mine["version"]
    code, out, _ = cbox(capsys, "renderers", "--json")  # the next command forgets the file
    assert "fake-cli" not in [r["name"] for r in json.loads(out)]


def test_compare_records_the_failure_with_stderr(tmp_path, fake_format, capsys):
    path = renderers_file(tmp_path, "fail")
    code, out, _ = cbox(capsys, "compare", "--scene", "furnace", "--renderers", str(path), "-r", "fake-cli",
                        "--spp", "2", "--out", str(tmp_path / "out"))
    assert code == 1
    assert "fake-cli: failed: CommandFailed: fake-cli at 2 spp: exited with code 3; stderr: loading the scene | " \
           "fatal: no GPU here" in out

def test_a_bad_renderers_file_is_a_config_error_in_the_gates_ci_files(tmp_path, fake_format, capsys):
    path = renderers_file(tmp_path, extra="colour = 1\n")
    code, _, err = cbox(capsys, "gate", "--renderers", str(path), "--out", str(tmp_path / "out"))
    assert code == 2 and "renderer.fake-cli.colour: unknown key" in err
    assert "renderer.fake-cli.colour: unknown key" in (tmp_path / "out" / "gate-junit.xml").read_text()


def test_the_environment_variable_declares_them_too(tmp_path, fake_format, capsys, monkeypatch):
    monkeypatch.setenv(registry.RENDERERS_VARIABLE, str(renderers_file(tmp_path)))
    code, out, _ = cbox(capsys, "compare", "--scene", "furnace", "-r", "fake-cli", "--spp", "3", "--seed", "2",
                        "--json", "--out", str(tmp_path / "out"))
    rec = json.loads(out.splitlines()[0])
    assert code == 0 and rec["renderer"] == "fake-cli" and rec["status"] == "ok" and runs(tmp_path) == [(3, 2)]


def _has(module: str) -> bool:
    try:
        importlib.import_module(module)
        return True
    except ImportError:
        return False


GATE = textwrap.dedent("""\
    alpha = 0.01
    [[expect]]
    scene = "{scene}"
    renderer = "mitsuba-cli"
    spp = 256
    seed = 0
    unbiased = true
    tile = {tile}
    time_limit = "5m"
""")


@pytest.mark.skipif(not _has("cornell_harness.scenes.export.mitsuba"), reason="the Mitsuba XML exporter "
                    "(cornell_harness.scenes.export.mitsuba) is not here yet")
@pytest.mark.parametrize("scene, tile", [
    "furnace 8".split(),
    pytest.param("cornell-box", "16", marks=pytest.mark.slow),  # gate.toml's expectation for mitsuba
])
def test_mitsuba_cli_passes_the_gate_that_mitsuba_passes(tmp_path, capsys, scene, tile):
    config = tmp_path / "gate.toml"
    config.write_text(GATE.format(scene=scene, tile=tile))
    code, out, err = cbox(capsys, "gate", "--renderers", str(EXAMPLES), "--config", str(config),
                          "--out", str(tmp_path / "out"))
    assert code == 0, out + err
    assert "PASS  " in out and "agreement" in out and "gate passed" in out


@pytest.mark.slow  # ~18 s on 2 cores, most of it the cluster's start; entry_for(spec) is tested by default
@pytest.mark.skipif(fakes._sandbox_format() is None, reason="no export format module yet (cornell_harness.scenes.export.*): "
                    "a Dask worker must export the scene for real")
def test_converge_on_dask_workers_runs_the_declared_program_by_its_spec(tmp_path, capsys):
    """The workers get the renderer's spec alone (no --renderers there): each cell a run of the program per spp."""
    import pandas as pd

    pytest.importorskip("distributed")
    path = renderers_file(tmp_path, scene_format=fakes._sandbox_format())
    code, _, err = cbox(capsys, "converge", "--scene", "furnace", "--renderers", str(path), "-r", "fake-cli",
                        "--spp", "1,2", "--seeds", "2", "--workers", "2", "--out", str(tmp_path / "out"))
    assert code == 0, err
    table = pd.read_parquet(tmp_path / "out" / "results.parquet")
    assert (table["status"] == "ok").all() and sorted(zip(table["spp"], table["seed"])) == sorted(runs(tmp_path))
    assert sorted(runs(tmp_path)) == [(1, 0), (1, 1), (2, 0), (2, 1)]
