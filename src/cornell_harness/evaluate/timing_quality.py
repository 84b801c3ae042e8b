"""Timing quality: whether an experiment's times were taken on a machine busy with other work.

Every timed render records, beside its wall time, the CPU other processes
used meanwhile, the machine's load just before and after it and a
calibration figure (:func:`cornell_harness.workflows.timing.measure` measures
them; the columns are :data:`TIMING_COLUMNS`). This module reads them back
and says whether the times can be trusted as they are:

- **foreign CPU**: ``foreign_cpu`` is the cores' worth of CPU that processes
  outside the command's own process tree used while the render was
  measured (:mod:`cornell_harness.workflows.foreign_cpu`). The render competed
  for the cores when ``foreign_cpu + threads > cores + LOAD_MARGIN``. The
  command's own work (its Dask workers, a sandbox's child, a renderer's
  program or thread pool) is never counted: a demo on a quiet machine is
  not busy with itself. Where a row has this figure, it alone decides.
- **load** (rows without it: no ``/proc``, or results written before it
  was recorded): ``load_before`` / ``load_after`` count the machine's
  runnable threads at that moment, the measuring thread included. During
  the render that thread is the render's own ``threads``, so the render
  competed for the cores when ``load - 1 + threads > cores + LOAD_MARGIN``.
- **calibration** (the same rows): ``calibration_s`` is a fixed,
  deterministic compute kernel timed around the render; a cell whose
  kernel ran more than :data:`SLOWDOWN_LIMIT` times slower than the run's
  fastest was timed on a slowed machine. Neither the load nor the kernel
  can tell the command's own other processes from another command's, which
  is why the foreign CPU, where known, replaces them.

A contended run's wall times are inflated by an unknown factor; its CPU
times (``cpu_time_s``, ``--time-basis cpu``) are not (docs/timing.md says
when to prefer them, measured).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

#: The columns a timed row holds beside ``time_s`` (all seconds except the loads and the thread count).
TIMING_COLUMNS = ("cpu_time_s", "setup_s", "threads", "load_before", "load_after", "calibration_s", "foreign_cpu")
#: Threads (or cores' worth of other processes' CPU) beyond the cores that count as contention: less is a
#: passing process (a shell, a log rotation), not a competitor for the render's cores.
LOAD_MARGIN = 0.5
#: A calibration kernel this many times slower than the run's fastest says the machine was busy (docs/timing.md).
SLOWDOWN_LIMIT = 1.2


@dataclass(frozen=True)
class TimingQuality:
    """The verdict on one experiment's times, with the figures behind it."""

    rows: int  # timed rows that carry load and calibration figures
    contended: int  # of those, rows timed while the machine was busy
    max_load: float  # the highest load_before / load_after seen (runnable threads, the measuring one included)
    threads: int  # the most threads one render used
    cores: int
    calibration_slowdown: float  # slowest calibration kernel / fastest, over the run (NaN without them)
    max_foreign: float = math.nan  # the most cores' worth of CPU other processes used beside a render (NaN: unknown)

    @property
    def known(self) -> bool:
        """Whether the rows recorded the figures at all (results written before they were)."""
        return self.rows > 0

    @property
    def ok(self) -> bool:
        """No row was timed on a busy machine (True when nothing is known: nothing says otherwise)."""
        return self.contended == 0

    def figures(self) -> str:
        """The figures behind the verdict, one phrase."""
        slow = "" if math.isnan(self.calibration_slowdown) else \
            f", calibration kernel up to {self.calibration_slowdown:.2f}x its fastest"
        if not math.isnan(self.max_foreign):
            return (f"{self.contended} of {self.rows} timed renders contended; other processes used up to "
                    f"{self.max_foreign:.2f} cores beside renders of {self.threads} threads on {self.cores} cores")
        return (f"{self.contended} of {self.rows} timed renders contended; load up to {self.max_load:.1f} runnable "
                f"threads beside renders of {self.threads} on {self.cores} cores{slow}")

    def line(self) -> str:
        """One line for the CLI: a warning when contended, else a plain statement."""
        if not self.known:
            return "timing quality unknown: these results carry no load or calibration figures"
        if self.ok:
            return f"timing quality good: {self.figures()}"
        return (f"warning: the machine was busy while timing ({self.figures()}); wall times are inflated, "
                "compare them with --time-basis cpu or rerun on a quiet machine")


def _column(runs: pd.DataFrame, name: str) -> np.ndarray:
    return runs[name].to_numpy(float) if name in runs else np.full(len(runs), math.nan)


def contended_rows(runs: pd.DataFrame, cores: int) -> np.ndarray:
    """Per row of ``runs``: True where the CPU other processes used beside it says the machine was busy, or,
    for a row without that figure, its load or its calibration kernel does.

    Rows without any of the figures (NaN) are never counted as contended.
    """
    if runs.empty:
        return np.zeros(0, bool)
    threads = np.nan_to_num(_column(runs, "threads"), nan=1.0)
    foreign = _column(runs, "foreign_cpu")
    busy_foreign = np.nan_to_num(foreign + threads, nan=0.0) > cores + LOAD_MARGIN
    load = np.fmax(_column(runs, "load_before"), _column(runs, "load_after"))
    busy_load = np.nan_to_num(load - 1.0 + threads, nan=0.0) > cores + LOAD_MARGIN
    cal = _column(runs, "calibration_s")
    fastest = np.nanmin(cal) if np.isfinite(cal).any() else math.nan
    busy_cal = np.nan_to_num(cal / fastest, nan=0.0) > SLOWDOWN_LIMIT if fastest > 0 else np.zeros(len(runs), bool)
    return np.where(np.isfinite(foreign), busy_foreign, busy_load | busy_cal)


def auto_basis(runs: pd.DataFrame, cores: int) -> str:
    """``--time-basis auto``: "cpu" where any timed row of ``runs`` was contended (wall time is then inflated by
    other work, CPU time is not), else "wall"."""
    return "cpu" if timing_quality(runs, cores).contended else "wall"


def timing_quality(runs: pd.DataFrame, cores: int) -> TimingQuality:
    """The verdict on the timed rows of ``runs`` (an experiment's results table) on a machine of ``cores``."""
    if "status" in runs:
        runs = runs[runs["status"] == "ok"]
    have = [c for c in ("load_before", "load_after", "calibration_s", "foreign_cpu") if c in runs]
    timed = runs[runs[have].notna().any(axis=1)] if have else runs.iloc[0:0]
    if timed.empty:
        return TimingQuality(0, 0, math.nan, 0, cores, math.nan)
    cal = timed["calibration_s"].to_numpy(float) if "calibration_s" in timed else np.array([math.nan])
    slowdown = float(np.nanmax(cal) / np.nanmin(cal)) if np.isfinite(cal).any() and np.nanmin(cal) > 0 else math.nan
    loads = timed[[c for c in ("load_before", "load_after") if c in timed]].to_numpy(float)
    threads = timed["threads"].to_numpy(float) if "threads" in timed else np.array([math.nan])
    foreign = _column(timed, "foreign_cpu")
    return TimingQuality(
        rows=len(timed), contended=int(contended_rows(timed, cores).sum()),
        max_load=float(np.nanmax(loads)) if np.isfinite(loads).any() else math.nan,
        threads=int(np.nanmax(threads)) if np.isfinite(threads).any() else 0,
        cores=int(cores), calibration_slowdown=slowdown,
        max_foreign=float(np.nanmax(foreign)) if np.isfinite(foreign).all() else math.nan)
