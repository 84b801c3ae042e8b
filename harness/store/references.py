"""The reference store: trusted images of each scene, with their variance.

``references/<scene>/`` holds

- ``scene.toml``: the scene;
- ``reference.exr``: the reference, the mean of ``batches`` independent
  Mitsuba renders of ``batch_spp`` samples each (float32 linear sRGB);
- ``variance.exr``: per-pixel, per-channel variance *of that mean*, i.e. the
  unbiased sample variance of the batch images divided by ``batches``;
- ``noise.exr``: one more batch, independent of the reference (seed
  ``noise_seed``), kept as a sample of the renderer's real noise: its channel
  correlations and tails make the noise yardsticks of :mod:`harness.evaluate.noise`
  match real renders where a Gaussian model would not;
- ``provenance.json``: renderer, version, variant, spp, seeds, wall time, the
  scene's content hash, date, command line.

References are built by :mod:`harness.workflows.reference_build`, with seeds from
:data:`REFERENCE_SEED_BASE` up, a range no user
run uses by default, so a test render never shares samples with its reference.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from harness.store.exr import ImageFileError, read_exr
from harness.scenes.model import Scene
from harness.scenes.quantities import DEFAULT_QUANTITY

REFERENCE_SEED_BASE = 1_000_000_000
REFERENCE_FILE, VARIANCE_FILE, NOISE_FILE = "reference.exr", "variance.exr", "noise.exr"
PROVENANCE_FILE = "provenance.json"


class ReferenceError(RuntimeError):
    """A reference is missing, stale or inconsistent. ``str()`` says how to fix it."""


@dataclass
class Reference:
    image: np.ndarray  # (H, W, 3) float32
    variance: np.ndarray  # variance of the mean, (H, W, 3) float32
    noise: np.ndarray  # one independent batch of noise_spp samples, (H, W, 3) float32
    provenance: dict
    folder: Path
    quantity: str = DEFAULT_QUANTITY  # the scene's: what the images mean (harness.scenes.quantities)

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
    return Reference(image, variance, noise, prov, folder, scene.quantity)
