"""Time limits: every command that renders takes ``--time-limit``, a command-line renderer's program has one of
its own (its renderers file's ``time_limit``, else scaled from the samples), and a render past its limit is
ended, with what it started, and recorded as a failure that says so. No temporary folder is left behind, on
success, failure or a kill.

The hanging renderers wait for good (a program sleeping 600 s, with a child of its own; ``Slow`` sleeps 120 s):
a test ends only because the limit ended them. No verdict rests on wall time; the limits are short so that the
tests are.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import pytest

from cornell_harness.adapters.renderers_file import DEFAULT_LIMIT_PER_SAMPLE_S, DEFAULT_LIMIT_START_S, read_file
from tests.adapters.test_commands import renderers_file
from tests.conftest import cbox_in_process as cbox
from tests.live_processes import alive, logged_pids


@pytest.fixture
def tmpdir_watched(tmp_path, monkeypatch):
    """A fresh ``$TMPDIR`` (this process's and its children's); after the test, no ``cbox-*`` is left in it."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmp))
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    yield tmp
    assert sorted(p.name for p in tmp.iterdir() if p.name.startswith("cbox-")) == []


def _hanging(tmp_path: Path, extra: str = "") -> Path:
    """The fake program that starts a child and hangs, declared with the mitsuba format (a real one, which the
    sandbox's child process can write too)."""
    return renderers_file(tmp_path, "spawn-hang", scene_format="mitsuba", extra=extra)


@pytest.mark.parametrize("command", ["compare", "converge"])
def test_time_limit_ends_a_hanging_program_and_records_the_failure(tmp_path, capsys, tmpdir_watched, command):
    files = ["--renderers", str(_hanging(tmp_path))]
    if command == "compare":
        argv = ["compare", "-s", "furnace", *files, "-r", "fake-cli", "--spp", "4", "--json"]
    else:
        argv = ["converge", "-s", "furnace", *files, "-r", "fake-cli", "--spp", "1,4", "--seeds", "1", "--json"]
    code, out, _ = cbox(capsys, *argv, "--time-limit", "3s", "--out", str(tmp_path / "out"))
    assert code == 1
    records = [json.loads(line) for line in out.splitlines()] if command == "compare" else json.loads(out)["runs"]
    (rec,) = records
    assert rec["status"] == "failed" and rec["reason"].startswith("killed at its time limit of 3 s"), rec
    assert rec["time_s"] >= 3.0
    pids = logged_pids(tmp_path / "runs.log")
    assert len(pids) == 2 and not any(map(alive, pids))  # the program and its child


def test_the_programs_own_limit_from_its_renderers_file(tmp_path, capsys, tmpdir_watched):
    """Without --time-limit, in this process: the renderers file's time_limit ends the program, and the failure
    says which limit and where it is set."""
    files = ["--renderers", str(_hanging(tmp_path, 'time_limit = "1s"\n'))]
    code, out, _ = cbox(capsys, "compare", "-s", "furnace", *files, "-r", "fake-cli", "--spp", "4", "--json",
                        "--out", str(tmp_path / "out"))
    assert code == 1
    (rec,) = [json.loads(line) for line in out.splitlines()]
    assert "fake-cli at 4 spp: killed at its time limit of 1 s" in rec["reason"], rec
    assert "the renderers file's time_limit sets it" in rec["reason"]
    assert not any(map(alive, logged_pids(tmp_path / "runs.log")))


def test_the_default_limit_grows_with_the_samples(tmp_path):
    (declared,) = read_file(renderers_file(tmp_path, scene_format="mitsuba")).values()
    assert declared.time_limit_s is None
    assert declared.run_time_limit_s(1, 8, 6) == DEFAULT_LIMIT_START_S + 48 * DEFAULT_LIMIT_PER_SAMPLE_S
    assert declared.run_time_limit_s(1024, 256, 256) == pytest.approx(60 + 671.09, abs=0.01)
    (fixed,) = read_file(renderers_file(tmp_path, scene_format="mitsuba", extra='time_limit = "90s"\n')).values()
    assert fixed.run_time_limit_s(1024, 256, 256) == 90.0


@pytest.mark.parametrize("value, message", [('"soon"', "expected e.g. 10s, 2m, 500ms"),
                                            ('"0s"', "must be positive"), ("90", 'expected a duration, e.g. "90s"')])
