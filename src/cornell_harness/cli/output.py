"""What a ``cbox`` command says besides its results: how much (``--quiet``, ``--verbose``), remarks, progress.

A long command reports progress with :class:`Progress` (a bar only when stderr is a terminal, else one plain
line per finished unit of work, so a CI log gets no carriage returns), other remarks with :func:`info`;
``--quiet`` silences both, ``--verbose`` adds per-unit lines under the bar and INFO logging
(:func:`set_verbosity`). :func:`close_progress_bars` lets an error start a fresh line.
"""

from __future__ import annotations

import enum
import logging
import sys
import time

import typer
from tqdm import tqdm

from cornell_harness.cli import interrupt


class Verbosity(enum.IntEnum):
    QUIET = 0  # results and errors only
    NORMAL = 1  # and progress, and remarks such as "report: out/report.html"
    VERBOSE = 2  # and a line per finished unit even under a bar, and INFO logging


_verbosity = Verbosity.NORMAL
_live_bars: list["Progress"] = []


_log_handlers: list[logging.Handler] = []  # ours on the root logger, while verbose


def set_verbosity(level: Verbosity) -> None:
    """Set how much commands say (``--quiet``, ``--verbose``); logging follows: INFO and up on stderr when
    verbose, ERROR and up when quiet, else Python's default (warnings, through its last-resort handler)."""
    global _verbosity
    _verbosity = level
    root = logging.getLogger()
    root.setLevel({Verbosity.QUIET: logging.ERROR, Verbosity.NORMAL: logging.WARNING,
                   Verbosity.VERBOSE: logging.INFO}[level])
    while _log_handlers:
        root.removeHandler(_log_handlers.pop())
    if level >= Verbosity.VERBOSE:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("cbox: %(name)s: %(levelname)s: %(message)s"))
        root.addHandler(handler)
        _log_handlers.append(handler)


def _flag(level: Verbosity):
    def callback(ctx: typer.Context, value: bool) -> None:
        if not value or ctx.resilient_parsing:
            return
        if _verbosity not in (Verbosity.NORMAL, level):
            raise typer.BadParameter("give --quiet or --verbose, not both")
        set_verbosity(level)
    return callback


# Global (`cbox -q converge ...`) on the app's callback below, and copied onto every command by
# command_tree (`cbox converge ... -q`), where one looks for it; neither edits a command's signature.
QuietOpt = typer.Option(False, "--quiet", "-q", callback=_flag(Verbosity.QUIET), expose_value=False,
                        help="Print only results and errors: no progress, no remarks.")
VerboseOpt = typer.Option(False, "--verbose", "-v", callback=_flag(Verbosity.VERBOSE), expose_value=False,
                          help="Also print a line per finished run under the progress bar, and INFO logging.")

def info(message: str) -> None:
    """A remark on stderr (``report: PATH``, ``wrote FILE``): not a result, so ``--quiet`` drops it."""
    if _verbosity > Verbosity.QUIET:
        tqdm.write(message, file=sys.stderr)  # above a live bar, if there is one


def _stderr_is_terminal() -> bool:
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):  # replaced or closed
        return False


def _clock(seconds: float) -> str:
    return tqdm.format_interval(seconds)


