"""What is still running, read from ``/proc`` by the tests themselves, not by the code they test
(:mod:`cornell_harness.processes`): a zombie has ended (only its exit status waits to be read)."""

from __future__ import annotations

from pathlib import Path


def _fields(stat: Path) -> list[str] | None:
    """``/proc/PID/stat``'s fields after the command's name (state first), None when the process is gone."""
    try:
        return stat.read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None


def alive(pid: int) -> bool:
    """Whether ``pid`` exists and has not ended."""
    fields = _fields(Path(f"/proc/{pid}/stat"))
    return fields is not None and fields[0] not in ("Z", "X")


def group(pgid: int) -> list[int]:
    """The live processes of process group ``pgid``."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        fields = _fields(stat)
        if fields is not None and int(fields[2]) == pgid and fields[0] not in ("Z", "X"):
            found.append(int(stat.parent.name))
    return found


def logged_pids(log: Path) -> list[int]:
    """The PIDs a test program logged, the last word of each line of ``log`` (none before it exists)."""
    return [int(line.split()[-1]) for line in log.read_text().splitlines()] if log.exists() else []
