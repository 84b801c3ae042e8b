"""Where a workflow's independent units of work run: in this process, on a local Dask cluster, or on a remote one.

Three backends behind one interface (:class:`InProcess`, :class:`DaskExecutor`,
opened by :func:`open_executor` from the CLI's ``--workers`` / ``--scheduler``):

- in-process (the default): tasks run here, one after another, in the order
  given; an exception propagates, as it always did;
- ``--workers N``: a Dask ``LocalCluster`` of N worker processes of one thread
  each on this machine, on loopback, without a dashboard unless asked;
- ``--scheduler tcp://HOST:PORT``: an existing Dask cluster.

A :class:`Task` is a module-level function and its arguments, named by a
content-hash ``key``: Dask runs one key once at a time (a second submission
of it waits for the first), so the same cell is never rendered twice at
once. What the work *is* (a cell of a sweep, a batch of a reference, an
expectation of the gate) is the workflows' business; this module runs it and
says how it ended. On Dask a task's value comes back compressed (:func:`pack`,
lossless: a cell's rows and float32 image as zlib'd pickle); a task that
raises is retried ``retries`` times, one whose worker dies is rescheduled up
to the scheduler's ``allowed-failures``; then it ends as an :class:`Outcome`
with the reason, and the rest go on. Values come back as tasks finish, in any
order; the caller alone writes files.

Workers are set up by :mod:`cornell_harness.workflows.worker_setup` (every worker,
those that join later too): ``CBOX_THREADS`` is the worker's share of its
machine's cores (N workers on N cores do not oversubscribe), and numba gets a
writable cache.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import pickle
import tempfile
import zlib
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Iterator

from cornell_harness.extras import require

#: Retries of a task that raised on a worker (a worker's death counts against ``allowed-failures`` instead).
DEFAULT_RETRIES = 2
#: Times a task may be on a worker that dies before it is recorded as failed (Dask's ``allowed-failures``,
#: set on a LocalCluster's scheduler; an existing cluster keeps its own).
ALLOWED_FAILURES = 2
#: Seconds to wait for a ``--scheduler`` to answer, at most (less where Dask's ``comm.timeouts.connect`` says less).
CONNECT_TIMEOUT_S = 10


class ExecutorError(RuntimeError):
    """A backend cannot be used as asked (no such scheduler, no workers). ``str()`` says why."""


def task_key(kind: str, *parts: Any) -> str:
    """A Dask-safe key for ``kind`` (``cell``, ``batch``) from the JSON of ``parts``: the same parts, the same key."""
    digest = hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()
    return f"cbox-{kind}-{digest[:32]}"


@dataclass(frozen=True)
class Task:
    """One unit of work: ``fn(*args)``, ``fn`` importable on a worker (module level), named ``key``."""

    key: str
    label: str  # for progress: "pathtracer seed 2"
    fn: Callable
    args: tuple = ()


@dataclass
class Outcome:
    """How a task ended: its value, or (``error`` set) why it failed after its retries."""

    task: Task
    value: Any = None
    error: str | None = None


class InProcess:
    """Tasks run here, in order; an exception propagates (today's behaviour: a renderer's own failure is
    already a failed row, so an exception here is a harness bug)."""

    name = "in-process"
    slots = 1  # tasks running at once
    local = True  # tasks may take this process's objects (a loaded renderer) as arguments

    def share(self, obj: Any) -> Any:
        """A handle on ``obj`` for the tasks' arguments: here the object itself."""
        return obj

    def run(self, tasks: Iterable[Task]) -> Iterator[Outcome]:
        for task in tasks:
            yield Outcome(task, task.fn(*task.args))


class DaskExecutor:
    """Tasks on a Dask cluster through ``client``; outcomes as they finish, failures recorded, not raised."""

    local = False  # tasks get plain data and load what they need on the worker

    def __init__(self, client: Any, name: str, retries: int = DEFAULT_RETRIES):
        self.client, self.name, self.retries = client, name, retries
        self.bytes_back: list[int] = []  # the packed size of each result received, for measurements

    @property
    def slots(self) -> int:
        return max(1, sum(self.client.nthreads().values()))

    def share(self, obj: Any) -> Any:
        """``obj`` sent once to every worker (a future the tasks take as an argument): a scene or a reference
        travels once per worker, not once per task. No shared filesystem is assumed."""
        return self.client.scatter([obj], broadcast=True, hash=False)[0]

    def run(self, tasks: Iterable[Task]) -> Iterator[Outcome]:
        from distributed import as_completed

        tasks = list(tasks)
        futures = {self.client.submit(run_packed, t.fn, *t.args, key=t.key, pure=False, retries=self.retries): t
                   for t in tasks}
        for future in as_completed(futures):
            task = futures[future]
            if future.status == "finished":
                data = future.result()
                self.bytes_back.append(len(data))
                outcome = Outcome(task, unpack(data))
            else:
                outcome = Outcome(task, error=_reason(future))
            future.release()  # the worker may drop the result: the caller holds it now
            yield outcome


