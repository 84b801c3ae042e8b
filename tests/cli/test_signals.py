"""A signal that ends a command ends every process it started: SIGTERM, SIGINT and SIGHUP on ``cbox gate``,
``compare`` and ``converge``, with a hanging command-line renderer and with our busy path tracer.

Each run is a real ``cbox`` process in a session of its own (as a CI job's shell would start it), stderr a
pipe. The signal goes to that process alone (what a CI runner's timeout sends), once the renderer is running:
the hanging program has written its PID, and the PID of a child it started, to its log; the path tracer's
command has said it is starting it and has then spent 1.5 s of CPU more (in ``cbox`` or its sandbox worker).
No verdict waits on a sleep: within :data:`ENDED_WITHIN_S` of the signal, no process of the run is left, by
the renderer's own PIDs, by every process below ``cbox`` before the signal, and by ``cbox``'s process group;
the exit code is 128 + the signal, the last line says what was kept, and ``$TMPDIR`` holds no ``cbox-*``.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cornell_harness import processes
from tests.adapters.test_commands import renderers_file
from tests.conftest import ROOT
from tests.live_processes import alive, group, logged_pids

#: The signals, the exit code each gives and the word of the line.
SIGNALS = {"SIGTERM": (signal.SIGTERM, 143, "terminated"), "SIGINT": (signal.SIGINT, 130, "interrupted"),
           "SIGHUP": (signal.SIGHUP, 129, "hung up")}
#: Seconds from the signal by which no process of the run may be left (the issue's bound; the grace period
#: between SIGTERM and SIGKILL is 2 s of it).
ENDED_WITHIN_S = 5.0
#: Seconds a run is given to reach its held point, or to end after the signal: guards against a hang only.
PATIENCE_S = 180


def _argv(command: str, renderer: str, files: list[str], tmp_path: Path, busy: bool) -> list[str]:
    scene, spp = ("cornell-box", "100000") if busy else ("furnace", "4")
    if command == "gate":
        config = tmp_path / "gate.toml"
        config.write_text(f'[[expect]]\nscene = "{scene}"\nrenderer = "{renderer}"\nspp = {spp}\nfinite_only = true\n')
        return ["gate", "--config", str(config), *files, "--out", str(tmp_path / "gate-out")]
    if command == "compare":
        return ["compare", "--scene", scene, *files, "-r", renderer, "--spp", spp, "--out", str(tmp_path / "out")]
    return ["converge", "--scene", scene, *files, "-r", renderer, "--spp", f"1,{spp}", "--seeds", "2",
            "--out", str(tmp_path / "exp")]


def _cpu_s(*pids: int) -> float:
    """The CPU seconds ``pids`` have used, all their threads (0 for one that is gone)."""
    total = 0
    for pid in pids:
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        total += int(fields[11]) + int(fields[12])
    return total / os.sysconf("SC_CLK_TCK")


def _wait_for(what: str, ready, proc) -> None:
    deadline = time.monotonic() + PATIENCE_S
    while not ready():
        if proc.poll() is not None or time.monotonic() > deadline:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            said = Path(proc.args[-1]).parent / "stderr.txt"  # every run's --out is in its tmp_path
            raise AssertionError(f"never {what}: {said.read_text() if said.exists() else ''}")
        time.sleep(0.05)


@pytest.mark.parametrize("signame", SIGNALS)
@pytest.mark.parametrize("command", ["gate", "compare", "converge"])
@pytest.mark.parametrize("renderer", ["hanging-program", "busy-pathtracer"])
def test_a_signal_ends_the_command_and_every_process_it_started(tmp_path, command, renderer, signame):
    signum, code, word = SIGNALS[signame]
    busy = renderer == "busy-pathtracer"
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    log = tmp_path / "runs.log"
    if busy:
        argv = _argv(command, "pathtracer", [], tmp_path, busy)
    else:  # the mitsuba format: a real one, which the sandbox's child can write too; the program ignores it
        files = ["--renderers", str(renderers_file(tmp_path, "spawn-hang", scene_format="mitsuba"))]
        argv = _argv(command, "fake-cli", files, tmp_path, busy)
    stdout, stderr = tmp_path / "stdout.txt", tmp_path / "stderr.txt"
    with open(stdout, "w") as out, open(stderr, "w") as err:
        proc = subprocess.Popen([sys.executable, "-m", "cornell_harness", *argv], cwd=ROOT, start_new_session=True,
                                env=dict(os.environ, PYTHONPATH=str(ROOT), TMPDIR=str(tmp)), stdout=out, stderr=err)
    if busy:
        _wait_for("started the path tracer", lambda: "pathtracer" in stderr.read_text(), proc)
        started = _cpu_s(proc.pid, *processes.descendants(proc.pid))
        _wait_for("rendered", lambda: _cpu_s(proc.pid, *processes.descendants(proc.pid)) > started + 1.5, proc)
    else:
        _wait_for("started the program and its child", lambda: len(logged_pids(log)) >= 2, proc)
    tree = processes.descendants(proc.pid)  # in-process, the path tracer has none
    assert tree or (busy and command != "gate")
    proc.send_signal(signum)
    signalled = time.monotonic()
    deadline = signalled + ENDED_WITHIN_S
    while (left := [p for p in [proc.pid, *tree, *logged_pids(log), *group(proc.pid)] if alive(p)]) and \
            time.monotonic() < deadline:
        time.sleep(0.05)
    ended_s = time.monotonic() - signalled
    try:
        proc.wait(timeout=PATIENCE_S)
    finally:
        for p in left:
            os.kill(p, signal.SIGKILL)
    assert not left, f"{left} still alive {ended_s:.1f} s after {signame}"
    lines = stderr.read_text().strip().splitlines()
    assert proc.returncode == code, lines
    assert lines[-1].startswith(f"cbox: {word}"), lines
    assert "Traceback" not in stderr.read_text(), lines
    assert sorted(p.name for p in tmp.iterdir() if p.name.startswith("cbox-")) == []
