"""LuxCoreRender adapter: an independent, unbiased RGB path tracer (``pyluxcore`` 2.11), the harness's second
reference engine (``cbox reference verify --engine luxcore``).

The scene is exported with :mod:`cornell_harness.scenes.export.luxcore` (its ``MAPPING`` says how each part is
written: one-sided diffuse, mirror and emitters, glass, box filter, depth; spheres as fine meshes) into a
temporary folder and rendered by :mod:`cornell_harness.renderers.luxcore_cli` in a child process, LuxCore's ``PATHCPU``
engine with its ``RANDOM`` sampler: unidirectional path tracing with next-event estimation and MIS,
without Russian roulette (LuxCore 2.11's biases its MIS weights: see the export's docstring); unbounded
paths are cut where the light lost is below 1e-5 of the brightest radiance.

Why a child process, started as ``python -m cornell_harness.renderers.luxcore_cli``: pyluxcore aborts the process at
interpreter exit once initialised, and aborts when OpenImageIO (which the harness uses for every image
file) is imported after it, so it must never be imported here. A fresh interpreter running the same
program as ``cbox-luxcore`` has none of the harness's modules loaded and ends with ``os._exit``;
``multiprocessing``'s spawn would import the parent's ``__main__`` (``cbox``, pytest) into it and leave
through a normal exit. Even :meth:`LuxCore.version` asks a child.

The render is split into independent batches (:mod:`cornell_harness.renderers.batches`), batch k seeded with
``pass_seed(seed, k)``; checkpoints fall on batch boundaries, and the variance of the mean comes from the
spread of the batch means.

Not bit-reproducible: LuxCore halts a batch on the film's total sample count, checked while its threads
run, so each pixel gets about the batch's spp (measured: 15 to 17 samples at 16 spp at 256², with 1 or
2 threads; up to 15 more on a 16 × 16 film), which pixels get one more depends on thread timing, and two renders with the same seed differ
at the noise level (each pixel is still the mean of its own samples: unbiased). ``info`` records the
range of samples per pixel.
"""

from __future__ import annotations

import importlib.util
import json
import sys
import tempfile
from functools import cache
from pathlib import Path
from typing import Sequence

import numpy as np

from cornell_harness.adapters.api import Checkpoint, RenderResult, default_threads
from cornell_harness.scenes.export import export_scene
from cornell_harness.scenes.export.luxcore import FEATURES
from cornell_harness.scenes.model import Scene
from cornell_harness.renderers.batches import BATCHES_SETTING, batch_plan, mean_and_variance, run_child_process

@cache
def _child_version() -> str:
    code = ("import os, sys, pyluxcore; sys.stdout.write('\\nversion=' + pyluxcore.Version() + '\\n'); "
            "sys.stdout.flush(); os._exit(0)")
    with tempfile.TemporaryDirectory(prefix="cbox-luxcore-") as tmp:
        status, stdout, stderr = run_child_process([sys.executable, "-c", code], Path(tmp), time_limit_s=120)
    lines = [line for line in stdout.splitlines() if line.startswith("version=")]
    if status != 0 or not lines:
        raise RuntimeError(f"pyluxcore.Version() failed: {stderr}")
    return lines[-1].removeprefix("version=")


class LuxCore:
    """LuxCoreRender's PATHCPU path tracer, through an exported LuxCore SDL scene, in a child process."""

    name = "luxcore"
    citations = (
        "LuxCoreRender 2.11, https://luxcorerender.org",)
    features = FEATURES
    quantities = ("radiance",)
    estimator = "unbiased"
    settings = (BATCHES_SETTING,)

    def unavailable_reason(self) -> str | None:
        # Found, never imported: pyluxcore in this process would abort it (see the module docstring).
        if importlib.util.find_spec("pyluxcore") is None:
            return "pyluxcore is not installed; pip install pyluxcore==2.11.2"
        return None

    def version(self) -> str:
        return _child_version()

    def render(self, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = (),
               settings: dict | None = None) -> RenderResult:
        batches = int((settings or {}).get("batches", BATCHES_SETTING.default))
        sizes = batch_plan(spp, max(2, batches) if spp >= 2 else 1, checkpoints)
        threads = default_threads()
        with tempfile.TemporaryDirectory(prefix="cbox-luxcore-") as tmp:
            cfg = export_scene(scene, "luxcore", Path(tmp) / "scene")
            out = Path(tmp) / "batches"
            command = [sys.executable, "-m", "cornell_harness.renderers.luxcore_cli", str(cfg), "--out", str(Path(tmp) / "image.exr"),
                       "--spp", str(spp), "--seed", str(seed), "--threads", str(threads),
                       "--passes", ",".join(map(str, sizes)), "--batch-dir", str(out)]
            status, _, stderr = run_child_process(command, Path(tmp))
            if status != 0:
                raise RuntimeError(f"LuxCore child exited with status {status}: {stderr}")
            record = json.loads((out / "batches.json").read_text())["batches"]
            means = [np.load(out / f"batch-{k}.npy") for k in range(len(sizes))]
        return self._result(means, record, sizes, spp, seed, checkpoints, threads)

    @staticmethod
    def _result(means, record, sizes, spp, seed, checkpoints, threads) -> RenderResult:
        """The image, the variance of its mean and the checkpoints, from the batch means."""
        shots, done, elapsed, cpu = [], 0, 0.0, 0.0
        for k, n in enumerate(sizes):
            done += n
            elapsed += record[k]["seconds"]
            cpu += record[k]["cpu_seconds"]  # the child's CPU time of the batch, all its threads
            if done in checkpoints:
                image, _ = mean_and_variance(means[:k + 1], sizes[:k + 1])
                shots.append(Checkpoint(done, image.astype(np.float32), elapsed, cpu_time_s=cpu))
        image, variance = mean_and_variance(means, sizes)
        # How far LuxCore's halt missed each batch's spp, per pixel (see the module docstring).
        off = [(r["pixel_samples"][0] - n, r["pixel_samples"][1] - n) for r, n in zip(record, sizes)]
        info = {"threads": threads, "batches": len(sizes), "engine": "PATHCPU", "sampler": "RANDOM",
                "pixel_samples_off": [min(o[0] for o in off), max(o[1] for o in off)],
                "samples": sum(r["samples"] for r in record)}
        return RenderResult(image.astype(np.float32), elapsed, spp, seed, shots, info,
                            None if variance is None else variance.astype(np.float32), cpu_time_s=cpu)
