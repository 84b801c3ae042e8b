"""Stand-ins for the sequence tests: an animated scene around a stored still one, its per-frame references made
from a known truth image, and renderers of sequences (stateless and stateful) that draw noise around that truth.

:class:`StandInSequence` gives what the scene model's animation contract names (``frame_count``, ``animation``
with ``frames``, ``fps``, ``offset(name, i)``, ``camera_at(i)`` and ``states(frames)``, ``at_frame(i)``) by moving
named objects by a fixed step per frame up to a stop frame (dataclasses.replace on the still scene's meshes), so the
workflow, the metrics and the CLI can be tested before stored animated scenes exist. The renderers are loaded by the tests as
``tests.sequence_fakes:ClassName`` (the sandbox's child imports them the same way).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from cornell_harness.adapters.api import RenderResult, SequenceResult, Setting, frame_seed
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.references import Reference

ALL = frozenset({"triangle_mesh", "diffuse", "area_light", "pinhole_camera", "box_filter"})
#: The fakes' noise: sd of one sample per pixel around the truth.
SIGMA = 0.2
#: The references' variance of their mean, everywhere.
REFERENCE_VARIANCE = 1e-6


@dataclasses.dataclass(frozen=True)
class StandInAnimation:
    frames: int
    fps: float
    tracks: tuple  # (object name, step (3,) per frame, last moving frame)
    camera: object  # the still scene's, every frame

    def offset(self, name: str, i: int) -> np.ndarray:
        for track, step, stop in self.tracks:
            if track == name:
                return np.asarray(step, dtype=np.float64) * min(i, stop)
        return np.zeros(3)

    def camera_at(self, i: int):
        return self.camera

    def states(self, frames) -> np.ndarray:
        """What moves at each frame, a row per frame: the tracks' offsets (the camera stays)."""
        return np.array([np.concatenate([self.offset(name, i) for name, _, _ in self.tracks]) for i in frames])


class StandInSequence:
    """A stored still scene animated by :class:`StandInAnimation`; every other attribute is the still scene's."""

    def __init__(self, still, animation: StandInAnimation):
        self.still, self.animation = still, animation

    def __getattr__(self, name):
        if name.startswith("__") or name in ("still", "animation"):
            raise AttributeError(name)
        return getattr(self.still, name)

    @property
    def frame_count(self) -> int:
        return self.animation.frames

    def at_frame(self, i: int):
        meshes = tuple(dataclasses.replace(m, vertices=m.vertices + self.animation.offset(m.name, i))
                       for m in self.still.meshes)
        return dataclasses.replace(self.still, meshes=meshes, camera=self.animation.camera_at(i))


def moving_light(frames: int = 12, stop: int = 4, size: int = 16, step=(0.08, 0.0, 0.0),
                 others: tuple = ()) -> StandInSequence:
    """The stored Cornell box at ``size``², its light sliding by ``step`` a frame up to frame ``stop``, then at rest;
    ``others``: more (name, step, stop) tracks."""
    still = resolve_scene("cornell-box").with_resolution(size, size)
    tracks = (("light", tuple(step), stop),) + tuple(others)
    return StandInSequence(still, StandInAnimation(frames, 24.0, tracks, still.camera))


def truth(scene) -> np.ndarray:
    """The fakes' exact image of a still scene: a bright band under the light's x, scaled by its radiance."""
    light = next(m for m in scene.meshes if m.name == "light")
    x = light.vertices.mean(axis=0)[0]
    u = (np.arange(scene.camera.width) + 0.5) / scene.camera.width * 2.0 - 1.0
    band = 0.2 + 0.6 * np.exp(-((u - x) / 0.5) ** 2)
    gain = float(np.mean(light.radiance)) / 13.0 if light.radiance is not None else 0.0
    img = np.broadcast_to(band[None, :, None] * gain, (scene.camera.height, scene.camera.width, 3))
    return img.astype(np.float32)


def references(scene, frames=None) -> list[Reference]:
    """Per-frame references: the truth, with variance :data:`REFERENCE_VARIANCE` and a noise image to match."""
    out = []
    for i in range(scene.frame_count) if frames is None else frames:
        image = truth(scene.at_frame(i))
        rng = np.random.default_rng(1000 + i)
        noise = image + np.sqrt(REFERENCE_VARIANCE * 4096 / 64) * rng.standard_normal(image.shape)
        out.append(Reference(image, np.full(image.shape, REFERENCE_VARIANCE, np.float32),
                             noise.astype(np.float32), {"spp": 4096, "noise_spp": 64}, Path(".")))
    return out


def noisy(scene, spp: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    image = truth(scene)
    return (image + SIGMA / np.sqrt(spp) * rng.standard_normal(image.shape)).astype(np.float32)


class NoisyTruth:
    """Stateless: each frame is the truth plus fresh noise from its seed."""

    name = "noisy-truth"
    features = ALL

    def unavailable_reason(self):
        return None

    def version(self):
        return "1.0"

    def render(self, scene, spp, seed, checkpoints=()):
        return RenderResult(noisy(scene, spp, seed), 0.001, spp, seed)


class ExponentialTruth(NoisyTruth):
    """Stateful: an exponential history, h_i = hysteresis·h_{i−1} + (1 − hysteresis)·(truth_i + noise_i)."""

    name = "exponential-truth"
    sequences = True
    settings = (Setting("hysteresis", float, 0.9, "weight of the history", 0.0, 0.999),)

    def render(self, scene, spp, seed, checkpoints=(), settings=None):
        return RenderResult(noisy(scene, spp, seed), 0.001, spp, seed)

    def render_sequence(self, scene, spp, seed, settings=None, frames=None):
        alpha = settings["hysteresis"]
        history, out = None, []
        for i in frames:
            fresh = noisy(scene.at_frame(i), spp, frame_seed(seed, i))
            history = fresh if history is None else alpha * history + (1.0 - alpha) * fresh
            out.append(RenderResult(history.astype(np.float32), 0.002, spp, frame_seed(seed, i)))
        return SequenceResult(out, {"hysteresis": alpha, "frames": len(out)})


class ForgetsFrames(ExponentialTruth):
    """Declares sequences but returns one frame too few."""

    name = "forgets-frames"

    def render_sequence(self, scene, spp, seed, settings=None, frames=None):
        result = super().render_sequence(scene, spp, seed, settings, frames)
        return SequenceResult(result.frames[:-1], result.state)