def run_packed(fn: Callable, *args: Any) -> bytes:
    """``fn(*args)`` packed: what a Dask worker runs for a task, so every result travels compressed."""
    return pack(fn(*args))


def pack(value: Any) -> bytes:
    """``value`` as compressed bytes, what a worker sends back (lossless: float32 images stay float32)."""
    return zlib.compress(pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL), 1)


def unpack(data: bytes) -> Any:
    """:func:`pack` undone."""
    return pickle.loads(zlib.decompress(data))


def _reason(future: Any) -> str:
    """One line on why a future did not finish: the task's exception, or the cluster's (a worker died)."""
    try:
        error = future.exception(timeout=5)
    except Exception as e:  # cancelled, or the cluster went away
        error = e
    if error is None:
        return f"task {future.status}"
    text = " ".join(str(error).split())
    return f"{type(error).__name__}: {text}" if text else type(error).__name__


@contextlib.contextmanager
def open_executor(workers: int | None = None, scheduler: str | None = None, dashboard: str | None = None,
                  retries: int = DEFAULT_RETRIES) -> Iterator[InProcess | DaskExecutor]:
    """The backend the options ask for: none, in-process; ``workers``, a LocalCluster of that many
    one-thread worker processes on 127.0.0.1 (``dashboard``: its address, e.g. ``:8787``; none by default);
    ``scheduler``, the existing cluster at that address. Closed (a LocalCluster stopped) on exit."""
    if workers is not None and scheduler is not None:
        raise ExecutorError("give --workers or --scheduler, not both")
    if workers is None and scheduler is None:
        yield InProcess()
        return
    require("--workers" if workers is not None else "--scheduler")
    import dask
    from dask.utils import parse_timedelta
    from distributed import Client, LocalCluster

    from cornell_harness.workflows.worker_setup import (THREAD_POOL_VARIABLES, WorkerSetup, local_env,
                                                local_pre_spawn_environ, workers_by_host)

    with contextlib.ExitStack() as stack:
        if scheduler is not None:
            try:
                timeout = min(CONNECT_TIMEOUT_S, parse_timedelta(dask.config.get("distributed.comm.timeouts.connect")))
                client = stack.enter_context(Client(scheduler, timeout=timeout))
            except (OSError, TimeoutError, ValueError) as e:
                raise ExecutorError(f"--scheduler {scheduler}: cannot connect: {' '.join(str(e).split())}") from None
            name = f"scheduler {scheduler}"
            if not client.nthreads():
                raise ExecutorError(f"--scheduler {scheduler}: the cluster has no workers")
        else:
            if workers < 1:
                raise ExecutorError(f"--workers {workers}: give 1 or more")
            # Dask's nanny writes its pre-spawn variables into this process's environment too: put them back
            # after, so what this process starts later does not inherit a worker's thread counts.
            saved = {name: os.environ.get(name) for name in THREAD_POOL_VARIABLES}
            stack.callback(_restore_environ, saved)
            # The scheduler's and workers' scratch folders (Dask's dask-scratch-space, which it keeps) in one
            # of ours, removed once the cluster is stopped: a run leaves nothing in the temporary directory.
            scratch = stack.enter_context(tempfile.TemporaryDirectory(prefix="cbox-dask-"))
            stack.enter_context(dask.config.set({"temporary-directory": scratch,
                                                 "distributed.scheduler.allowed-failures": ALLOWED_FAILURES,
                                                 "distributed.nanny.pre-spawn-environ":
                                                     local_pre_spawn_environ(workers)}))
            cluster = stack.enter_context(LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                dashboard_address=dashboard, silence_logs=logging.ERROR,
                # Without a dashboard the scheduler still serves its health routes over HTTP: on a free
                # port of loopback, not on 8787, which a user's own cluster may hold.
                scheduler_kwargs=None if dashboard else {"dashboard_address": "127.0.0.1:0"},
                # Set before the worker process starts, so numba reads it at import.
                env=local_env(workers)))
            client = stack.enter_context(Client(cluster))
            name = f"{workers} local worker{'s' if workers > 1 else ''}"
        client.register_plugin(WorkerSetup(workers_by_host(client), keep_threads=scheduler is not None))
        yield DaskExecutor(client, name, retries)


def _restore_environ(saved: dict[str, str | None]) -> None:
    for name, value in saved.items():
        if value is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = value
