"""What a signal that ends ``cbox`` does: its renderers end with it, one line says what was kept, no traceback.

SIGINT (Ctrl-C), SIGTERM (what a CI system sends on a job's timeout or cancel)
and SIGHUP (a closed terminal or SSH session) end a command the same way:

1. every process the command started in a group of its own (a sandbox worker,
   a command-line renderer's program, the LuxCore child), with what they
   started, is ended at once (:func:`cornell_harness.processes.end_children`:
   SIGTERM, SIGKILL after a grace period), so no renderer keeps running,
   whatever it is doing;
2. the command unwinds: every ``finally`` and ``with`` on the way out runs (the
   experiment's lock, a Dask cluster's close, temporary folders), and results
   already written stay as they were, each complete (they are written atomically);
3. whatever it started that is still there is ended the same way (a Dask worker that
   did not close);
4. one line says what was kept, and the exit code is 128 + the signal's number,
   what a shell reports for a program the signal ended: 130 (SIGINT), 143
   (SIGTERM), 129 (SIGHUP).

``cbox: interrupted; 2 of 6 cells kept; rerun the same command to resume`` where
the work's units survive in its folder (a convergence run's cells), ``cbox:
interrupted after 2 of 6 renders; a rerun starts over`` where they do not, and
``cbox: interrupted`` before any work began; SIGTERM says ``terminated`` and
SIGHUP ``hung up`` where SIGINT says ``interrupted``.

Typer turns a KeyboardInterrupt into ``Exit(130)`` and, outside standalone
mode, returns 130 as if the command had, so :func:`cornell_harness.cli.app.main` cannot
catch it; the handler installed here records which signal came
(:func:`fired`) and then raises KeyboardInterrupt as Python's own does for
SIGINT, so the unwinding is the same for all three. During start-up, while
the command modules are imported (seconds: NumPy, SciPy, Numba), there is
nothing to clean up and no ``try`` to catch it: the handler of
:func:`starting` prints the line and exits at once.

The count comes from the latest progress (:class:`cornell_harness.cli.output.Progress`
registers itself with :func:`track`): this module imports nothing heavy, so
``app.py`` installs it before everything else.
"""

from __future__ import annotations

import _thread
import contextlib
import os
import signal
import sys
import threading
from typing import Any, Iterator, Protocol

from cornell_harness import processes

#: The signals that end a command, and the word its line uses for each.
SIGNALS = {signal.SIGINT: "interrupted", signal.SIGTERM: "terminated", signal.SIGHUP: "hung up"}


class Work(Protocol):
    def interrupted_note(self) -> str:
        """What the message adds after ``cbox: interrupted``: ``; 2 of 6 cells kept; ...``."""


_fired: int | None = None  # the signal that came while the command ran
_work: Work | None = None
_before: set[int] = set()  # the processes below this one when the command began: not the command's to end


def _say(signum: int, note: str = "") -> None:
    try:
        print(f"cbox: {SIGNALS[signum]}{note}", file=sys.stderr, flush=True)
    except (OSError, ValueError):  # stderr closed or a broken pipe: the exit code still says it
        pass


def _on_startup_signal(signum: int, frame: Any) -> None:
    _say(signum)
    raise SystemExit(128 + signum)  # SystemExit leaves an import without a traceback


def _on_signal(signum: int, frame: Any) -> None:
    global _fired
    first = _fired is None
    _fired = signum if first else _fired
    if first:  # at once, what runs in groups of its own; a Dask cluster's workers are closed by the unwinding
        end_children(loose=False)
    raise KeyboardInterrupt  # a second one, during the first one's clean-up, cuts that short: as the user asks


def _unraisable(hook: Any) -> Any:
    """``sys.unraisablehook`` while a command runs: the KeyboardInterrupt of a signal that came while a callback
    from C ran (numba compiling through LLVM's object cache) cannot leave it, and Python would print it as
    "Exception ignored ... Traceback"; instead it is raised again on the main thread, where it can."""
    def unraisable(info: Any) -> None:
        if _fired is not None and isinstance(info.exc_value, KeyboardInterrupt):
            _thread.interrupt_main(signal.SIGINT)  # calls _on_signal again: the first signal's code is kept
            return
        hook(info)

    return unraisable


def _swap(handler: Any) -> dict | None:
    """Install ``handler`` for every signal of :data:`SIGNALS` and return the ones before; None (nothing done)
    off the main thread, where Python allows no signal handler."""
    if threading.current_thread() is not threading.main_thread():
        return None
    return {s: signal.signal(s, handler) for s in SIGNALS}


def _restore(before: dict | None) -> None:
    for s, handler in (before or {}).items():
        signal.signal(s, handler)


@contextlib.contextmanager
def starting() -> Iterator[None]:
    """While the CLI's modules are imported: a signal prints ``cbox: interrupted`` (or its word) and exits."""
    before = _swap(_on_startup_signal)
    try:
        yield
    finally:
        _restore(before)


@contextlib.contextmanager
def handling() -> Iterator[None]:
    """While a command runs: a signal is recorded and raised as KeyboardInterrupt; the handlers before are put
    back after (tests run ``main()`` in their own process, whose signals stay pytest's). However the command
    ends, the processes it started end with it."""
    global _fired, _work, _before
    _fired, _work = None, None
    _before = set(processes.descendants(os.getpid()))
    before, hook = _swap(_on_signal), sys.unraisablehook
    sys.unraisablehook = _unraisable(hook)
    try:
        yield
    finally:
        end_children()
        _restore(before)
        sys.unraisablehook = hook


def end_children(loose: bool = True) -> None:
    """End what the command started (:func:`cornell_harness.processes.end_children`), sparing the processes that
    were there before it began (a test's own, when ``main()`` runs inside pytest)."""
    processes.end_children(spare=_before, loose=loose)


def track(work: Work) -> None:
    """The work now under way (the latest progress): the message counts its units."""
    global _work
    _work = work


def fired() -> bool:
    """Whether a signal of :data:`SIGNALS` came while the command ran."""
    return _fired is not None


def exit_interrupted() -> None:
    """End the command's processes, print the message with what the latest work kept, and exit 128 + the
    signal's number (130 when no signal was recorded: a KeyboardInterrupt raised by other means). A second
    signal now changes nothing."""
    _swap(signal.SIG_IGN)
    end_children()
    signum = _fired if _fired is not None else signal.SIGINT
    _say(signum, _work.interrupted_note() if _work is not None else "")
    sys.exit(128 + signum)
