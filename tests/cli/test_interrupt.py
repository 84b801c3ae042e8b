"""Ctrl-C (SIGINT): one line saying what was kept, exit code 130, no traceback; progress in a pipe from the start.

The runs are real ``python -m cornell_harness`` processes, stderr a pipe (as in CI), held at a known point by the test
renderer (tests/user_renderers.py CountingNoise, $CBOX_TEST_RENDER_HOLD_AFTER) or, for start-up, by an import
hook of the test's own; the signal is sent only once the process says it is there, so no verdict rests on timing.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from cornell_harness import processes
from tests.conftest import ROOT
from tests.live_processes import group

SEEDS = 3
#: Seconds a held process is given to reach its point or to end, at most: guards against a hang only.
PATIENCE_S = 120


def _converge(out, seeds=SEEDS):
    return ["converge", "--scene", "cornell-box", "--renderer", "tests.user_renderers:CountingNoise",
            "--spp", "1,2", "--seeds", str(seeds), "--out", str(out)]


def _env(log, **extra):
    return dict(os.environ, PYTHONPATH=str(ROOT), CBOX_TEST_RENDER_LOG=str(log), **extra)


def _start(argv, env):
    return subprocess.Popen(argv, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _lines_until(proc, text: str) -> list[str]:
    """stderr's lines up to and including the first holding ``text``; fails if the process ends first."""
    lines = []
    deadline = time.monotonic() + PATIENCE_S
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line:
            break
        lines.append(line.rstrip("\n"))
        if text in line:
            return lines
    proc.kill()
    raise AssertionError(f"never said {text!r}: {lines}")


