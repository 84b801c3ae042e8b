"""The frames of a sequence as our stateful renderers walk them, and the temporal stage around any renderer.

An animated scene (the scene model's contract: ``frame_count``, ``at_frame(i)``)
is rendered frame after frame by a renderer that carries state between frames
(the probes' volume, a temporal stage's history): asked for some frames only,
it must still render every frame from 0 to the last one asked for, and returns
those asked for, in order. A still scene is a sequence of one frame, itself.

**A temporal stage** (:class:`TemporalStage`) is a renderer around another:
each frame rendered by it, then combined with the previous frames' history.
What :mod:`cornell_harness.renderers.temporal` (exponential accumulation,
TAA-style) and :mod:`cornell_harness.renderers.svgf` (SVGF) share: the wrapper
(name ``<renderer>+<stage>``, the wrapped renderer's settings plus the stage's
own, availability, version) and the frame loop of ``render_sequence``.

**The frame loop** (:func:`stage_frames`): frame i is ``scene.at_frame(i)``
(object offsets from ``scene.animation.offset``), rendered by the wrapped renderer with the frame's seed
(:func:`cornell_harness.adapters.api.frame_seed`); the toolkit then writes the frame's
G-buffer (:func:`cornell_harness.renderers.core.gbuffer.gbuffer`: one ray through each
pixel centre) and, from frame 1 on, the motion vectors to the previous frame
(:func:`cornell_harness.renderers.core.motion.motion_vectors`). A stage's ``step`` turns
them and its history into the frame's image. A frame's time is the wrapped
renderer's plus the stage's (G-buffer, motion vectors, filter): a real-time
engine writes its G-buffer every frame too.

A still render (``render``) is a sequence's first frame: no history.
"""

from __future__ import annotations

from typing import Any, Iterator, Mapping, NamedTuple, Sequence

import numpy as np

from cornell_harness.adapters.api import RenderResult, SequenceResult, Setting, Stopwatch, attribute, frame_seed
from cornell_harness.scenes.model import Scene
from cornell_harness.renderers.core.gbuffer import GBuffer, gbuffer
from cornell_harness.renderers.core.geometry import SceneGeometry
from cornell_harness.renderers.core.motion import motion_vectors, object_offsets


def frame_count(scene) -> int:
    """The scene's frames: ``scene.frame_count`` of an animated scene, 1 for a still one."""
    return int(getattr(scene, "frame_count", 1))


def frames_to_render(scene, frames: Sequence[int] | None) -> tuple[int, list[int]]:
    """(how many frames to render, 0 .. n-1; the frames to return, in order); ValueError for a frame out of range
    or none asked for."""
    count = frame_count(scene)
    wanted = sorted(set(range(count) if frames is None else (int(f) for f in frames)))
    if not wanted or wanted[0] < 0 or wanted[-1] >= count:
        raise ValueError(f"frames {list(frames or [])} out of range: the scene has {count} frame(s)")
    return wanted[-1] + 1, wanted


def still_frame(scene, i: int) -> Scene:
    """Frame ``i`` as a still scene (``scene.at_frame(i)``; a scene without frames is its own frame 0)."""
    return scene.at_frame(i) if hasattr(scene, "at_frame") else scene



class Frame(NamedTuple):
    """What a stage's ``step`` gets for frame ``index``."""

    index: int
    scene: Scene  # the still scene of this frame
    result: RenderResult  # the wrapped renderer's render of it
    gbuffer: GBuffer
    offsets: np.ndarray  # (objects, 3) each object's animation offset
    motion: np.ndarray | None  # (H, W, 2) to the previous frame; None for frame 0


def stage_frames(base, scene, spp: int, seed: int, settings: Mapping[str, Any], count: int,
                 aovs: Sequence[str] = ()) -> Iterator[tuple[Frame, float, float]]:
    """Each frame 0 .. count-1 (module docstring), with the wall and CPU seconds the stage spent on it so far
    (its G-buffer and motion vectors; the wrapped renderer's are in ``frame.result``)."""
    kwargs = {"settings": dict(settings)} if attribute(base, "settings") else {}
    if aovs:
        kwargs["aovs"] = tuple(aovs)
    prev = None
    for i in range(count):
        still = still_frame(scene, i)
        result = base.render(still, spp, frame_seed(seed, i), (), **kwargs)
        clock = Stopwatch()
        g = gbuffer(still, SceneGeometry(still))
        offsets = object_offsets(scene, i)
        motion = None
        if prev is not None:
            motion = motion_vectors(g.position, g.object, prev.scene.camera, still.camera, prev.offsets, offsets)
        frame = Frame(i, still, result, g, offsets, motion)
        yield frame, *clock.read()
        prev = frame


