"""Building a reference: independent batches → mean, variance of the mean, a noise batch, provenance.

For a scene with named regions the provenance also says how noisy the
reference is in each (:func:`harness.evaluate.regions.region_noise`): a
caustic needs far more samples than a wall.

The layout of what is written is documented in :mod:`harness.store.references`.
"""

from __future__ import annotations

import datetime as _dt
import os
import platform
import sys
import time
from pathlib import Path
from typing import Callable

import numpy as np

from harness.adapters.registry import RendererEntry
from harness.evaluate.regions import region_masks, region_noise
from harness.scenes.model import Scene
from harness.store.atomic import write_json_atomic
from harness.store.exr import write_exr
from harness.store.image_files import SPP_ATTRIBUTE
from harness.store.references import (NOISE_FILE, PROVENANCE_FILE, REFERENCE_FILE, REFERENCE_SEED_BASE, VARIANCE_FILE,
                                      Reference, reference_folder)
from harness.workflows.render import render_checked


def build_reference(
    scene: Scene,
    spp: int,
    batches: int,
    entry: RendererEntry,
    folder: Path | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Reference:
    """Render ``batches`` independent batches (and the noise batch) with ``entry``; store mean, variance, noise,
    provenance. The harness's reference renderer is Mitsuba 3; the CLI names it, this module names none.

    ``spp`` must be a multiple of ``batches``. The files are written only when
    every batch is done, each atomically, provenance last; by default into the
    scene's reference folder (:func:`~harness.store.references.reference_folder`).
    """
    if batches < 2:
        raise ValueError("need at least 2 batches to estimate the variance")
    if spp % batches:
        raise ValueError(f"spp ({spp}) must be a multiple of batches ({batches})")
    folder = Path(folder) if folder else reference_folder(scene)
    batch_spp = spp // batches
    seeds = [REFERENCE_SEED_BASE + b for b in range(batches)]
    shape = (scene.camera.height, scene.camera.width, 3)
    mean, m2 = np.zeros(shape), np.zeros(shape)  # Welford's running mean and sum of squares
    wall = 0.0
    info: dict = {}
    for b, seed in enumerate(seeds):
        t0 = time.perf_counter()
        result = render_checked(entry, scene, batch_spp, seed)
        wall += time.perf_counter() - t0
        info = result.info
        x = result.image.astype(np.float64)
        delta = x - mean
        mean += delta / (b + 1)
        m2 += delta * (x - mean)
        if progress:
            progress(b + 1, batches + 1)
    noise_seed = REFERENCE_SEED_BASE + batches
    noise = render_checked(entry, scene, batch_spp, noise_seed).image
    if progress:
        progress(batches + 1, batches + 1)
    variance_of_mean = m2 / (batches - 1) / batches
    prov = _provenance(scene, entry, info, spp, batches, seeds, noise_seed, wall)
    if scene.overrides:  # a derived scene's reference: what it was derived with (harness.scenes.overrides)
        prov["overrides"] = list(scene.overrides)
    if scene.regions:
        prov["region_noise"] = region_noise(mean, variance_of_mean, region_masks(scene))
    meta = {"cbox:scene_hash": prov["scene_hash"], SPP_ATTRIBUTE: str(spp), "cbox:renderer": prov["renderer_version"]}
    write_exr(folder / REFERENCE_FILE, mean, meta)
    write_exr(folder / VARIANCE_FILE, variance_of_mean, meta)
    write_exr(folder / NOISE_FILE, noise, meta)
    write_json_atomic(folder / PROVENANCE_FILE, prov)
    return Reference(mean.astype(np.float32), variance_of_mean.astype(np.float32), noise, prov, folder)


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
