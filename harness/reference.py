"""The reference store: trusted images of each scene, with their variance.

``references/<scene>/`` holds

- ``scene.toml``: the scene;
- ``reference.exr``: the reference, the mean of ``batches`` independent
  Mitsuba renders of ``batch_spp`` samples each (float32 linear sRGB);
- ``variance.exr``: per-pixel, per-channel variance *of that mean*, i.e. the
  unbiased sample variance of the batch images divided by ``batches``;
- ``noise.exr``: one more batch, independent of the reference (seed
  ``noise_seed``), kept as a sample of the renderer's real noise: its channel
  correlations and tails make the noise yardsticks of :mod:`harness.stats`
  match real renders where a Gaussian model would not;
- ``provenance.json``: renderer, version, variant, spp, seeds, wall time, the
  scene's content hash, date, command line.

References use seeds from :data:`REFERENCE_SEED_BASE` up, a range no user
run uses by default, so a test render never shares samples with its reference.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from harness.atomic import write_json_atomic
from harness.exr import ImageFileError, read_exr, write_exr
from harness.scene import Scene, SceneError, load_scene

REFERENCE_SEED_BASE = 1_000_000_000
REFERENCE_FILE, VARIANCE_FILE, NOISE_FILE = "reference.exr", "variance.exr", "noise.exr"
PROVENANCE_FILE = "provenance.json"


class ReferenceError(RuntimeError):
    """A reference is missing, stale or inconsistent. ``str()`` says how to fix it."""


def references_root() -> Path:
    """Folder of stored references: ``$CBOX_REFERENCES`` or the project's ``references/``."""
    env = os.environ.get("CBOX_REFERENCES")
    return Path(env) if env else Path(__file__).resolve().parent.parent / "references"


def scene_names() -> list[str]:
    root = references_root()
    return sorted(p.parent.name for p in root.glob("*/scene.toml"))


def resolve_scene(name_or_path: str) -> Scene:
    """Load a scene by stored name (``cornell-box``) or by path to a file or folder."""
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.is_dir() or os.sep in name_or_path:
        return load_scene(p)
    stored = references_root() / name_or_path / "scene.toml"
    if not stored.exists():
        known = ", ".join(scene_names()) or "(none)"
        raise SceneError(name_or_path, "--scene", f"no stored scene of that name; known: {known}; or give a path")
    return load_scene(stored)


@dataclass
class Reference:
    image: np.ndarray  # (H, W, 3) float32
    variance: np.ndarray  # variance of the mean, (H, W, 3) float32
    noise: np.ndarray  # one independent batch of noise_spp samples, (H, W, 3) float32
    provenance: dict
    folder: Path

    @property
    def spp(self) -> int:
        return int(self.provenance["spp"])

    @property
    def noise_spp(self) -> int:
        return int(self.provenance["noise_spp"])


def rebuild_command(scene: Scene, spp: int = 16384) -> str:
    return f"cbox reference build --scene {scene.path.parent} --spp {spp}"


def load_reference(scene: Scene, folder: Path | None = None) -> Reference:
    """The stored reference of ``scene``; refuse one built from different content."""
    folder = Path(folder) if folder else scene.path.parent
    prov_path = folder / PROVENANCE_FILE
    if not prov_path.exists():
        raise ReferenceError(f"{prov_path}: no reference for scene {scene.name!r}; build it with: {rebuild_command(scene)}")
    try:
        prov = json.loads(prov_path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ReferenceError(f"{prov_path}: unreadable ({e}); rebuild with: {rebuild_command(scene)}") from None
    spp = int(prov.get("spp", 16384))
    if prov.get("scene_hash") != scene.content_hash():
        raise ReferenceError(
            f"{prov_path}: reference was built for scene hash {prov.get('scene_hash')}, but {scene.path} "
            f"now hashes to {scene.content_hash()}; rebuild it with: {rebuild_command(scene, spp)}"
        )
    try:
        image, variance, noise = (read_exr(folder / f) for f in (REFERENCE_FILE, VARIANCE_FILE, NOISE_FILE))
    except ImageFileError as e:
        raise ReferenceError(f"{e}; rebuild with: {rebuild_command(scene, spp)}") from None
    shape = (scene.camera.height, scene.camera.width, 3)
    if not image.shape == variance.shape == noise.shape == shape:
        raise ReferenceError(
            f"{folder}: reference images are {image.shape[1]}x{image.shape[0]}, scene is {shape[1]}x{shape[0]}; "
            f"rebuild with: {rebuild_command(scene, spp)}"
        )
    return Reference(image, variance, noise, prov, folder)


def build_reference(
    scene: Scene,
    spp: int,
    batches: int = 128,
    renderer=None,
    folder: Path | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Reference:
    """Render ``batches`` independent batches (and the noise batch); store mean, variance, noise, provenance.

    ``spp`` must be a multiple of ``batches``. The files are written only when
    every batch is done, each atomically, provenance last.
    """
    if batches < 2:
        raise ValueError("need at least 2 batches to estimate the variance")
    if spp % batches:
        raise ValueError(f"spp ({spp}) must be a multiple of batches ({batches})")
    if renderer is None:
        from renderers.mitsuba3 import Mitsuba3

        renderer = Mitsuba3()
    folder = Path(folder) if folder else scene.path.parent
    batch_spp = spp // batches
    seeds = [REFERENCE_SEED_BASE + b for b in range(batches)]
    shape = (scene.camera.height, scene.camera.width, 3)
    mean, m2 = np.zeros(shape), np.zeros(shape)  # Welford's running mean and sum of squares
    wall = 0.0
    info: dict = {}
    for b, seed in enumerate(seeds):
        t0 = time.perf_counter()
        result = renderer.render(scene, batch_spp, seed)
        wall += time.perf_counter() - t0
        info = result.info
        x = result.image.astype(np.float64)
        delta = x - mean
        mean += delta / (b + 1)
        m2 += delta * (x - mean)
        if progress:
            progress(b + 1, batches + 1)
    noise_seed = REFERENCE_SEED_BASE + batches
    noise = renderer.render(scene, batch_spp, noise_seed).image
    if progress:
        progress(batches + 1, batches + 1)
    variance_of_mean = m2 / (batches - 1) / batches
    prov = {
        "scene": scene.name,
        "scene_hash": scene.content_hash(),
        "renderer": renderer.name,
        "renderer_version": renderer.version(),
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
    meta = {"cbox:scene_hash": prov["scene_hash"], "cbox:spp": str(spp), "cbox:renderer": prov["renderer_version"]}
    write_exr(folder / REFERENCE_FILE, mean, meta)
    write_exr(folder / VARIANCE_FILE, variance_of_mean, meta)
    write_exr(folder / NOISE_FILE, noise, meta)
    write_json_atomic(folder / PROVENANCE_FILE, prov)
    return Reference(mean.astype(np.float32), variance_of_mean.astype(np.float32), noise, prov, folder)
