"""Sweeps and references on Dask: a real cluster on loopback (a ``dask scheduler`` and ``dask worker`` processes),
a LocalCluster (``--workers 2``), a worker killed mid-sweep; every backend gives what the in-process run gives."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tests.conftest import CORNELL, ROOT

pytest.importorskip("distributed")

from cornell_harness.adapters.registry import resolve  # noqa: E402
from cornell_harness.evaluate.timing_quality import TIMING_COLUMNS  # noqa: E402
from cornell_harness.scenes.library import resolve_scene  # noqa: E402
from cornell_harness.store.experiments import RESULTS_FILE  # noqa: E402
from cornell_harness.store.exr import read_exr  # noqa: E402
from cornell_harness.store.references import load_reference  # noqa: E402
from cornell_harness.workflows.converge import run_experiment
from cornell_harness.workflows.spp_list import parse_spp_list  # noqa: E402
from cornell_harness.workflows.executor import DEFAULT_RETRIES, Task, open_executor, task_key  # noqa: E402
from cornell_harness.workflows.reference_build import build_reference  # noqa: E402

DASK = Path(sys.executable).parent / "dask"
#: Measured (times), or where the cell ran (its threads, how Mitsuba found LLVM there): the only columns
#: allowed to differ between backends.
RUN_COLUMNS = ["time_s", "efficiency", "info_setup_s", "info_threads", "info_variant_note", "info_cpu_time_of",
               *TIMING_COLUMNS,
               # the timings behind time_s (cornell_harness.evaluate.timing_stats.repeat_columns)
               "time_samples_s", "time_s_low", "time_s_high", "cpu_time_samples_s", "cpu_time_s_low", "cpu_time_s_high"]
#: Ours, built on Embree in the worker, and a user's renderer loaded there by module:Class (cheap: Mitsuba, whose
#: import and JIT cost seconds per worker, renders the reference batches and a gate expectation below).
RENDERERS = ["pathtracer", "tests.user_renderers:SeededNoise"]
SPP = "1-16"
SEEDS = [0, 1]
#: Only a guard against a hang: a scheduler or worker starts in seconds on a quiet machine, more under load
#: (two CPU burners, a shared CI runner), never near this.
START_TIMEOUT_S = 300


def _env(**extra: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "CBOX_THREADS"}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    return {**env, **extra}


class LoopbackCluster:
    """``dask scheduler`` and ``dask worker`` processes on 127.0.0.1, each a process of its own (no nanny: a
    worker's PID is the process that runs its tasks)."""

    def __init__(self, folder: Path, env: dict):
        self.folder, self.env = folder, env
        self.file = folder / "scheduler.json"
        self.procs: list[subprocess.Popen] = []
        self.scheduler = self._start([str(DASK), "scheduler", "--host", "127.0.0.1", "--port", "0",
                                      "--no-dashboard", "--scheduler-file", str(self.file)], "scheduler")
        deadline = time.monotonic() + START_TIMEOUT_S
        # The file is written after it is created: on a busy machine it can be read empty, so wait for its address.
        while (address := self._address()) is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert address, f"no scheduler address in {self.file} after {START_TIMEOUT_S} s"
        self.address = address

    def _address(self) -> str | None:
        import json

        try:
            return json.loads(self.file.read_text())["address"]
        except (OSError, ValueError, KeyError):
            return None

    def _start(self, cmd: list[str], name: str) -> subprocess.Popen:
        log = open(self.folder / f"{name}-{len(self.procs)}.log", "w")
        proc = subprocess.Popen(cmd, cwd=ROOT, env=self.env, stdout=log, stderr=subprocess.STDOUT)
        self.procs.append(proc)
        return proc

    @property
    def workers(self) -> list[subprocess.Popen]:
        return [p for p in self.procs[1:] if p.poll() is None]

    def add_worker(self) -> subprocess.Popen:
        return self._start([str(DASK), "worker", "--scheduler-file", str(self.file), "--host", "127.0.0.1",
                            "--nthreads", "1", "--no-nanny", "--no-dashboard", "--death-timeout", "60"], "worker")

    def wait_for_workers(self, n: int) -> None:
        from distributed import Client

        with Client(self.address, timeout=START_TIMEOUT_S) as client:
            client.wait_for_workers(n, timeout=START_TIMEOUT_S)

    def close(self) -> None:
        """Killed: nothing of theirs is kept, and a graceful Dask shutdown takes seconds."""
        for proc in self.procs:
            if proc.poll() is None:
                proc.kill()
            proc.wait()


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("distributed")


@pytest.fixture(scope="module")
def render_log(workdir) -> Path:
    return workdir / "renders.log"


@pytest.fixture(scope="module")
def cluster(workdir, render_log):
    c = LoopbackCluster(workdir, _env(CBOX_TEST_RENDER_LOG=str(render_log), CBOX_TEST_RENDER_SLEEP="0.5",
                                      CBOX_TEST_RENDER_HOLD_PIDS=str(workdir / "hold-pids"),
                                      DASK_TEMPORARY_DIRECTORY=str(workdir / "dask-scratch")))  # killed: kept here
    try:
        c.add_worker()
        c.add_worker()
        c.wait_for_workers(2)
        yield c
    finally:
        c.close()


@pytest.fixture(scope="module")
def small_scene(workdir):
    """The Cornell box at 32 × 32 pixels, in a folder of its own, with a reference of its own (Mitsuba, in this
    process): small enough that a cell takes milliseconds once a worker has its renderers loaded."""
    folder = workdir / "small-box"
    folder.mkdir()
    text = CORNELL.read_text().replace("resolution = [256, 256]", "resolution = [32, 32]")
    assert "resolution = [32, 32]" in text
    (folder / "scene.toml").write_text(text.replace('name = "cornell-box"', 'name = "small-box"'))
    scene = resolve_scene(str(folder))
    (mitsuba,) = resolve(["mitsuba"])
    build_reference(scene, spp=8, batches=2, entry=mitsuba)
    return scene


@pytest.fixture(scope="module")
def in_process(workdir, small_scene) -> Path:
    """The converge of the issue, in this process: the table every backend must give."""
    out = workdir / "in-process"
    run_experiment(out, small_scene, load_reference(small_scene), resolve(RENDERERS), parse_spp_list(SPP), SEEDS)
    return out


def assert_same_experiment(a: Path, b: Path) -> None:
    """The same results table (but :data:`RUN_COLUMNS`) and the same final images, bit for bit."""
    ta, tb = pd.read_parquet(a / RESULTS_FILE), pd.read_parquet(b / RESULTS_FILE)
    assert len(ta) == len(RENDERERS) * len(SEEDS) * 5 and (ta["status"] == "ok").all(), ta[["renderer", "status"]]
    assert list(ta.columns) == list(tb.columns)
    pd.testing.assert_frame_equal(ta.drop(columns=RUN_COLUMNS, errors="ignore"),
                                  tb.drop(columns=RUN_COLUMNS, errors="ignore"), check_exact=True)
    names = sorted(p.name for p in (a / "images").glob("*.exr"))  # a report's PNGs may lie beside them
    assert names == sorted(p.name for p in (b / "images").glob("*.exr")) and len(names) == len(RENDERERS) * len(SEEDS)
    for name in names:
        assert np.array_equal(read_exr(a / "images" / name), read_exr(b / "images" / name)), name


def test_converge_through_scheduler_equals_in_process(cluster, workdir, small_scene, in_process, capsys):
    """``cbox converge ... --scheduler tcp://127.0.0.1:PORT`` (the command, in this process): the in-process
    table and images; and a finished cell is never rendered again."""
    from cornell_harness.cli import output
    from cornell_harness.cli.app import main

    out = workdir / "scheduler"
    cluster.wait_for_workers(2)
    try:
        with pytest.raises(SystemExit) as e:
            main(["converge", "--scene", str(small_scene.path.parent), *[a for r in RENDERERS for a in ("-r", r)],
                  "--spp", SPP, "--seeds", str(len(SEEDS)), "--scheduler", cluster.address, "--out", str(out)])
    finally:
        output.set_verbosity(output.Verbosity.NORMAL)
    err = capsys.readouterr().err
    assert e.value.code == 0, err
    assert f"running on scheduler {cluster.address} (2 worker threads)" in err
    assert_same_experiment(in_process, out)
    seen = []  # the same sweep again loads every cell and submits nothing
    with open_executor(scheduler=cluster.address) as executor:
        run_experiment(out, small_scene, load_reference(small_scene), resolve(RENDERERS), parse_spp_list(SPP), SEEDS,
                       executor=executor, on_cell=lambda name, cached: seen.append(cached))
    assert seen == [True] * len(RENDERERS) * len(SEEDS)


def test_converge_on_local_workers_equals_in_process(workdir, small_scene, in_process, monkeypatch):
    """``--workers 2``: a LocalCluster of two worker processes gives the in-process table and images, and leaves
    nothing in the temporary directory (Dask keeps a dask-scratch-space there unless told otherwise)."""
    out, before = workdir / "workers", os.environ.get("OMP_NUM_THREADS")
    temp = workdir / "temp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    with open_executor(workers=2) as executor:
        assert executor.slots == 2
        threads = executor.client.run(lambda: (os.environ.get("CBOX_THREADS"), os.environ.get("OMP_NUM_THREADS")))
        run_experiment(out, small_scene, load_reference(small_scene), resolve(RENDERERS), parse_spp_list(SPP), SEEDS,
                       executor=executor)
    share = str(max(1, (os.cpu_count() or 1) // 2))
    assert list(threads.values()) == [(share, share)] * 2  # its share of the cores, for renders and metrics alike
    assert os.environ.get("OMP_NUM_THREADS") == before  # Dask's settings for its workers are not left here
    assert_same_experiment(in_process, out)
    assert sorted(p.name for p in temp.iterdir()) == []


def test_reference_batches_across_workers_equal_single_process_build(cluster, workdir, small_scene):
    """A reference built from batches on two workers is the single-process build, bit for bit."""
    (mitsuba,) = resolve(["mitsuba"])
    here = build_reference(small_scene, spp=12, batches=6, entry=mitsuba, folder=workdir / "ref-here")
    with open_executor(scheduler=cluster.address) as executor:
        there = build_reference(small_scene, spp=12, batches=6, entry=mitsuba, folder=workdir / "ref-there",
                                executor=executor)
    for what in ("image", "variance", "noise"):
        assert np.array_equal(getattr(here, what), getattr(there, what)), what
    assert np.array_equal(read_exr(workdir / "ref-here" / "reference.exr"),
                          read_exr(workdir / "ref-there" / "reference.exr"))
    assert here.provenance["seeds"] == there.provenance["seeds"]



def test_reference_verify_across_workers_equals_in_process(cluster, small_scene):
    """``cbox reference verify --workers``: the engine's batches on two workers give the in-process verdict, bit
    for bit (render_batches folds them in seed order), for the same per-region table."""
    from cornell_harness.store.references import load_reference
    from cornell_harness.workflows.reference_verify import verify_reference

    (mitsuba,) = resolve(["mitsuba"])
    ref = load_reference(small_scene)
    here = verify_reference(small_scene, ref, mitsuba, spp=8, batches=4)
    with open_executor(scheduler=cluster.address) as executor:
        there = verify_reference(small_scene, ref, mitsuba, spp=8, batches=4, executor=executor)
    assert np.array_equal(here.image, there.image) and np.array_equal(here.variance, there.variance)
    assert here.agreement.table() == there.agreement.table()

def test_killed_worker_loses_no_cell_and_duplicates_none(cluster, workdir, small_scene, render_log):
    """SIGKILL a worker while it renders a cell: the cell is rendered again elsewhere, every cell is in the
    table once, none is missing, and the run goes on.

    The victim's PID is in the hold file, so its first cell waits 600 s after logging its start: the kill
    lands mid-cell whenever this test gets to send it (a 0.5 s window once, which a busy machine could miss)."""
    victim = cluster.workers[0]
    seeds = list(range(6))
    out, result = workdir / "killed", {}
    render_log.unlink(missing_ok=True)
    (workdir / "hold-pids").write_text(f"{victim.pid}\n")

    def sweep():
        with open_executor(scheduler=cluster.address) as executor:
            result["table"] = run_experiment(out, small_scene, load_reference(small_scene),
                                             resolve(["tests.user_renderers:LoggedNoise"]), [1], seeds,
                                             executor=executor)

    thread = threading.Thread(target=sweep)
    thread.start()
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline and f"start {victim.pid} " not in (render_log.read_text()
                                                                    if render_log.exists() else ""):
        time.sleep(0.02)
    os.kill(victim.pid, signal.SIGKILL)  # mid-cell: it holds between start and end
    victim.wait()
    thread.join(timeout=START_TIMEOUT_S)  # a hang guard: the other worker's six cells take seconds
    cluster.add_worker()  # in its place, for any test after this one
    assert not thread.is_alive()
    log = [line.split() for line in render_log.read_text().splitlines()]
    victims = [(what, int(seed)) for what, pid, seed in log if pid == str(victim.pid)]
    assert victims and victims[-1][0] == "start", f"the worker was not killed mid-cell: {victims}"
    killed = victims[-1][1]
    assert [int(seed) for what, _, seed in log if what == "start"].count(killed) == 2  # again, on another worker
    ended = sorted(int(seed) for what, pid, seed in log if what == "end")
    assert ended == seeds, ended  # every cell completed once, the one on the dead worker included
    table = result["table"]
    assert (table["status"] == "ok").all(), table[["seed", "status", "reason"]]
    assert sorted(zip(table["seed"], table["spp"])) == [(s, 1) for s in seeds]
    stored = pd.read_parquet(out / RESULTS_FILE)
    assert not stored.duplicated(["renderer", "seed", "spp"]).any()
    assert sorted(zip(stored["seed"], stored["spp"])) == [(s, 1) for s in seeds]
    assert sorted(p.name for p in (out / "cells").iterdir()) == [f"logged-noise__seed{s}.parquet" for s in seeds]


def test_repeats_on_the_cluster_are_stored_and_not_redone(cluster, workdir, small_scene):
    """--time-repeats on workers: every cell's final checkpoint gets its K timings (in the scheduler's order),
    the images repeat bit for bit, and the same run again submits nothing."""
    out, scene = workdir / "repeats", small_scene
    with open_executor(scheduler=cluster.address) as executor:
        table = run_experiment(out, scene, load_reference(scene), resolve(["tests.user_renderers:Clocked"]), [1, 4],
                               SEEDS, executor=executor, time_repeats=3)
        repeats = []
        run_experiment(out, scene, load_reference(scene), resolve(["tests.user_renderers:Clocked"]), [1, 4], SEEDS,
                       executor=executor, time_repeats=3, on_repeat=lambda name, stored: repeats.append(stored))
    top = table[table["spp"] == 4]
    assert (top["time_repeats"] == 3).all() and (table[table["spp"] == 1]["time_repeats"] == 1).all()
    assert top["time_samples_s"].tolist() == ["[0.5, 0.5, 0.5]"] * len(SEEDS)  # Clocked's own clock
    assert "info_repeat_images_differ" not in table and repeats == [True] * 2 * len(SEEDS)


def test_task_that_raises_is_retried_then_recorded_and_the_rest_go_on(cluster, workdir):
    """A task that raises on a worker is tried 1 + DEFAULT_RETRIES times, then ends with its reason; the others
    finish."""
    log = workdir / "attempts.log"

    def work(i):  # nested: shipped by value, nothing to import on the worker
        with open(log, "a") as f:
            f.write(f"{i}\n")
        if i == 1:
            raise RuntimeError("boom")
        return i * 10

    with open_executor(scheduler=cluster.address) as executor:
        outcomes = {o.task.label: o for o in executor.run([Task(task_key("test", str(log), i), str(i), work, (i,))
                                                           for i in range(3)])}
    assert (outcomes["0"].value, outcomes["2"].value) == (0, 20) and outcomes["0"].error is None
    assert outcomes["1"].error == "RuntimeError: boom" and outcomes["1"].value is None
    attempts = log.read_text().split()
    assert (attempts.count("0"), attempts.count("1"), attempts.count("2")) == (1, 1 + DEFAULT_RETRIES, 1)


def test_gate_on_cluster_gives_the_in_process_verdict(cluster, workdir, small_scene):
    """``cbox gate --scheduler``: each expectation renders on a worker, is checked in the client, and every
    metric and check is the in-process gate's (without the time-limited child process, which would start
    an interpreter per expectation; test_gate shows the child gives the same run)."""
    from cornell_harness.gate.config import load_config
    from cornell_harness.gate.run import run_gate
    from cornell_harness.workflows.runner import json_safe

    path = workdir / "gate.toml"
    path.write_text(f'''alpha = 0.01

[[expect]]
name = "path tracer"
scene = "{small_scene.path}"
renderer = "pathtracer"
spp = 16
unbiased = true
slope = [-2.0, 0.0]

[[expect]]
name = "noise"
scene = "{small_scene.path}"
renderer = "tests.user_renderers:SeededNoise"
spp = 8
max = {{ rel_mse = 10.0 }}
''')
    cfg = load_config(path)
    here = run_gate(cfg, sandbox=False)
    with open_executor(scheduler=cluster.address) as executor:
        there = run_gate(cfg, sandbox=False, executor=executor)
    assert [o.expectation.name for o in there] == ["path tracer", "noise"]
    for a, b in zip(here, there):
        assert b.record.status == "ok", b.record.reason
        assert json_safe(a.record.metrics) == json_safe(b.record.metrics)
        assert [(c.name, c.passed, c.message) for c in a.checks] == [(c.name, c.passed, c.message) for c in b.checks]


def test_options_are_checked_before_any_work(tmp_path, capsys, monkeypatch):
    """--workers with --scheduler, a malformed address, --dashboard without --workers and an unreachable
    scheduler: one line naming the option, exit 2, nothing written."""
    import dask

    from cornell_harness.cli import output
    from cornell_harness.cli.app import main

    monkeypatch.syspath_prepend(str(ROOT))
    base = ["converge", "--scene", "cornell-box", "-r", "tests.user_renderers:SeededNoise", "--spp", "1", "--seeds", "1",
            "--out", str(tmp_path / "x")]
    cases = {("--workers", "2", "--scheduler", "tcp://127.0.0.1:1"): "--scheduler: give --workers N",
             ("--scheduler", "127.0.0.1:8786"): "--scheduler: '127.0.0.1:8786' is not a scheduler address",
             ("--dashboard", ":8787"): "--dashboard: ",
             ("--scheduler", "tcp://127.0.0.1:9"): "--scheduler tcp://127.0.0.1:9: cannot connect"}
    try:
        with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
            for extra, message in cases.items():
                with pytest.raises(SystemExit) as e:
                    main(base + list(extra))
                err = capsys.readouterr().err
                assert e.value.code == 2 and err.startswith("cbox: error: ") and message in err, (extra, err)
                assert len(err.strip().splitlines()) == 1, err
    finally:
        output.set_verbosity(output.Verbosity.NORMAL)
    assert not (tmp_path / "x" / "results.parquet").exists()


def test_worker_share_of_cores_and_a_writable_numba_cache(tmp_path):
    from cornell_harness.workflows.worker_setup import numba_cache_dir, threads_per_worker

    assert [threads_per_worker(2, n) for n in (1, 2, 3)] == [2, 1, 1]  # never oversubscribed, never 0
    assert threads_per_worker(64, 4) == 16
    given = tmp_path / "given"
    assert numba_cache_dir({"NUMBA_CACHE_DIR": str(given)}) == str(given)
    assert numba_cache_dir({"XDG_CACHE_HOME": str(tmp_path / "home")}) is None  # numba's own choice works
    blocked = tmp_path / "a-file"
    blocked.write_text("")  # a file where a folder should be: nothing can be made under it, even by root
    fallback = numba_cache_dir({"NUMBA_CACHE_DIR": str(blocked / "x"), "XDG_CACHE_HOME": str(blocked)})
    assert fallback is not None and "cbox-numba-cache" in fallback


def test_progress_says_running_and_failed_cells(capsys):
    from cornell_harness.cli.output import Progress

    with Progress(4, "converge box", "cell", slots=2) as bar:
        bar.advance("pathtracer seed 0")
        bar.advance("pathtracer seed 1", failed=True)
        bar.advance("pathtracer seed 2")
    lines = capsys.readouterr().err.splitlines()
    assert lines[0].startswith("converge box: 1/4 cells, pathtracer seed 0 (") and ", 2 running" in lines[0]
    assert re.search(r"pathtracer seed 1 \(\d+\.\d s, failed\), 2 running, 1 failed", lines[1]), lines[1]
    assert ", 1 running, 1 failed" in lines[2]


def test_results_table_rewrites_are_throttled_while_cells_finish(tmp_path, monkeypatch):
    """The cells are the record; the table is rewritten as they finish, throttled (thousands of quick cells
    must not rewrite a growing table after each), and always at the end, in the planned order."""
    from cornell_harness.workflows import converge

    monkeypatch.setattr(converge, "RESULTS_EVERY_S", 60.0)  # no slow machine lets a minute pass below
    table = converge._Table(tmp_path / RESULTS_FILE)
    table.frames = [None, pd.DataFrame({"seed": [0]})]
    assert table.write(now=False) is not None  # the first finished cell writes
    table.frames[0] = pd.DataFrame({"seed": [1]})
    assert table.write(now=False) is None  # the next, within RESULTS_EVERY_S, does not
    assert pd.read_parquet(tmp_path / RESULTS_FILE)["seed"].tolist() == [0]
    assert table.write()["seed"].tolist() == [1, 0]  # the end: every cell, in planned order
    assert pd.read_parquet(tmp_path / RESULTS_FILE)["seed"].tolist() == [1, 0]