def test_a_bad_time_limit_in_a_renderers_file_is_one_line(tmp_path, capsys, value, message):
    path = renderers_file(tmp_path, scene_format="mitsuba", extra=f"time_limit = {value}\n")
    code, out, err = cbox(capsys, "renderers", "--renderers", str(path))
    assert code == 2 and out == ""
    assert err.startswith(f"cbox: error: {path}: renderer.fake-cli.time_limit: ") and message in err, err
    assert len(err.splitlines()) == 1


def test_render_past_its_limit_is_one_line_and_exit_1(tmp_path, capsys, tmpdir_watched):
    code, out, err = cbox(capsys, "render", "-s", "furnace", "-r", "tests.user_renderers:Slow", "--spp", "1",
                          "--time-limit", "2s", "--out", str(tmp_path / "x.exr"))
    assert code == 1 and out == ""
    assert err.splitlines() == [err.strip()] and "killed at its time limit of 2 s" in err, err
    assert not (tmp_path / "x.exr").exists()


def test_a_render_that_raises_is_one_line_and_exit_1(tmp_path, capsys):
    code, _, err = cbox(capsys, "render", "-s", "furnace", "-r", "tests.user_renderers:Crashes", "--spp", "1",
                        "--out", str(tmp_path / "x.exr"))
    assert code == 1
    assert err == "cbox: error: renderer 'crashes' failed: RuntimeError: segfault simulator\n"


def test_stress_time_limit_replaces_the_variants_bound(tmp_path, capsys, tmpdir_watched):
    code, out, _ = cbox(capsys, "stress", "-r", "tests.user_renderers:Slow", "-v", "spp-1",
                        "--time-limit", "2s", "--out", str(tmp_path / "stress"))
    assert code == 1
    row = out.splitlines()[1].split()
    assert row[:5] == ["spp-1", "slow", "fail", "1", "256x256"] and row[6] == "2", out  # the bound: 2 s
    assert "spp-1 / slow (fail): did not end within the 2 s bound: killed" in out


@pytest.mark.parametrize("command", ["build", "verify"])
def test_reference_commands_past_their_limit_are_one_line_and_exit_1(tmp_path, capsys, tmpdir_watched, command):
    """Each batch renders in a child process with the limit, which neither Slow's nor Mitsuba's at 8M spp ends
    within; nothing is stored."""
    home = tmp_path / "home"
    if command == "build":
        argv = ["reference", "build", "-s", "furnace", "--set", "render.max_depth=3", "--spp", str(1 << 24),
                "--batches", "2", "--time-limit", "2s"]  # 8M spp a batch: minutes of Mitsuba
        name = "mitsuba"
    else:
        argv = ["reference", "verify", "-s", "furnace", "-e", "tests.user_renderers:Slow", "--spp", "2",
                "--batches", "2", "--time-limit", "2s", "--no-record"]
        name = "slow"
    code, out, err = cbox(capsys, *argv, "--home", str(home))
    assert code == 1, err
    assert err.strip().splitlines()[-1].startswith(f"cbox: error: renderer {name!r} failed: killed at its time "
                                                    "limit of"), err
    assert not list(home.rglob("*.exr"))


@pytest.mark.parametrize("mode, code", [("ok", 0), ("fail", 1)])
def test_a_command_render_that_ends_leaves_no_temporary_folder(tmp_path, capsys, tmpdir_watched, mode, code):
    """Success and failure, in this process and in the sandbox (--time-limit): $TMPDIR is as before."""
    files = ["--renderers", str(renderers_file(tmp_path, mode, scene_format="mitsuba"))]
    for limit in ([], ["--time-limit", "60s"]):
        got, _, _ = cbox(capsys, "compare", "-s", "furnace", *files, "-r", "fake-cli", "--spp", "2", *limit,
                         "--out", str(tmp_path / "out"))
        assert got == code


def test_the_gates_time_limit_ends_the_program_and_its_folder(tmp_path, capsys, tmpdir_watched):
    config = tmp_path / "gate.toml"
    config.write_text('[[expect]]\nscene = "furnace"\nrenderer = "fake-cli"\nspp = 2\nfinite_only = true\n'
                      'time_limit = "10s"\n')  # room for the worker to start the program on a loaded machine
    code, out, _ = cbox(capsys, "gate", "--config", str(config), "--renderers", str(_hanging(tmp_path)),
                        "--out", str(tmp_path / "gate"))
    assert code == 1
    assert "time_limit: killed at its time limit of 10 s" in out, out
    pids = logged_pids(tmp_path / "runs.log")
    assert len(pids) == 2 and not any(map(alive, pids))
