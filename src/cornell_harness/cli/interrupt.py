"""What Ctrl-C (SIGINT) does to ``cbox``: one line saying what was kept, exit code 130, never a traceback.

``cbox: interrupted; 2 of 6 cells kept; rerun the same command to resume`` where
the work's units survive in its folder (a convergence run's cells), ``cbox:
interrupted after 2 of 6 renders; a rerun starts over`` where they do not, and
``cbox: interrupted`` before any work began. 130 is 128 + SIGINT, what a shell
reports for a program the signal ended.

Typer turns a KeyboardInterrupt into ``Exit(130)`` and, outside standalone
mode, returns 130 as if the command had, so :func:`cornell_harness.cli.app.main` cannot
catch it; the handler installed here records that the signal came
(:func:`fired`) and then raises KeyboardInterrupt as Python's own does, so
every ``finally`` and ``with`` on the way out (the experiment's lock, a Dask
cluster) still runs. During start-up, while the command modules are imported
(seconds: NumPy, SciPy, Numba), there is nothing to clean up and no ``try`` to
catch it: the handler of :func:`starting` prints the line and exits at once.

The count comes from the latest progress (:class:`cornell_harness.cli.output.Progress`
registers itself with :func:`track`): this module imports nothing heavy, so
``app.py`` installs it before everything else.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from typing import Any, Iterator, Protocol


class Work(Protocol):
    def interrupted_note(self) -> str:
        """What the message adds after ``cbox: interrupted``: ``; 2 of 6 cells kept; ...``."""


_fired = False
_work: Work | None = None


def _say(note: str = "") -> None:
    try:
        print(f"cbox: interrupted{note}", file=sys.stderr, flush=True)
    except (OSError, ValueError):  # stderr closed or a broken pipe: the exit code still says it
        pass


def _on_startup_signal(signum: int, frame: Any) -> None:
    _say()
    raise SystemExit(130)  # SystemExit leaves an import without a traceback


def _on_signal(signum: int, frame: Any) -> None:
    global _fired
    _fired = True
    raise KeyboardInterrupt  # a second one, during the first one's clean-up, cuts that short: as the user asks


def _swap(handler: Any) -> Any:
    """Install ``handler`` for SIGINT and return the one before; None (nothing done) off the main thread,
    where Python allows no signal handler."""
    if threading.current_thread() is not threading.main_thread():
        return None
    return signal.signal(signal.SIGINT, handler)


@contextlib.contextmanager
def starting() -> Iterator[None]:
    """While the CLI's modules are imported: a Ctrl-C prints ``cbox: interrupted`` and exits 130."""
    before = _swap(_on_startup_signal)
    try:
        yield
    finally:
        if before is not None:
            signal.signal(signal.SIGINT, before)


@contextlib.contextmanager
def handling() -> Iterator[None]:
    """While a command runs: a Ctrl-C is recorded and raised as KeyboardInterrupt; the handler before is put
    back after (tests run ``main()`` in their own process, whose Ctrl-C stays pytest's)."""
    global _fired, _work
    _fired, _work = False, None
    before = _swap(_on_signal)
    try:
        yield
    finally:
        if before is not None:
            signal.signal(signal.SIGINT, before)


def track(work: Work) -> None:
    """The work now under way (the latest progress): the message counts its units."""
    global _work
    _work = work


def fired() -> bool:
    """Whether a Ctrl-C came while the command ran."""
    return _fired


def exit_interrupted() -> None:
    """Print the message, with what the latest work kept, and exit 130 (a second Ctrl-C now changes nothing)."""
    _swap(signal.SIG_IGN)
    _say(_work.interrupted_note() if _work is not None else "")
    sys.exit(130)
