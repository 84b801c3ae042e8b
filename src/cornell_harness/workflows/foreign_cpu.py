"""The CPU that processes other than the command's own used while it timed a render: the measure of contention.

A render competes for the cores only with work that is not the command's
own. The command's own work (its Dask workers, a sandboxed render's child,
a renderer's program, its thread pools spinning down) is part of what it
measures, or was scheduled by it on purpose; counting it as load flagged a
quiet machine as busy. So the measure here is the machine's busy CPU time
over an interval less that of the command's process tree:

- **the machine's**: the ``cpu`` line of ``/proc/stat`` (proc(5)), all
  cores, every state but idle and iowait: user, nice, system, irq, softirq
  and steal (time a hypervisor gave to another machine: it is contention
  too);
- **the command's**: utime + stime + cutime + cstime of every process in
  the tree under the command's root (``/proc/PID/stat``): its live
  descendants by their own times, the finished and waited-for ones through
  their parents' ``cutime`` and ``cstime``, so that a child that ends inside
  the interval is counted once, whichever side of its end the readings fall.

The root is the process named by the environment variable
:data:`ROOT_ENV` where that process is this one or an ancestor of it (the
CLI sets it at start, :func:`mark_command_root`; every child it starts, a
Dask worker or the sandbox's child, inherits it), else this process.

All figures are in clock ticks (``SC_CLK_TCK``, 100 per second on Linux),
each counter truncated to a whole tick as it is read: the difference of two
readings of a sum of them may be off by a few ticks with nothing running,
which :data:`ROUNDING_TICKS` allows for. Without ``/proc`` (macOS) there is
no figure (NaN) and the verdict falls back to load and calibration
(:mod:`cornell_harness.evaluate.timing_quality`).

Kept light (the standard library only): the sandbox's child process imports it.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass

#: The environment variable naming the command's root process (a PID), inherited by everything it starts.
ROOT_ENV = "CBOX_COMMAND_PID"
#: Ticks of rounding allowed in a difference of readings, plus one per process of the command's tree: each
#: counter is truncated to a tick as it is read (the machine's six summed, each process's four), so a
#: difference of two readings is off by under one tick per counter, typically about one in all.
ROUNDING_TICKS = 3


def _fields(pid: int | str) -> list[bytes] | None:
    """The fields of ``/proc/PID/stat`` after the command name (state first), or None (gone, or no /proc)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rpartition(b")")[2].split()
    except OSError:
        return None


def _ancestors(pid: int) -> set[int]:
    """The PIDs above ``pid`` up to init (empty without /proc)."""
    seen: set[int] = set()
    while pid > 1 and (fields := _fields(pid)) is not None:
        pid = int(fields[1])
        if pid in seen:
            break
        seen.add(pid)
    return seen


def command_root() -> int:
    """The PID whose process tree is the command's own: :data:`ROOT_ENV`'s where it is this process or an
    ancestor of it (not a stale value inherited from elsewhere), else this process's."""
    me = os.getpid()
    try:
        named = int(os.environ.get(ROOT_ENV, ""))
    except ValueError:
        return me
    return named if named == me or named in _ancestors(me) else me


def mark_command_root() -> None:
    """Make this process the command's root unless an ancestor already is: a command started by another
    command (a renderer's program calling ``cbox``) stays part of the first one's work."""
    os.environ[ROOT_ENV] = str(command_root())


def _machine_busy_ticks() -> int | None:
    """The machine's busy ticks so far, all cores: the ``cpu`` line of /proc/stat less idle and iowait."""
    try:
        with open("/proc/stat", "rb") as f:
            values = [int(v) for v in f.readline().split()[1:9]]
    except (OSError, ValueError):
        return None
    user, nice, system, _idle, _iowait, irq, softirq, steal = (values + [0] * 8)[:8]
    return user + nice + system + irq + softirq + steal


def _tree_ticks(root: int) -> tuple[int, int] | None:
    """(CPU ticks of ``root`` and its descendants, waited-for children included; processes in the tree)."""
    try:
        names = os.listdir("/proc")
    except OSError:
        return None
    children: dict[int, list[int]] = {}
    ticks: dict[int, int] = {}
    for name in names:
        if not name.isdigit() or (fields := _fields(name)) is None:
            continue
        pid = int(name)
        try:
            ticks[pid] = sum(int(v) for v in fields[11:15])  # utime, stime, cutime, cstime
            children.setdefault(int(fields[1]), []).append(pid)
        except (ValueError, IndexError):
            continue
    if root not in ticks:
        return None
    total, count, todo = 0, 0, [root]
    while todo:
        pid = todo.pop()
        total, count = total + ticks.get(pid, 0), count + 1
        todo.extend(children.get(pid, ()))
    return total, count


@dataclass(frozen=True)
class CpuSnapshot:
    """The machine's and the command's CPU ticks at one moment (:func:`cpu_snapshot`)."""

    at: float  # time.monotonic() seconds
    busy: int  # the machine's busy ticks, all cores
    own: int  # the command's tree's ticks
    processes: int  # in the command's tree


def cpu_snapshot(root: int | None = None, start: bool = True) -> CpuSnapshot | None:
    """The ticks now, of the tree under ``root`` (default :func:`command_root`); None without /proc.

    ``start``: the snapshot opens an interval, so the tree is read before the machine's counter (and after it
    when it closes one): the command's own reading, between the two, is inside its own figure."""
    root = command_root() if root is None else root
    first = _tree_ticks(root) if start else _machine_busy_ticks()
    at = time.monotonic()
    second = _machine_busy_ticks() if start else _tree_ticks(root)
    tree, busy = (first, second) if start else (second, first)
    if tree is None or busy is None:
        return None
    return CpuSnapshot(at, busy, tree[0], tree[1])


def foreign_cpu_seconds(before: CpuSnapshot, after: CpuSnapshot) -> float:
    """CPU seconds other processes used between the two snapshots (the rounding allowance taken off, never
    below 0)."""
    ticks = (after.busy - before.busy) - (after.own - before.own)
    slack = ROUNDING_TICKS + max(before.processes, after.processes)
    return max(ticks - slack, 0) / os.sysconf("SC_CLK_TCK")


def foreign_cores(before: CpuSnapshot | None, after: CpuSnapshot | None) -> float:
    """Cores' worth of CPU that processes outside the command's tree used between the snapshots: their CPU
    seconds over the wall seconds between; NaN without either snapshot."""
    if before is None or after is None or after.at <= before.at:
        return math.nan
    return foreign_cpu_seconds(before, after) / (after.at - before.at)