class Progress:
    """Progress of a long command through ``total`` units of work (runs, cells, batches, expectations).

    On a terminal, a bar on stderr; anywhere else (a CI log, a pipe), a line
    when the work starts (the first :meth:`start`: ``converge cornell-box: 0/8
    cells, starting pathtracer seed 0``), then one plain line per finished unit,
    ``converge cornell-box: 3/8 cells, pathtracer seed 2 (12.3 s), 01:02
    left``, and never a carriage return. ``--quiet``: nothing. ``kept``: the
    finished units stay in the output folder and a rerun resumes, which a
    Ctrl-C's message says (:mod:`cornell_harness.cli.interrupt`, told of each Progress).
    The time left is the mean time of the units that did work times the units
    to go: stored (resumed) units take no time and do not count. With
    ``slots`` > 1 (units running at once, on several workers) it also says how
    many are running; it says how many failed once one has.
    """

    def __init__(self, total: int, desc: str, unit: str = "run", slots: int = 1, kept: bool = False):
        # English plurals of the units we count: runs, cells, expectations, batches.
        self.unit, self.units = unit, unit + ("es" if unit.endswith(("s", "x", "ch", "sh")) else "s")
        self.total, self.desc, self.slots, self.kept = total, desc, slots, kept
        self.done = self.stored = self.failed = 0
        self._said = False  # a line has gone to the log
        self.work_s = 0.0
        self._since = time.perf_counter()
        self._bar = None
        if _verbosity > Verbosity.QUIET and _stderr_is_terminal():
            self._bar = tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, dynamic_ncols=True, leave=False,
                             bar_format="{desc}: {n_fmt}/{total_fmt} " + self.units + " |{bar}| {elapsed}{postfix}")
        _live_bars.append(self)
        interrupt.track(self)

    def left_s(self) -> float | None:
        """Seconds to go, from the units that did work; None before the first of them."""
        worked = self.done - self.stored
        if not worked or self.done >= self.total:
            return None
        return self.work_s / worked * (self.total - self.done)

    def start(self, label: str) -> None:
        """Name the unit now running: on the bar; in a log, the first only (the work has started), as the
        line of each unit comes when it finishes."""
        if self._bar is not None:
            self._bar.set_postfix_str(self._postfix(label))
        elif _verbosity > Verbosity.QUIET and not self._said:
            self._said = True
            print(f"{self.desc}: {self.done}/{self.total} {self.units}, starting {label}".rstrip(), file=sys.stderr,
                  flush=True)

    def interrupted_note(self) -> str:
        """What a Ctrl-C's message says of this work: ``; 2 of 6 cells kept; rerun the same command to resume``
        or ``after 2 of 6 renders; a rerun starts over``."""
        of = f"{self.done - self.failed if self.kept else self.done} of {self.total} " + \
            (self.unit if self.total == 1 else self.units)
        return f"; {of} kept; rerun the same command to resume" if self.kept else f" after {of}; a rerun starts over"

    def running(self) -> int:
        """Units running now: as many as there are slots, while that many are left."""
        return min(self.slots, self.total - self.done)

    def advance(self, label: str, stored: bool = False, failed: bool = False) -> None:
        """One more unit finished (``stored``: loaded from an earlier run, not worked on; ``failed``: it failed)."""
        now = time.perf_counter()
        took, self._since = now - self._since, now
        self.done += 1
        self.failed += bool(failed)
        if stored:
            self.stored += 1
        else:
            self.work_s += took
        left = self.left_s()
        line = (f"{self.desc}: {self.done}/{self.total} {self.units}, {label} "
                f"({'stored' if stored else f'{took:.1f} s'}{', failed' if failed else ''})"
                + "".join(f", {part}" for part in self._counts()) + (f", {_clock(left)} left" if left else ""))
        if self._bar is not None:
            if _verbosity >= Verbosity.VERBOSE:
                self._bar.write(line, file=sys.stderr)
            self._bar.set_postfix_str(self._postfix(""), refresh=False)
            self._bar.update(1)
        elif _verbosity > Verbosity.QUIET:
            self._said = True
            print(line, file=sys.stderr, flush=True)

    def write(self, line: str) -> None:
        """A result line on stdout while the bar is up (the bar is redrawn under it)."""
        if self._bar is not None:
            self._bar.write(line, file=sys.stdout)
        else:
            typer.echo(line)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()  # leave=False: the line is cleared and the cursor is back at its start
            self._bar = None
        if self in _live_bars:
            _live_bars.remove(self)

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _counts(self) -> list[str]:
        """``2 running``, ``1 failed``: what a bar or a line adds when there is something to say."""
        return ([f"{self.running()} running"] if self.slots > 1 and self.running() else []) + \
            ([f"{self.failed} failed"] if self.failed else [])

    def _postfix(self, label: str) -> str:
        left = self.left_s()
        return ", ".join(filter(None, [label, *self._counts(), f"{_clock(left)} left" if left else ""]))


def close_progress_bars() -> None:
    """Close every live progress bar: what is printed next starts a fresh line."""
    for bar in list(_live_bars):
        bar.close()
