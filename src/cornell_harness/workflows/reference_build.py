"""Building a reference: independent batches → mean, variance of the mean, a noise batch, provenance.

For a scene with named regions the provenance also says how noisy the
reference is in each (:func:`cornell_harness.evaluate.regions.region_noise`): a
caustic needs far more samples than a wall.

The layout of what is written is documented in :mod:`cornell_harness.store.references`.
"""

from __future__ import annotations

import datetime as _dt
import os
import platform
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from cornell_harness.scenes.spectral_scene import convention_used
from cornell_harness.adapters.registry import RendererEntry
from cornell_harness.adapters.seeds import frame_seed
from cornell_harness.adapters.settings import canonical
from cornell_harness.evaluate.regions import region_masks, region_noise
from cornell_harness.scenes.animation import reference_still
from cornell_harness.scenes.model import Scene
from cornell_harness.store.atomic import write_json_atomic
from cornell_harness.store.exr import write_exr
from cornell_harness.store.image_files import SPP_ATTRIBUTE
from cornell_harness.store.references import (NOISE_FILE, PROVENANCE_FILE, REFERENCE_FILE, REFERENCE_SEED_BASE, VARIANCE_FILE,
                                      Reference, reference_folder)
from cornell_harness.workflows.cells import entry_for
from cornell_harness.workflows.executor import DaskExecutor, ExecutorError, InProcess, Task, task_key
from cornell_harness.workflows.runner import render_timed


#: Below this, a frame's reference and noise images are stored as half floats (whose largest value is 65504).
#: An animated scene's frames are many references at once: half floats keep each frame's images at about a
#: third of float32's bytes, a rounding of at most 2^-11 relative, a small fraction of the per-pixel noise of a
#: reference of a few thousand spp (a few per cent). The variance stays float32: half would flush its small
#: values (dark pixels, below about 6e-8) to zero.
HALF_LIMIT = 6.0e4


def build_reference(
    scene: Scene,
    spp: int,
    batches: int,
    entry: RendererEntry,
    folder: Path | None = None,
    progress: Callable[[int, int, str], None] | None = None,
    executor: InProcess | DaskExecutor | None = None,
) -> Reference:
    """Render ``batches`` independent batches (and the noise batch) with ``entry``; store mean, variance, noise,
    provenance. The harness's reference renderer is Mitsuba 3; the CLI names it, this module names none.

    ``spp`` must be a multiple of ``batches``. The files are written only when
    every batch is done, each atomically, provenance last; by default where the
    scene's reference is built (:func:`~cornell_harness.store.references.reference_folder`:
    beside a scene file of the user's, in the user store for a stored scene).

    The batches render on ``executor`` (:func:`render_batches`: combined in batch order, so every backend gives
    the same reference, bit for bit); ``progress(done, total, label)`` follows finished batches (``batch 3``,
    ``noise image``).

    A frame of an animated scene builds the reference it reads: that of the frame it shares it with
    (:func:`~cornell_harness.scenes.animation.reference_still`), with that frame's seeds, hash and number.
    """
    scene = reference_still(scene)
    if batches < 2:
        raise ValueError("need at least 2 batches to estimate the variance")
    if spp % batches:
        raise ValueError(f"spp ({spp}) must be a multiple of batches ({batches})")
    folder = Path(folder) if folder else reference_folder(scene)
    batch_spp = spp // batches
    seeds = [reference_seed(b, scene.frame) for b in range(batches)]
    noise_seed = reference_seed(batches, scene.frame)
    done = render_batches(scene, entry, batch_spp, seeds, executor, progress, extra_seed=noise_seed)
    mean, variance_of_mean, noise, wall, info = done.mean, done.variance, done.extra, done.wall_s, done.info
    prov = _provenance(scene, entry, info, spp, batches, seeds, noise_seed, wall)
    if scene.frame is not None:  # a frame of an animated scene (Scene.at_frame)
        prov["frame"] = scene.frame
    if scene.overrides:  # a derived scene's reference: what it was derived with (cornell_harness.scenes.overrides)
        prov["overrides"] = list(scene.overrides)
    if scene.regions:
        prov["region_noise"] = region_noise(mean, variance_of_mean, region_masks(scene))
    half = scene.frame is not None and max(float(np.abs(mean).max()), float(np.abs(noise).max())) < HALF_LIMIT
    prov["pixel_types"] = {REFERENCE_FILE: "half" if half else "float", VARIANCE_FILE: "float",
                           NOISE_FILE: "half" if half else "float"}
    meta = {"cbox:scene_hash": prov["scene_hash"], SPP_ATTRIBUTE: str(spp), "cbox:renderer": prov["renderer_version"]}
    write_exr(folder / REFERENCE_FILE, mean, meta, half=half)
    write_exr(folder / VARIANCE_FILE, variance_of_mean, meta)
    write_exr(folder / NOISE_FILE, noise, meta, half=half)
    write_json_atomic(folder / PROVENANCE_FILE, prov)
    stored = np.float16 if half else np.float32  # what a reader of the files gets
    return Reference(mean.astype(stored).astype(np.float32), variance_of_mean.astype(np.float32),
                     noise.astype(stored).astype(np.float32), prov, folder)


