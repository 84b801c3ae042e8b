"""CPU burners for the contention tests: processes that burn a core each, started outside the test's process tree
(another command's work on the machine), or inside it (the command's own worker); and a process's CPU ticks.

An outside burner is double-forked: its launcher, the test's child, exits at once, so the burner is adopted
by init (or the nearest subreaper above the test) and is no descendant of the test process, which is the
command's root when the CLI runs in-process. It writes its PID to a file; the test waits on that file and on
the CPU time the burner has used (never on a sleep), and kills it by that PID at the end.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Iterator

from tests.live_processes import alive

_OUTSIDE = """
import os, sys
if os.fork():
    os._exit(0)
os.setsid()
with open(sys.argv[1] + ".tmp", "w") as f:
    f.write(str(os.getpid()))
os.replace(sys.argv[1] + ".tmp", sys.argv[1])
while True:
    pass
"""
#: A hang guard only: a burner starts within a second, even on a busy machine.
START_S = 60


def cpu_ticks(pid: int) -> int:
    """utime + stime + cutime + cstime of ``pid`` (clock ticks), from /proc/PID/stat."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rpartition(")")[2].split()
    return sum(int(v) for v in fields[11:15])


def wait_for_cpu(pids: list[int], ticks: int) -> None:
    """Return once every one of ``pids`` has used ``ticks`` more CPU ticks than now."""
    start = {pid: cpu_ticks(pid) for pid in pids}
    deadline = time.monotonic() + START_S
    while not all(cpu_ticks(p) - start[p] >= ticks for p in pids):
        assert time.monotonic() < deadline, f"burners {pids} used no CPU in {START_S} s"
        time.sleep(0.01)


@contextlib.contextmanager
def outside_burners(n: int, folder: Path) -> Iterator[list[int]]:
    """``n`` processes burning a core each, none of them in this process's tree: their PIDs, each already burning;
    killed on leaving."""
    pids: list[int] = []
    try:
        for i in range(n):
            pidfile = Path(folder) / f"burner{i}.pid"
            subprocess.run([sys.executable, "-c", _OUTSIDE, str(pidfile)], check=True, timeout=START_S)
            deadline = time.monotonic() + START_S
            while not pidfile.exists():
                assert time.monotonic() < deadline, f"no burner wrote {pidfile}"
                time.sleep(0.01)
            pids.append(int(pidfile.read_text()))
        wait_for_cpu(pids, 2)
        yield pids
    finally:
        for pid in pids:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        deadline = time.monotonic() + START_S
        while any(alive(p) for p in pids) and time.monotonic() < deadline:
            time.sleep(0.01)


@contextlib.contextmanager
def own_burner() -> Iterator[int]:
    """One process burning a core, this process's child (the command's own worker): its PID; killed on leaving."""
    proc = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        wait_for_cpu([proc.pid], 2)
        yield proc.pid
    finally:
        proc.kill()
        proc.wait()
