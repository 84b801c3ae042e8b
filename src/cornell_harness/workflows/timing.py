"""What a timed render records beside its wall time: the machine's load, a calibration kernel, the CPU time.

One wall-clock sample per cell cannot tell a slow renderer from a
busy machine. :func:`measure` runs a render between two readings of the
machine and returns :class:`Timing`, which becomes the results columns of
:data:`cornell_harness.evaluate.timing_quality.TIMING_COLUMNS` (the verdict on them
lives there):

- **foreign CPU** (:mod:`cornell_harness.workflows.foreign_cpu`): the cores'
  worth of CPU that processes outside the command's own process tree used
  while the render was measured. The verdict reads it where it is known,
  because it alone tells the command's own work (its workers, children,
  thread pools) from other work; the load and the calibration kernel below
  cannot, and are kept as figures, and as the verdict where it is not known.
- **load** (:func:`machine_load`): the runnable threads on the machine now,
  the measuring thread included, read from ``procs_running`` in
  ``/proc/stat`` (proc(5): "number of processes in runnable state", i.e.
  threads running or waiting for a core) and averaged over
  :data:`LOAD_SAMPLES` readings :data:`LOAD_GAP_S` apart, because one
  reading is a single instant. Not the load average (``os.getloadavg``):
  it is an exponentially damped average with a one-minute time constant,
  so a burst of competing work during a cell of a few seconds moves it by
  a few percent and it still shows work that ended a minute ago. The load
  average is only the fallback where ``/proc/stat`` is absent (macOS).
- **calibration** (:func:`calibration_seconds`): a fixed, deterministic,
  single-threaded pure-Python loop of about 20 ms, timed on the wall clock
  just before and just after the render. Its work never changes, so on one
  machine its time changes only when something else holds the core; a
  pure-Python loop (no memory traffic, no library threads) loses time in
  proportion to the share of a core it loses. Measured on the 2-core
  development machine (a virtual machine; docs/timing.md): quiet, median 21.6 ms,
  but one kernel in ten takes 1.5x that (a neighbour's burst, a stolen
  tick); beside two CPU burners, median 28-47 ms. (Shorter kernels, 1-4 ms,
  whose median over repeats was tried, mostly run between two preemptions
  and miss the contention.) The cell's figure
  is the **faster** of the two timings: contention that lasts through the
  cell slows both, while a single preemption at either end (which the
  slower of the two, or the mean, would carry) must not flag a quiet cell
  against :data:`cornell_harness.evaluate.timing_quality.SLOWDOWN_LIMIT`; the load
  readings catch the contention itself.
- **CPU time**: this process's CPU time, all its threads
  (:func:`time.process_time`; Mitsuba's LLVM threads are this process's),
  plus its finished children's (:func:`os.times`; a child counts once
  waited for: a command-line renderer's program). Beside two burners on
  2 cores the renderers' CPU times moved by 1-5% while their wall times
  doubled (tests/cli/test_contention.py).
  :class:`cornell_harness.adapters.api.Stopwatch` gives it for the render proper;
  :func:`measure` gives it for the whole render call, the fallback for a
  renderer that does not report its own.

Kept light (no pandas, no SciPy): the sandbox's child process imports it.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import asdict, dataclass
from typing import Callable, TypeVar

from cornell_harness.adapters.api import Stopwatch
from cornell_harness.workflows.foreign_cpu import cpu_snapshot, foreign_cores

#: Readings of ``procs_running`` averaged into one load figure, and the seconds between two.
LOAD_SAMPLES = 5
LOAD_GAP_S = 0.002
#: Seconds :func:`settle` waits at most for this process's own threads to go idle.
SETTLE_S = 0.25
#: Iterations of the calibration loop (about 20 ms on a 2020s core).
CALIBRATION_STEPS = 200_000

T = TypeVar("T")


def _procs_running() -> int | None:
    """``procs_running`` of ``/proc/stat`` (runnable threads now, the reader included), or None without it."""
    try:
        with open("/proc/stat", "rb") as f:
            for line in f:
                if line.startswith(b"procs_running"):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return None


def own_runnable_threads() -> int | None:
    """This process's threads that are runnable now (state R in ``/proc/self/task/*/stat``), the calling one
    included; None without ``/proc``."""
    try:
        tasks = os.listdir("/proc/self/task")
    except OSError:
        return None
    n = 0
    for tid in tasks:
        try:
            with open(f"/proc/self/task/{tid}/stat", "rb") as f:
                n += f.read().rpartition(b")")[2].split()[0] == b"R"
        except (OSError, IndexError):
            continue  # a thread that ended since the listing
    return n


def settle(timeout_s: float = SETTLE_S, gap_s: float = LOAD_GAP_S) -> None:
    """Wait, at most ``timeout_s``, until no other thread of this process is runnable: a renderer's thread pool
    may spin on after its render (Mitsuba's worker thread stays runnable about 20 ms, measured), and a load
    reading or calibration kernel then would count the harness's own render as the machine's load."""
    deadline = time.perf_counter() + timeout_s
    while (own_runnable_threads() or 1) > 1 and time.perf_counter() < deadline:
        time.sleep(gap_s)


def machine_load(samples: int = LOAD_SAMPLES, gap_s: float = LOAD_GAP_S) -> float:
    """Runnable threads on the machine now, the measuring thread included and this process's others not:
    ``procs_running`` less this process's other runnable threads (:func:`own_runnable_threads`), averaged
    over ``samples`` readings ``gap_s`` apart; the one-minute load average where ``/proc/stat`` is absent,
    NaN where neither is."""
    readings = []
    for i in range(samples):
        if i:
            time.sleep(gap_s)
        value = _procs_running()
        if value is None:
            break
        readings.append(value - max((own_runnable_threads() or 1) - 1, 0))
    if readings:
        return sum(readings) / len(readings)
    try:
        return float(os.getloadavg()[0])
    except (OSError, AttributeError):
        return math.nan


def calibration_kernel(steps: int = CALIBRATION_STEPS) -> int:
    """The calibration work: a fixed integer recurrence (a linear congruential generator, folded), pure Python
    on one thread; returns its result so the work is checkable (the same ``steps``, the same value)."""
    x, acc = 12345, 0
    for _ in range(steps):
        x = (x * 1103515245 + 12345) & 0x7FFFFFFF
        acc ^= x >> 7
    return acc


def calibration_seconds(steps: int = CALIBRATION_STEPS) -> float:
    """Wall seconds of :func:`calibration_kernel` now: the machine's speed for one thread at this moment."""
    t0 = time.perf_counter()
    calibration_kernel(steps)
    return time.perf_counter() - t0


@dataclass
class Timing:
    """The figures of one timed call: its wall and CPU time (the whole call), and the machine around it."""

    wall_s: float
    cpu_s: float
    load_before: float
    load_after: float
    calibration_s: float  # the faster of the kernel's timings just before and just after
    foreign_cpu: float = math.nan  # cores' worth of CPU other processes used meanwhile (foreign_cpu.py)

    def as_dict(self) -> dict:
        return asdict(self)


def measure(call: Callable[[], T]) -> tuple[T, Timing]:
    """``call()`` between two readings of the machine: its value and its :class:`Timing`.

    Order: calibration, load, the call, load, calibration, so that each load reading is the one nearest
    the call; each side after :func:`settle`, so that the readings are of the machine, not of this process.
    The CPU other processes used (:mod:`cornell_harness.workflows.foreign_cpu`) is read over all of it, the
    calibration kernels included: a longer interval than a short render's, whose few ticks the counters'
    rounding would swamp. An exception in ``call`` propagates (nothing is recorded for a failed render).
    """
    settle()
    start = cpu_snapshot(start=True)
    cal_before = calibration_seconds()
    load_before = machine_load()
    watch = Stopwatch()
    value = call()
    wall, cpu = watch.wall(), watch.cpu()
    settle()
    load_after = machine_load()
    cal_after = calibration_seconds()
    foreign = foreign_cores(start, cpu_snapshot(start=False))
    return value, Timing(wall, cpu, load_before, load_after, min(cal_before, cal_after), foreign)