class TemporalStage:
    """Base of the temporal stages: ``<base>+<suffix>`` around ``base`` (module docstring).

    A subclass sets ``suffix``, ``OWN_SETTINGS``, ``aovs_needed``, and ``start(settings)`` (a fresh history)
    and ``step(history, frame, prev_frame, settings) -> image`` (the frame's image; the history updated in place).
    """

    suffix = ""
    OWN_SETTINGS: tuple[Setting, ...] = ()
    aovs_needed: tuple[str, ...] = ()
    estimator = "biased"
    quantities = ("radiance",)
    sequences = True
    citations: tuple[str, ...] = ()
    approximation = ""

    def __init__(self, base, threads: int | None = None):
        self.base, self.threads = base, threads
        self.name = f"{base.name}+{self.suffix}"
        self.features = base.features
        self.approximations = tuple(attribute(base, "approximations")) + (self.approximation,)
        self.settings = attribute(base, "settings") + self.OWN_SETTINGS
        self.citations = attribute(base, "citations") + type(self).citations

    def unavailable_reason(self) -> str | None:
        if not set(self.aovs_needed) <= set(attribute(self.base, "aovs")):
            return f"{self.base.name} gives no {' and '.join(self.aovs_needed)} AOVs"
        return self.base.unavailable_reason()

    def version(self) -> str:
        return self.base.version()

    def _split(self, settings: Mapping[str, Any] | None) -> tuple[dict, dict]:
        """(the stage's settings with their defaults, the wrapped renderer's)."""
        own = {s.name for s in self.OWN_SETTINGS}
        given = dict(settings or {})
        mine = {**{s.name: s.default for s in self.OWN_SETTINGS}, **{k: v for k, v in given.items() if k in own}}
        return mine, {k: v for k, v in given.items() if k not in own}

    def render(self, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = (), *,
               settings: Mapping[str, Any] | None = None) -> RenderResult:
        """A still image: the first frame of a sequence of ``scene`` (no history), with ``seed`` itself."""
        mine, theirs = self._split(settings)
        kwargs = {"settings": theirs} if attribute(self.base, "settings") else {}
        result = self.base.render(scene, spp, seed, checkpoints, **kwargs)
        result.variance = None  # a stage's image is biased: no per-pixel variance (estimator)
        result.info.update(stage=self.suffix, **mine)
        return result

    def render_sequence(self, scene, spp: int, seed: int, settings: Mapping[str, Any] | None = None,
                        frames: Sequence[int] | None = None) -> SequenceResult:
        """Frames of ``scene`` (all, or ``frames``), each the stage's combination of the wrapped renderer's
        image with the history (module docstring)."""
        mine, theirs = self._split(settings)
        count, wanted = frames_to_render(scene, frames)
        history, prev, out = self.start(mine), None, []
        for frame, stage_s, stage_cpu in stage_frames(self.base, scene, spp, seed, theirs, count,
                                                      self.aovs_needed):
            clock = Stopwatch()
            image, info = self.step(history, frame, prev, mine)
            step_s, step_cpu = clock.read()
            prev = frame
            if frame.index not in wanted:
                continue
            r = frame.result
            cpu = None if r.cpu_time_s is None else r.cpu_time_s + stage_cpu + step_cpu
            out.append(RenderResult(image.astype(np.float32), r.time_s + stage_s + step_s, r.spp, r.seed, [],
                                    {**r.info, **info, "stage": self.suffix, "stage_s": round(stage_s + step_s, 4),
                                     "frame": frame.index}, None, {}, cpu))
        return SequenceResult(out, {"stage": self.suffix, **mine})

    def start(self, settings: Mapping[str, Any]) -> dict:
        return {}

    def step(self, history: dict, frame: Frame, prev: Frame | None, settings: Mapping[str, Any]):
        raise NotImplementedError
