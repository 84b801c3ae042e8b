"""What a Dask worker needs before it renders: its share of the cores, and a numba cache it can write.

Imported only where Dask is used (it subclasses Dask's ``WorkerPlugin``):
:func:`cornell_harness.workflows.executor.open_executor` registers :class:`WorkerSetup`
on every cluster it opens, and gives a LocalCluster's workers :func:`local_env`
and :func:`local_pre_spawn_environ` before their processes start.
"""

from __future__ import annotations

import os
import signal
import sys
import tempfile
import threading
from pathlib import Path
from typing import Any

from distributed.diagnostics.plugin import WorkerPlugin

from cornell_harness.adapters.api import THREADS_VARIABLE, machine_cores


def threads_per_worker(cores: int, workers_on_host: int) -> int:
    """A worker's share of its machine's cores: N workers on N cores get one each, never fewer than one."""
    return max(1, cores // max(1, workers_on_host))


def numba_cache_dir(environ: dict | None = None) -> str | None:
    """A numba cache folder this process can write, or None where numba's own choice is writable.

    A writable ``$NUMBA_CACHE_DIR`` is kept. Without one numba caches beside the code when it can, else in
    the user's cache folder (``~/.cache/numba``); where that is not writable either (a service account
    without a home), numba could not cache at all, so a folder of this user's in the temporary directory.
    """
    environ = os.environ if environ is None else environ
    if (given := environ.get("NUMBA_CACHE_DIR")) and _writable(Path(given)):
        return given
    home_cache = Path(environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    if _writable(home_cache / "numba"):
        return None
    return str(Path(tempfile.gettempdir()) / f"cbox-numba-cache-{os.getuid()}")


def _writable(folder: Path) -> bool:
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            return True
    except OSError:
        return False


def local_env(workers: int) -> dict[str, str]:
    """The environment of a LocalCluster's ``workers`` processes: their share of this machine's cores, and
    the numba cache of this process (warm where the harness ran before) when it is set."""
    env = {THREADS_VARIABLE: str(threads_per_worker(machine_cores(), workers))}
    if (cache := numba_cache_dir()) is not None:
        env["NUMBA_CACHE_DIR"] = cache
    return env


#: Thread pools of the libraries a cell's scoring uses (OpenMP: FLIP; BLAS: NumPy, SciPy). Dask's nanny sets
#: them to 1 in each worker it starts, before the start (``distributed.nanny.pre-spawn-environ``): a metric
#: then runs on one core where the worker has more.
THREAD_POOL_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


def local_pre_spawn_environ(workers: int) -> dict[str, str]:
    """Dask's pre-spawn environment for a LocalCluster of ``workers``, its thread pools at each worker's share."""
    import dask

    share = str(threads_per_worker(machine_cores(), workers))
    given = dask.config.get("distributed.nanny.pre-spawn-environ", default={}) or {}
    return {**{k: str(v) for k, v in given.items()}, **{name: share for name in THREAD_POOL_VARIABLES}}


def host_of(address: str) -> str:
    """``tcp://10.0.0.5:40123`` → ``10.0.0.5``."""
    return address.split("://", 1)[-1].rsplit(":", 1)[0]


def workers_by_host(client: Any) -> dict[str, int]:
    """How many worker processes each host of the client's cluster runs now."""
    counts: dict[str, int] = {}
    for address in client.scheduler_info(n_workers=-1)["workers"]:
        counts[host_of(address)] = counts.get(host_of(address), 0) + 1
    return counts


#: The CBOX_THREADS value this plugin set in a worker (so a later client tells it from one the worker was given).
_OURS = "CBOX_THREADS_SET_BY_CBOX"


class WorkerSetup(WorkerPlugin):
    """Run on each worker (those that join later too) before its first task: ``CBOX_THREADS`` = its share of
    its host's cores, and a writable numba cache (:func:`numba_cache_dir`, decided on the worker's machine).

    ``workers_by_host`` counts the worker processes on each host when the client connected; a worker on a
    host not counted shares with nobody. With ``keep_threads`` (an existing cluster), a ``CBOX_THREADS``
    already in the worker's environment, set by whoever started it, is kept. Without it (a LocalCluster of
    this process's own) the worker ignores Ctrl-C: a terminal sends it to every process of the foreground
    group, and the client, which closes the cluster (:mod:`cornell_harness.cli.interrupt`), is the one to hear it;
    a worker that heard it too would print a traceback of its own.
    """

    name = "cbox-worker-setup"
    idempotent = False  # set up again by each client: the host counts may have changed

    def __init__(self, workers_by_host: dict[str, int], keep_threads: bool = True):
        self.workers_by_host, self.keep_threads = dict(workers_by_host), keep_threads

    def setup(self, worker: Any) -> None:
        if not self.keep_threads and threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        # Kept only when whoever started the worker set it: one this plugin set for an earlier client is redone.
        given = os.environ.get(THREADS_VARIABLE) and os.environ.get(_OURS) != os.environ.get(THREADS_VARIABLE)
        if not (self.keep_threads and given):
            share = threads_per_worker(machine_cores(), self.workers_by_host.get(host_of(worker.address), 1))
            os.environ[THREADS_VARIABLE] = os.environ[_OURS] = str(share)
        cache = numba_cache_dir()
        if cache is not None and os.environ.get("NUMBA_CACHE_DIR") != cache:
            os.environ["NUMBA_CACHE_DIR"] = cache
            if "numba" in sys.modules:  # numba reads it at import; a worker that imported it already reloads
                from numba.core import config

                config.reload_config()
