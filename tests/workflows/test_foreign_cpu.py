"""The CPU other processes use beside a timed render: the command's own busy worker is its own, a burner outside
its process tree is foreign; and which process is the command's root.

The figures are checked against each burner's own CPU ticks read over the same interval, so whatever else runs
on the machine (other tests, other users) only adds to the foreign figure and cannot make these fail; the
verdict on the figures is tests/evaluate/test_timing_quality.py's, and a compare beside outside burners is
tests/cli/test_contention.py's.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys

import pytest

from cornell_harness.workflows import foreign_cpu as fc
from cornell_harness.workflows.timing import measure
from tests.burners import cpu_ticks, outside_burners, own_burner, wait_for_cpu

pytestmark = pytest.mark.skipif(not os.path.exists("/proc/stat"), reason="the figures are read from Linux's /proc")

#: CPU ticks each burner must use inside the interval: 0.3 s, far above the counters' rounding.
BURN_TICKS = 30


def test_the_own_worker_is_own_and_the_outside_burner_is_foreign(tmp_path):
    me = os.getpid()
    others = fc.cpu_snapshot(me, start=True).processes  # this process and what earlier tests left it (a tracker)
    with outside_burners(1, tmp_path) as (outside,), own_burner() as worker:
        before = fc.cpu_snapshot(me, start=True)
        worker0, outside0, self0 = cpu_ticks(worker), cpu_ticks(outside), cpu_ticks(me)
        wait_for_cpu([worker, outside], BURN_TICKS)
        worker1, outside1, self1 = cpu_ticks(worker), cpu_ticks(outside), cpu_ticks(me)
        after = fc.cpu_snapshot(me, start=False)
    own = after.own - before.own
    # The tree's figure is this process's and its worker's, read over a slightly wider interval; not the burner's.
    expected = (worker1 - worker0) + (self1 - self0)
    assert expected - 3 <= own <= expected + 3 + fc.ROUNDING_TICKS, (own, expected, outside1 - outside0)
    assert before.processes == after.processes == others + 1  # and its worker
    # Everything busy and not the tree's: the burner's ticks at least, whatever else ran.
    foreign_ticks = fc.foreign_cpu_seconds(before, after) * os.sysconf("SC_CLK_TCK")
    assert foreign_ticks >= (outside1 - outside0) - fc.ROUNDING_TICKS - 2 - 3, (foreign_ticks, outside1 - outside0)
    assert fc.foreign_cores(before, after) == pytest.approx(
        fc.foreign_cpu_seconds(before, after) / (after.at - before.at))


def test_a_child_that_ends_inside_the_interval_stays_counted_as_own():
    """Its CPU moves from its own figure to its parent's cutime when it is waited for: counted once, as own."""
    before = fc.cpu_snapshot(os.getpid(), start=True)  # this process and what earlier tests left it
    done = subprocess.run([sys.executable, "-c", "import time\nt = time.process_time()\n"
                           "while time.process_time() - t < 0.3: pass"], check=True)
    after = fc.cpu_snapshot(os.getpid(), start=False)
    assert done.returncode == 0 and after.processes == before.processes  # the ended child is not one of them
    assert after.own - before.own >= 30  # its 0.3 s of CPU, through this process's cutime


def test_measure_records_the_foreign_cpu():
    _, timing = measure(lambda: sum(range(10_000)))
    assert math.isfinite(timing.foreign_cpu) and timing.foreign_cpu >= 0


def test_the_root_is_the_named_ancestor_else_this_process(monkeypatch):
    me = os.getpid()
    monkeypatch.delenv(fc.ROOT_ENV, raising=False)
    assert fc.command_root() == me
    monkeypatch.setenv(fc.ROOT_ENV, str(os.getppid()))  # an ancestor: the command's root
    assert fc.command_root() == os.getppid()
    fc.mark_command_root()  # an ancestor is already the root: kept
    assert os.environ[fc.ROOT_ENV] == str(os.getppid())
    with own_burner() as child:  # no ancestor of this process: a stale value, inherited from elsewhere
        monkeypatch.setenv(fc.ROOT_ENV, str(child))
        assert fc.command_root() == me
    monkeypatch.setenv(fc.ROOT_ENV, "not a pid")
    assert fc.command_root() == me
    fc.mark_command_root()
    assert os.environ[fc.ROOT_ENV] == str(me)


def test_a_child_started_by_the_command_inherits_its_root(monkeypatch):
    monkeypatch.setenv(fc.ROOT_ENV, str(os.getpid()))
    code = "from cornell_harness.workflows.foreign_cpu import command_root; print(command_root())"
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert int(out.stdout) == os.getpid()


def test_no_snapshot_no_figure():
    snap = fc.CpuSnapshot(1.0, 100, 10, 1)
    assert math.isnan(fc.foreign_cores(None, snap)) and math.isnan(fc.foreign_cores(snap, None))
    assert math.isnan(fc.foreign_cores(snap, snap))  # no time between
