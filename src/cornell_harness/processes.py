"""The one process-lifetime rule: every process a command starts ends with the command, and no later.

A child is started by :func:`start` (or run to its end, within a time limit, by
:func:`run`) in a process group of its own, which this process records. What
that child starts stays in its group, unless it makes a group of its own; a
program that daemonises leaves the tree but not its group.

A command ends its children with :func:`end_children` when a signal ends it
(SIGTERM, SIGINT, SIGHUP: :mod:`cornell_harness.cli.interrupt`) and again
when it exits, whatever the exit: every process group in its process tree, and
every group it started, is sent SIGTERM; after :data:`GRACE_S` seconds what is
left gets SIGKILL. Processes that share the command's own group (a Dask
``LocalCluster``'s workers, which distributed starts) are signalled one by one,
never by group (the command's group may hold the shell pipeline it runs in),
and only at the command's exit: its unwinding closes the cluster first.

A child that passes its time limit is ended the same way, with its group and
its children, and :func:`run` raises :class:`TimeLimitExceeded`.

Where there is no ``/proc`` (macOS) only the groups started here are ended.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Iterable, Sequence

#: Seconds between SIGTERM and SIGKILL: a renderer may flush or remove its files, but not hold up the exit.
GRACE_S = 2.0
#: Seconds between two looks at what is still alive, while waiting.
POLL_S = 0.02

_started: set[int] = set()  # the process groups started here that may still have members


class TimeLimitExceeded(RuntimeError):
    """A child ran past its time limit and was ended, with its group; ``time_s`` is how long it ran."""

    def __init__(self, limit_s: float, time_s: float):
        super().__init__(f"killed at its time limit of {limit_s:g} s")
        self.limit_s, self.time_s = limit_s, time_s


def start(argv: Sequence[str], **popen_args) -> subprocess.Popen:
    """``subprocess.Popen(argv, **popen_args)`` in a process group (a session) of its own, recorded to be ended."""
    proc = subprocess.Popen(list(argv), start_new_session=True, **popen_args)
    _started.add(proc.pid)
    return proc


def run(argv: Sequence[str], time_limit_s: float | None = None, **popen_args) -> int:
    """Run ``argv`` (:func:`start`) to its end and return its exit code (negative: the signal that ended it).

    Past ``time_limit_s`` seconds it is ended with its group (:func:`end`) and :class:`TimeLimitExceeded`
    raised. Whatever interrupts the wait (a signal's KeyboardInterrupt) ends it too before going on.
    """
    t0 = time.monotonic()
    proc = start(argv, **popen_args)
    try:
        return proc.wait(timeout=time_limit_s)
    except subprocess.TimeoutExpired:
        end([proc.pid])
        raise TimeLimitExceeded(time_limit_s, time.monotonic() - t0) from None
    finally:
        end([proc.pid])  # its group: what it started and left behind (a no-op when all are gone)
        proc.wait()


def end(groups: Iterable[int], grace_s: float = GRACE_S) -> None:
    """End process groups ``groups`` and every process below them: SIGTERM, then SIGKILL after ``grace_s``."""
    groups = set(groups)
    _end(groups, [], grace_s)
    _started.difference_update(groups)


def end_children(grace_s: float = GRACE_S, spare: Iterable[int] = (), loose: bool = True) -> None:
    """End every process this one started and what they started, but ``spare`` and what is below them: the
    groups in its tree and those :func:`start` made, politely first (see the module docstring); with ``loose``
    also the processes in this one's own group (a Dask ``LocalCluster``'s workers), but Python's own
    multiprocessing helper (:func:`_runtime_helpers`), which ends when this process does. Safe to call more
    than once, and with no children."""
    own, spare = os.getpgrp(), set(spare) | _runtime_helpers()
    tree = descendants(os.getpid(), skip=spare)
    groups = {g for g in map(_group_of, tree) if g is not None and g != own and g not in spare} | _started
    _end(groups, [p for p in tree if _group_of(p) == own] if loose else [], grace_s)
    _started.clear()


def _runtime_helpers() -> set[int]:
    """multiprocessing's resource tracker, if this process started one: it ignores SIGTERM, cleans up what the
    workers leave, and ends by itself when this process has."""
    tracker = sys.modules.get("multiprocessing.resource_tracker")
    pid = getattr(getattr(tracker, "_resource_tracker", None), "_pid", None)
    return {pid} if isinstance(pid, int) else set()


def descendants(pid: int, skip: Iterable[int] = ()) -> list[int]:
    """Every process below ``pid`` (its children, theirs, ...) but ``skip`` and what is below them, by ``/proc``;
    empty where there is none."""
    found, todo, skip = [], [pid], set(skip)
    while todo:
        for task in _tasks(todo.pop()):
            try:
                children = [c for c in map(int, task.joinpath("children").read_text().split()) if c not in skip]
            except (OSError, ValueError):
                continue
            found += children
            todo += children
    return found


def _tasks(pid: int) -> list[Path]:
    """The threads of ``pid`` in ``/proc``: a child is listed under the thread that started it."""
    try:
        return list(Path(f"/proc/{pid}/task").iterdir())
    except OSError:
        return []


def _group_of(pid: int) -> int | None:
    try:
        return os.getpgid(pid)
    except (ProcessLookupError, PermissionError):
        return None


def _end(groups: set[int], loose: list[int], grace_s: float) -> None:
    """SIGTERM to ``groups`` (and what is below them) and to the ``loose`` processes, SIGKILL after ``grace_s``
    to whatever of them is still alive. Ended children are left for their owners to reap (a zombie counts as
    ended): reaped here, a ``Popen`` would read exit code 0."""
    if not groups and not loose:
        return
    members = _members(groups, loose)
    _signal(groups, members, signal.SIGTERM)
    deadline = time.monotonic() + grace_s
    while time.monotonic() < deadline:
        members = [p for p in _members(groups, loose) if _alive(p)]
        if not members:
            return
        time.sleep(POLL_S)
    _signal(groups, members, signal.SIGKILL)
    deadline = time.monotonic() + grace_s  # SIGKILL cannot be refused: this only waits for the kernel
    while members and time.monotonic() < deadline:
        members = [p for p in members if _alive(p)]
        time.sleep(POLL_S)


def _members(groups: set[int], loose: list[int]) -> list[int]:
    """The processes of ``groups`` (and of the trees below them) and ``loose``, with their descendants."""
    roots = set(loose) | {p for p in groups if _alive(p)}
    for proc in Path("/proc").glob("[0-9]*"):
        try:
            if os.getpgid(int(proc.name)) in groups:
                roots.add(int(proc.name))
        except (ProcessLookupError, PermissionError, ValueError):
            pass
    return sorted(roots | {d for r in roots for d in descendants(r)})


def _signal(groups: set[int], members: list[int], signum: int) -> None:
    for target, kill in [(g, os.killpg) for g in groups] + [(p, os.kill) for p in members]:
        try:
            kill(target, signum)
        except (ProcessLookupError, PermissionError):
            pass


def _alive(pid: int) -> bool:
    """Whether ``pid`` exists and is no zombie (a zombie has ended; only its exit status waits to be read)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        try:
            os.kill(pid, 0)  # no /proc: existence is all that can be asked
        except (ProcessLookupError, PermissionError):
            return False
        return True
    return state not in ("Z", "X")
