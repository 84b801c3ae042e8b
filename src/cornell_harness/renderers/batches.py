"""Engines that render in a child process, in independent batches: the plan of the batches, the mean of their
means with the variance of that mean, the batches setting, and the child's environment.

An engine that gives no variance of its own (LuxCore, Cycles) renders ``spp`` as independent batches, each its
own seed; the spread of their means is the variance of the image's mean (:func:`mean_and_variance`), and a
checkpoint falls on a batch boundary (:func:`batch_plan`). Its child runs this package's own code
(:func:`child_env`) under the process-lifetime rule (:mod:`cornell_harness.processes`).
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path
from typing import Sequence

import numpy as np

from cornell_harness import processes
from cornell_harness.adapters.api import Setting, spp_passes

#: Default number of independent batches a render is split into (the variance's degrees of freedom).
BATCHES = 16
#: The ``batches`` setting of such an engine.
BATCHES_SETTING = Setting("batches", int, BATCHES, "independent batches (each its own seed) the render is split "
                          "into; the variance of the mean comes from their spread", low=2, high=1 << 16)
#: Characters of the child's stderr quoted when it fails.
STDERR_TAIL = 2000


def batch_plan(spp: int, batches: int, checkpoints: Sequence[int] = ()) -> list[int]:
    """The spp of each batch: passes of at most ``ceil(spp / batches)``, with a boundary at every checkpoint
    (:func:`cornell_harness.adapters.api.spp_passes`: they double from 1, so every power of two is a boundary)."""
    return list(spp_passes(spp, max(1, -(-spp // batches)), checkpoints))


def mean_and_variance(means: list[np.ndarray], sizes: list[int]) -> tuple[np.ndarray, np.ndarray | None]:
    """The spp-weighted mean of batch means and the variance of that mean (None from one batch).

    With batch k's mean m_k over n_k samples and N = Σ n_k, s² = Σ n_k (m_k − m̄)² / (B − 1) is an
    unbiased estimate of the per-sample variance σ² (E Σ n_k (m_k − m̄)² = B σ² − σ²), so s²/N
    estimates the variance of m̄.
    """
    n = np.asarray(sizes, dtype=np.float64)[:, None, None, None]
    m = np.stack(means).astype(np.float64)
    mean = (n * m).sum(axis=0) / n.sum()
    if len(means) < 2:
        return mean, None
    s2 = (n * (m - mean) ** 2).sum(axis=0) / (len(means) - 1)
    return mean, s2 / n.sum()


def run_child_process(argv: list[str], folder: Path, time_limit_s: float | None = None) -> tuple[int, str, str]:
    """Run an engine's child process (:func:`cornell_harness.processes.run`: ended with the command, or at
    ``time_limit_s``), with this package's environment (:func:`child_env`): (exit code, its stdout, the last
    :data:`STDERR_TAIL` characters of its stderr), both kept in files of ``folder``."""
    with open(folder / "stdout.txt", "wb") as out, open(folder / "stderr.txt", "wb") as err:
        code = processes.run(argv, time_limit_s, stdin=subprocess.DEVNULL, stdout=out, stderr=err,
                             env=child_env(folder))
    tail = (folder / "stderr.txt").read_text(errors="replace").strip()[-STDERR_TAIL:]
    return code, (folder / "stdout.txt").read_text(errors="replace"), tail


def child_env(temp: Path | None = None) -> dict:
    """The child's environment: the folder holding this package first on the path, so it runs the same code;
    with ``temp``, that folder as its temporary directory (TMPDIR): an engine's own temporary files (Blender's
    ``blender_*`` folder, which a child that ends by ``os._exit`` never removes) go where the run's files go, and
    are removed with them."""
    root = str(Path(__file__).resolve().parents[2])
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([root] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    if temp is not None:
        env["TMPDIR"] = str(temp)
    return env
