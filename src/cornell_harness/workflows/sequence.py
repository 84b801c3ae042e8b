"""Rendering an animated scene's frames: the one entry point of a sequence render, stateful or not.

A renderer that declares ``sequences = True`` (:class:`cornell_harness.adapters.api.Declarations`) renders the
frames itself with its ``render_sequence`` and carries state from frame to frame (a temporal history, probes
updated with a hysteresis); any other gets the stateless default, each frame rendered on its own as the still
scene ``scene.at_frame(i)`` with the seed :func:`~cornell_harness.adapters.api.frame_seed` ``(seed, i)``. Both go
through the one render path (:func:`cornell_harness.workflows.render.render_sequence_checked`); with a time limit
the whole sequence is one job in a sandboxed child process
(:func:`cornell_harness.workflows.sandbox.run_sandboxed_sequence`), so a stateful renderer's state lives there
from the first frame to the last, and the limit bounds the sequence, not each frame.

Every frame's :class:`~cornell_harness.adapters.api.RenderResult` keeps its own ``time_s`` (the per-frame
times); :class:`SequenceRun` adds the measure of the whole call (:mod:`cornell_harness.workflows.timing`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from cornell_harness.adapters.api import RenderResult, SequenceResult
from cornell_harness.adapters.registry import RendererEntry
from cornell_harness.scenes.model import Scene
from cornell_harness.workflows.render import RenderError, RenderTimeout, render_sequence_checked
from cornell_harness.workflows.sandbox import run_sandboxed_sequence
from cornell_harness.workflows.timing import Timing, measure


@dataclass
class SequenceRun:
    """A sequence render and the measure of the call that made it (every frame's, for a sandboxed one)."""

    result: SequenceResult
    timing: Timing


def frame_list(scene: Scene, frames: Sequence[int] | None = None) -> list[int]:
    """``frames`` checked against ``scene``'s frame count (ValueError naming the first outside it), or every
    frame of the scene; sorted, each once: a stateful renderer's state runs forward in time."""
    count = scene.frame_count
    wanted = sorted({int(i) for i in frames}) if frames is not None else list(range(count))
    if not wanted:
        raise ValueError("no frames to render")
    bad = [i for i in wanted if not 0 <= i < count]
    if bad:
        raise ValueError(f"frame {bad[0]} is outside the scene's {count} frames (0 to {count - 1})")
    return wanted


def render_sequence(entry: RendererEntry, scene: Scene, spp: int, seed: int, frames: Sequence[int] | None = None,
                    time_limit_s: float | None = None) -> SequenceResult:
    """``frames`` (default every frame) of animated ``scene`` rendered by ``entry`` at ``spp`` from ``seed``:
    one :class:`~cornell_harness.adapters.api.RenderResult` per frame in frame order, and the renderer's state.

    With ``time_limit_s`` (or the entry's own) the sequence runs in a sandboxed child ended at it
    (:class:`~cornell_harness.workflows.render.RenderTimeout`); a renderer's failure there is a
    :class:`~cornell_harness.workflows.render.RenderError` carrying the child's traceback.
    """
    return render_sequence_timed(entry, scene, spp, seed, frames, time_limit_s).result


def render_sequence_timed(entry: RendererEntry, scene: Scene, spp: int, seed: int,
                          frames: Sequence[int] | None = None, time_limit_s: float | None = None) -> SequenceRun:
    """:func:`render_sequence` with the measure of its call (:func:`cornell_harness.workflows.timing.measure`)."""
    frames = frame_list(scene, frames)
    limit = time_limit_s if time_limit_s is not None else entry.time_limit_s
    if limit is None:
        result, timing = measure(lambda: render_sequence_checked(entry, scene, spp, seed, frames))
        return SequenceRun(result, timing)
    out = run_sandboxed_sequence(entry.spec, scene, spp, seed, frames, limit, settings=dict(entry.settings))
    if out.ended == "timeout":
        raise RenderTimeout(f"killed at its time limit of {limit:g} s (ran {out.time_s:.1f} s)", out.time_s)
    if (why := out.problem()) is not None:
        raise RenderError(why, out.traceback)
    results = [RenderResult(image, t, s, seed if sd is None else int(sd), info=info, variance=variance,
                            cpu_time_s=cpu)
               for image, t, s, sd, info, variance, cpu in zip(out.images, out.render_times, out.spps, out.seeds,
                                                               out.infos, out.variances, out.cpu_times)]
    return SequenceRun(SequenceResult(results, dict(out.state)), out.timings[0])