def _interrupt(proc) -> tuple[int, str]:
    """SIGINT, as a terminal's Ctrl-C sends it; (exit code, the rest of stderr)."""
    proc.send_signal(signal.SIGINT)
    try:
        _, rest = proc.communicate(timeout=PATIENCE_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        raise
    return proc.returncode, rest


def _rendered_seeds(log) -> set[int]:
    return {int(line.split()[0]) for line in log.read_text().splitlines()}


def test_interrupted_converge_says_what_it_kept_and_the_rerun_resumes(tmp_path):
    """Held in the second cell (after two renders: one cell of spp 1 and 2), SIGINT: that cell is kept, the
    message says so, exit 130; the rerun renders only the other seeds."""
    out, log = tmp_path / "exp", tmp_path / "renders.log"
    proc = _start([sys.executable, "-m", "cornell_harness", *_converge(out)], _env(log, CBOX_TEST_RENDER_HOLD_AFTER="2"))
    said = _lines_until(proc, f"1/{SEEDS} cells")
    code, rest = _interrupt(proc)
    assert code == 130, rest
    assert rest.strip().splitlines()[-1] == \
        f"cbox: interrupted; 1 of {SEEDS} cells kept; rerun the same command to resume", said + [rest]
    assert "Traceback" not in rest and "Aborted" not in rest, rest
    kept = {int(p.stem.rsplit("seed", 1)[1]) for p in (out / "cells").glob("*.parquet")}
    assert kept == _rendered_seeds(log) == {0}, kept

    first = len(log.read_text().splitlines())
    again = subprocess.run([sys.executable, "-m", "cornell_harness", *_converge(out)], cwd=ROOT, env=_env(log),
                           capture_output=True, text=True, timeout=PATIENCE_S * 2)
    assert again.returncode == 0, again.stderr
    second = {int(line.split()[0]) for line in log.read_text().splitlines()[first:]}
    assert second == set(range(SEEDS)) - kept, second
    assert again.stderr.count("(stored)") == 1, again.stderr


def test_first_progress_line_comes_before_the_first_cell_ends(tmp_path):
    """In a pipe the work's start is a line of its own: here the first cell holds (HOLD_AFTER 0), and the line
    is there while it does; a Ctrl-C then keeps nothing."""
    out, log = tmp_path / "exp", tmp_path / "renders.log"
    log.touch()  # the hold counts the renders logged: none yet
    proc = _start([sys.executable, "-m", "cornell_harness", *_converge(out, seeds=2)],
                  _env(log, CBOX_TEST_RENDER_HOLD_AFTER="0"))
    said = _lines_until(proc, "starting")
    assert said[-1] == "converge cornell-box: 0/2 cells, starting counting-noise seed 0", said
    code, rest = _interrupt(proc)
    assert code == 130 and "\r" not in rest, rest
    assert rest.strip().splitlines()[-1] == "cbox: interrupted; 0 of 2 cells kept; rerun the same command to resume"
    assert log.read_text() == "" and not list((out / "cells").glob("*.parquet"))


#: ``cbox ARGS`` whose start-up holds in the import of the first command module (cornell_harness.cli.listing), after
#: touching the file argv[1] (``marker``): the imports of app.py are under way, nothing of the command has run.
_HELD_STARTUP = textwrap.dedent("""
    import importlib.abc, pathlib, sys, time

    class Hold(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path, target=None):
            if name == "cornell_harness.cli.listing":
                pathlib.Path(marker).touch()
                time.sleep(600)
            return None

    sys.meta_path.insert(0, Hold())
    marker, sys.argv = sys.argv[1], ["cbox", *sys.argv[2:]]
    from cornell_harness.cli.app import main
    main()
""")


def test_interrupt_during_start_up_is_one_line_without_traceback(tmp_path):
    marker = tmp_path / "importing"
    proc = _start([sys.executable, "-c", _HELD_STARTUP, str(marker), *_converge(tmp_path / "exp")],
                  _env(tmp_path / "renders.log"))
    deadline = time.monotonic() + PATIENCE_S
    while not marker.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert marker.exists(), proc.communicate()
    code, rest = _interrupt(proc)
    assert code == 130, rest
    assert rest.strip() == "cbox: interrupted", rest
    assert not (tmp_path / "exp").exists()


@pytest.mark.slow
@pytest.mark.parametrize("signum, code, word, to_group", [(signal.SIGINT, 130, "interrupted", True),
                                                          (signal.SIGTERM, 143, "terminated", False)],
                         ids=["ctrl-c-to-the-group", "sigterm-to-cbox"])
def test_a_signal_on_local_workers_closes_the_cluster(tmp_path, signum, code, word, to_group):
    """--workers 2, held once one render (spp 1 of a cell) is logged, so no cell ends: Ctrl-C as a terminal
    sends it (to the whole process group, the workers too), or SIGTERM to cbox alone as a CI runner sends it,
    gives the message and its exit code, no traceback from any process, and no process of the run is left
    behind (of the group, or below cbox before the signal)."""
    out, log = tmp_path / "exp", tmp_path / "renders.log"
    proc = subprocess.Popen([sys.executable, "-m", "cornell_harness", *_converge(out), "--workers", "2"], cwd=ROOT,
                            env=_env(log, CBOX_TEST_RENDER_HOLD_AFTER="1"), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    said = _lines_until(proc, "starting")
    deadline = time.monotonic() + PATIENCE_S  # the workers are rendering
    while not (log.exists() and log.read_text()) and time.monotonic() < deadline:
        time.sleep(0.1)
    tree = processes.descendants(proc.pid)
    assert len(tree) >= 2, tree  # the workers
    if to_group:
        os.killpg(proc.pid, signum)
    else:
        proc.send_signal(signum)
    try:
        _, rest = proc.communicate(timeout=PATIENCE_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        raise
    assert proc.returncode == code, said + [rest]
    assert rest.strip().splitlines()[-1] == f"cbox: {word}; 0 of {SEEDS} cells kept; rerun the same command " \
                                             "to resume", rest
    assert "Traceback" not in rest, rest
    deadline = time.monotonic() + 30  # the workers' nannies end with their scheduler
    while (left := group(proc.pid) + [p for p in tree if Path(f"/proc/{p}").exists()]) and \
            time.monotonic() < deadline:
        time.sleep(0.2)
    assert not left, left