def reference_seed(batch: int, frame: int | None = None) -> int:
    """The seed of batch ``batch`` of a reference (the noise image's is batch ``batches``): ``REFERENCE_SEED_BASE +
    batch``; for frame ``frame`` of an animated scene, that seed's frame seed (:func:`frame_seed`, the one
    derivation of frames' seeds), so the frames' references are independent, those of identical frames too."""
    seed = REFERENCE_SEED_BASE + batch
    return seed if frame is None else frame_seed(seed, frame)


@dataclass
class Batches:
    """What :func:`render_batches` gives: the batches' mean, the variance of that mean, the extra image (if one was
    asked for), the summed render time and the last batch's renderer info."""

    mean: np.ndarray  # float64
    variance: np.ndarray  # float64, variance of the mean: unbiased sample variance over batches / batches
    extra: np.ndarray | None
    wall_s: float
    info: dict


def render_batches(scene: Scene, entry: RendererEntry, batch_spp: int, seeds: list[int],
                   executor: InProcess | DaskExecutor | None = None,
                   progress: Callable[[int, int, str], None] | None = None, extra_seed: int | None = None) -> Batches:
    """One render of ``batch_spp`` per seed with ``entry`` (and one more at ``extra_seed``, kept apart), combined
    into the mean and the variance of the mean (Welford's running sums).

    The batches render on ``executor`` (default: in this process, in order), finished ones in any order; they are
    combined here in seed order, so every backend gives the same mean, bit for bit, for a renderer whose image
    depends only on its seed. ``progress(done, total, label)`` follows finished batches (``batch 3``, ``noise
    image`` for the extra one).
    """
    batches = len(seeds)
    if batches < 2:
        raise ValueError("need at least 2 batches to estimate the variance")
    executor = executor or InProcess()
    shared = executor.share(scene)
    all_seeds = seeds + ([] if extra_seed is None else [extra_seed])
    tasks = [Task(task_key("batch", scene.content_hash(), entry.spec, canonical(entry.settings), batch_spp, seed),
                  f"batch {b + 1}" if b < batches else "noise image", render_batch,
                  (entry.spec, dict(entry.settings), shared, batch_spp, seed, entry if executor.local else None,
                   entry.time_limit_s))
             for b, seed in enumerate(all_seeds)]
    index = {t.key: b for b, t in enumerate(tasks)}
    shape = (scene.camera.height, scene.camera.width, 3)
    mean, m2 = np.zeros(shape), np.zeros(shape)  # Welford's running mean and sum of squares
    wall = 0.0
    info: dict = {}
    extra = None
    waiting: dict[int, np.ndarray] = {}  # batches that finished before one ahead of them: folded in order
    folded = done = 0
    for outcome in executor.run(tasks):
        b = index[outcome.task.key]
        if outcome.error is not None:
            raise ExecutorError(f"{entry.name} batch {b + 1} of {len(tasks)} (seed {tasks[b].args[4]}) failed: "
                                f"{outcome.error}")
        image, time_s, batch_info = outcome.value
        wall += time_s
        if b == batches:
            extra = image
        else:
            waiting[b] = image
            if b == batches - 1:
                info = batch_info
        while folded in waiting:  # the same sums in the same order on every backend: the same bits
            x = waiting.pop(folded).astype(np.float64)
            delta = x - mean
            mean += delta / (folded + 1)
            m2 += delta * (x - mean)
            folded += 1
        done += 1
        if progress:
            progress(done, len(tasks), outcome.task.label)
    return Batches(mean, m2 / (batches - 1) / batches, extra, wall, info)


def render_batch(spec: str, settings: dict, scene: Scene, spp: int, seed: int, entry: RendererEntry | None = None,
                 time_limit_s: float | None = None) -> tuple[np.ndarray, float, dict]:
    """One batch, in whatever process runs it: its image (float32), render time and the renderer's info.
    In-process the caller's ``entry`` renders it; on a worker, ``spec`` with ``settings`` loaded there. With
    ``time_limit_s``, in a child process ended at it (RenderTimeout)."""
    entry = (entry or entry_for(spec, settings)).with_time_limit(time_limit_s)
    t0 = time.perf_counter()
    result, _ = render_timed(entry, scene, spp, seed)
    return result.image, time.perf_counter() - t0, dict(result.info)


def _provenance(scene: Scene, entry: RendererEntry, info: dict, spp: int, batches: int, seeds: list[int],
                noise_seed: int, wall: float) -> dict:
    """What a reader needs to trust and rebuild the reference."""
    batch_spp = spp // batches
    return {
        "scene": scene.name,
        "scene_hash": scene.content_hash(),
        "renderer": entry.name,
        "settings": entry.settings,
        "renderer_version": entry.renderer.version(),
        "variant": info.get("variant"),
        **({"rgb_convention": convention_used(scene.spectral.rgb_convention, info)} if scene.spectral else {}),
        "spp": spp,
        "batches": batches,
        "batch_spp": batch_spp,
        "seeds": seeds,
        "noise_seed": noise_seed,
        "noise_spp": batch_spp,
        "wall_time_s": round(wall, 3),
        "resolution": [scene.camera.width, scene.camera.height],
        "max_depth": scene.max_depth,
        "pixel_filter": scene.pixel_filter,
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
        "machine": f"{platform.machine()}, {os.cpu_count()} CPUs, {platform.system()} {platform.release()}",
        "variance": "variance of the mean: unbiased sample variance over batches / batches",
    }
