"""What a timed render records beside its wall time (src/cornell_harness/workflows/timing.py): the machine's load, the
calibration kernel, the CPU time of a call."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import time

import pytest

from cornell_harness.adapters.api import Stopwatch
from cornell_harness.workflows import timing

BURN = "while 1: pass"


def _cpu_ticks(pid: int) -> int:
    """utime + stime of ``pid`` in clock ticks (proc(5))."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rpartition(")")[2].split()
    return int(fields[11]) + int(fields[12])


@pytest.mark.skipif(not os.path.exists("/proc/stat"), reason="procs_running is Linux's /proc/stat")
def test_machine_load_counts_the_measuring_thread_and_two_burners():
    """Runnable threads now: this one at least, and two CPU burners beside it at least 3 (they are runnable
    whether or not they hold a core), whatever else the machine runs."""
    assert timing.machine_load() >= 1.0
    burners = [subprocess.Popen([sys.executable, "-c", BURN]) for _ in range(2)]
    try:
        deadline = time.monotonic() + 30
        while any(_cpu_ticks(b.pid) < 2 for b in burners) and time.monotonic() < deadline:
            time.sleep(0.02)  # each has started its loop
        load = timing.machine_load()
    finally:
        for b in burners:
            b.kill()
            b.wait()
    assert 3.0 <= load < 3.0 + 64, load


@pytest.mark.skipif(not os.path.exists("/proc/self/task"), reason="threads' states are Linux's /proc")
def test_this_process_own_spinning_thread_is_not_the_machines_load(monkeypatch):
    """A thread of this process still running (a renderer's pool spinning after its render: Mitsuba's does for
    about 20 ms) is counted by own_runnable_threads, left out of machine_load, and waited for by settle."""
    import hashlib
    import threading

    stop, data = threading.Event(), bytes(1 << 22)

    def spin():  # hashing a large buffer runs in C without the GIL: the thread stays runnable
        while not stop.is_set():
            hashlib.sha256(data).digest()

    worker = threading.Thread(target=spin)
    worker.start()
    try:
        time.sleep(0.05)
        own = max(timing.own_runnable_threads() for _ in range(20))
        monkeypatch.setattr(timing, "_procs_running", lambda: 5)  # the machine's count, this process's included
        load = timing.machine_load(samples=20)
        monkeypatch.undo()
        t0 = time.perf_counter()
        timing.settle(timeout_s=0.2)
        waited = time.perf_counter() - t0
    finally:
        stop.set()
        worker.join()
    assert own >= 2, own
    assert load < 5, load  # the spinning thread is taken out of the machine's count
    assert waited >= 0.15  # it never went idle: settle waited to its limit
    t0 = time.perf_counter()
    timing.settle(timeout_s=0.2)
    assert time.perf_counter() - t0 < 0.15  # idle now: no wait


def test_machine_load_falls_back_on_the_load_average(monkeypatch):
    monkeypatch.setattr(timing, "_procs_running", lambda: None)
    assert timing.machine_load() == pytest.approx(os.getloadavg()[0], abs=0.5)
    monkeypatch.setattr(timing.os, "getloadavg", lambda: (_ for _ in ()).throw(OSError("none here")))
    assert math.isnan(timing.machine_load())


def test_calibration_kernel_does_fixed_work():
    """The same work every time (its result pinned), and a time that is a small fraction of a second."""
    assert timing.calibration_kernel(1000) == timing.calibration_kernel(1000) == 2727387
    assert timing.calibration_kernel(1001) != timing.calibration_kernel(1000)
    assert 0.0 < timing.calibration_seconds() < 2.0


def test_measure_records_the_call_and_the_machine_around_it(monkeypatch):
    """Calibration, load, the call, load, calibration; the faster calibration is the figure."""
    order = []
    loads, cals = iter([2.0, 3.5]), iter([0.030, 0.020])
    monkeypatch.setattr(timing, "machine_load", lambda: order.append("load") or next(loads))
    monkeypatch.setattr(timing, "calibration_seconds", lambda: order.append("cal") or next(cals))

    def call():
        order.append("call")
        t0 = time.process_time()
        while time.process_time() - t0 < 0.1:
            pass
        return "image"

    value, t = timing.measure(call)
    assert value == "image" and order == ["cal", "load", "call", "load", "cal"]
    assert (t.load_before, t.load_after, t.calibration_s) == (2.0, 3.5, 0.020)
    assert 0.1 <= t.cpu_s and 0.1 <= t.wall_s < 30
    assert set(t.as_dict()) == {"wall_s", "cpu_s", "load_before", "load_after", "calibration_s", "foreign_cpu"}


def test_stopwatch_counts_a_waited_for_childs_cpu():
    """A child that burns 0.3 s of CPU: the stopwatch's CPU time has it once the child has been waited for."""
    watch = Stopwatch()
    subprocess.run([sys.executable, "-c", "import time\nwhile time.process_time() < 0.3: pass"], check=True)
    wall, cpu = watch.read()
    assert 0.3 <= cpu < 0.3 + 5.0 and wall > 0
