"""``cbox sequence``'s work: render an animated scene's frames with each renderer at each seed, score every frame
against its reference, and the sequence's temporal figures; write the results.

One (renderer, seed) is one task of the executor (:mod:`cornell_harness.workflows.executor`): its sequence is one
render (:func:`cornell_harness.workflows.sequence.render_sequence_timed`, sandboxed as one job with a time limit),
so a stateful renderer's state never crosses tasks. What the scene's motion gives every renderer's figures alike
(the change frame lag follows, the disocclusion masks, the flicker floor) is computed once, here, from the scene
and its references (:class:`SceneMotion`). Every frame is scored by the one scorer
(:func:`cornell_harness.workflows.runner.score`): a frame's row has every metric a still image's has, and its
``frame``; a sequence's row has the temporal metrics (:mod:`cornell_harness.evaluate.temporal`) and the mean over
frames of each per-image metric. A renderer's failure is a failed row, as in every other command.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from cornell_harness.adapters.registry import RendererEntry
from cornell_harness.evaluate import temporal
from cornell_harness.evaluate.disocclusion import disocclusion_masks
from cornell_harness.evaluate.registry import IMAGE_METRICS, LAG_METRIC, TEMPORAL_METRICS
from cornell_harness.scenes.model import Scene
from cornell_harness.store.atomic import atomic_path, json_safe, write_json_atomic
from cornell_harness.store.references import Reference, load_reference
from cornell_harness.workflows import runner
from cornell_harness.workflows.executor import InProcess, Task, task_key
from cornell_harness.workflows.render import RenderTimeout
from cornell_harness.workflows.sequence import frame_list, render_sequence_timed


@dataclass
class SceneMotion:
    """What the reference's motion gives every renderer's temporal figures: the frames, the change frame lag
    follows (its position in ``frames``; None: nothing settles before the steady frames), each frame's
    disocclusion mask and the flicker floor."""

    frames: list[int]
    change: int | None
    masks: np.ndarray
    floor: float


@dataclass
class SequenceOutcome:
    """Every frame's row, every sequence's row, and the first seed's frames of each renderer (for the report)."""

    frame_rows: list[dict] = field(default_factory=list)
    sequence_rows: list[dict] = field(default_factory=list)
    images: dict = field(default_factory=dict)  # renderer -> (F, H, W, 3) float32


def scene_motion(scene: Scene, frames: Sequence[int], references: Sequence[Reference]) -> SceneMotion:
    """The :class:`SceneMotion` of ``frames`` of ``scene`` (taken as consecutive) with their ``references``."""
    stills = [scene.at_frame(i) for i in frames]
    changes = temporal.settle_frames(scene.animation.states(frames))
    if len(frames) >= 3:
        first_steady = temporal.steady_band(np.zeros(len(frames)))[2]
        changes = [c for c in changes if c < first_steady]
    else:
        changes = []
    floor = temporal.flicker_floor(np.stack([r.variance for r in references]))
    return SceneMotion(list(frames), changes[-1] if changes else None, disocclusion_masks(stills), floor)


def sequence_references(scene: Scene, frames: Sequence[int]) -> list[Reference]:
    """Each frame's stored reference, ``load_reference(scene.at_frame(i))``, loaded once for the frames that share
    it (:meth:`~cornell_harness.scenes.animation.Animation.reference_frame`); ReferenceError for a missing one."""
    loaded: dict[int, Reference] = {}
    out = []
    for i in frames:
        still = scene.at_frame(i)
        if still.reference_frame not in loaded:
            loaded[still.reference_frame] = load_reference(still)
        out.append(loaded[still.reference_frame])
    return out


def sequence_task(entry: RendererEntry, scene: Scene, spp: int, seed: int, references: Sequence[Reference],
                  motion: SceneMotion, time_limit_s: float | None = None) -> tuple[list[dict], dict, np.ndarray | None]:
    """One (renderer, seed): its frames' rows, its sequence's row, and its frames (None if it did not render)."""
    rec = runner.RunRecord.new(scene, entry, spp, seed)
    if rec.status != "ok":
        return [], _sequence_row(rec, motion), None
    try:
        rec.version = str(entry.renderer.version())
        run = render_sequence_timed(entry, scene, spp, seed, motion.frames, time_limit_s)
    except RenderTimeout as e:
        rec.status, rec.reason, rec.time_s, rec.info = "failed", str(e), e.time_s, {"timed_out": True}
        return [], _sequence_row(rec, motion), None
    except Exception as e:  # a renderer's bug is a failed row, not a crash
        return [], _sequence_row(rec.failed(e), motion), None
    frame_rows, errors = [], []
    for i, result, reference in zip(motion.frames, run.result.frames, references):
        frame = runner.RunRecord.new(scene, entry, spp, seed, version=rec.version, time_s=float(result.time_s),
                                     info=dict(result.info))
        frame.timed(result, run.timing)
        if result.cpu_time_s is None:  # the call's CPU time is the whole sequence's, not this frame's
            frame.cpu_time_s = None
            frame.info.pop("cpu_time_of", None)
        frame.metrics, frame.regions = runner.score(scene.at_frame(i), result.image, reference, spp,
                                                    result.variance)
        row = frame.row()
        row.update(frame=i, frame_seed=int(result.seed))
        frame_rows.append(row)
        errors.append(frame.metrics.get(LAG_METRIC, math.nan))
    images = np.stack([r.image for r in run.result.frames])
    refs = np.stack([r.image for r in references])
    rec.time_s = float(sum(r.time_s for r in run.result.frames))
    rec.timed(run.result.frames[0], run.timing)
    cpu = [r.cpu_time_s for r in run.result.frames]
    rec.cpu_time_s = run.timing.cpu_s if None in cpu else float(sum(cpu))
    rec.info = {"state": run.result.state}
    row = _sequence_row(rec, motion)
    row.update(time_per_frame_s=rec.time_s / len(motion.frames), flicker=temporal.flicker(images, refs),
               ghosting=temporal.ghosting(images, refs, motion.masks),
               lag=math.nan if motion.change is None else temporal.lag(errors, motion.change))
    for key in IMAGE_METRICS:
        values = [r[key] for r in frame_rows if isinstance(r.get(key), (int, float))]
        if values:
            row[key] = float(np.mean(values))
    return frame_rows, row, images


def sequence_record(entry: RendererEntry, scene: Scene, spp: int, seed: int, references: Sequence[Reference],
                    time_limit_s: float | None = None) -> runner.RunRecord:
    """Every frame of ``scene`` rendered and scored as one :class:`~cornell_harness.workflows.runner.RunRecord`
    (what the gate checks): its metrics the sequence's row's (temporal figures, per-image means over frames), its
    NaN and Inf counts summed over frames, its image the last frame's."""
    frames = frame_list(scene)
    motion = scene_motion(scene, frames, references)
    frame_rows, row, images = sequence_task(entry, scene, spp, seed, references, motion, time_limit_s)
    rec = runner.RunRecord.new(scene, entry, spp, seed, version=row.get("version"), time_s=row.get("time_s"))
    rec.status, rec.reason = row["status"], row["reason"]
    if rec.status != "ok":
        rec.info = {"timed_out": True} if "time limit" in str(rec.reason) else {}
        return rec
    rec.metrics = {k: row[k] for k in (*IMAGE_METRICS, *TEMPORAL_METRICS) if k in row}
    for key in ("nan_count", "inf_count", "negative_count"):
        rec.metrics[key] = int(sum(r.get(key) or 0 for r in frame_rows))
    rec.image = images[-1]
    return rec


def _sequence_row(rec: runner.RunRecord, motion: SceneMotion) -> dict:
    row = rec.row()
    change = None if motion.change is None else motion.frames[motion.change]
    bound = None if motion.change is None else temporal.lag_bound(len(motion.frames), motion.change)
    row.update(frames=len(motion.frames), first_frame=motion.frames[0], change_frame=change, lag_bound=bound,
               flicker_floor=motion.floor)
    return row


def run_sequence(entries: Sequence[RendererEntry], scene: Scene, spp: int, seeds: Sequence[int],
                 references: Sequence[Reference], frames: Sequence[int] | None = None,
                 time_limit_s: float | None = None, executor=None) -> SequenceOutcome:
    """Every renderer of ``entries`` at every seed on ``frames`` (default all) of ``scene``, scored against
    ``references`` (one per frame, in order: :func:`sequence_references`). One task per (renderer, seed) on
    ``executor`` (default in this process)."""
    frames = frame_list(scene, frames)
    if len(references) != len(frames):
        raise ValueError(f"{len(references)} references for {len(frames)} frames")
    motion = scene_motion(scene, frames, references)
    executor = executor or InProcess()
    shared = [executor.share(x) for x in (scene, list(references), motion)]
    tasks = [Task(task_key("sequence", scene.content_hash(), e.spec, e.settings, spp, seed, frames),
                  f"{e.name} seed {seed}", sequence_task_of, (e.spec, e.settings, *shared, spp, seed, time_limit_s,
                                                               e if executor.local else None))
             for e in entries for seed in seeds]
    out = SequenceOutcome()
    for outcome in executor.run(tasks):
        if outcome.error is not None:
            raise RuntimeError(f"{outcome.task.label}: {outcome.error}")
        frame_rows, row, images = outcome.value
        out.frame_rows += frame_rows
        out.sequence_rows.append(row)
        if images is not None and row["renderer"] not in out.images:
            out.images[row["renderer"]] = images
    return out


def sequence_task_of(spec: str, settings: dict, scene: Scene, references: list, motion: SceneMotion, spp: int,
                     seed: int, time_limit_s: float | None, entry: RendererEntry | None = None):
    """The executor's task: :func:`sequence_task` with the caller's ``entry`` in this process, else the
    renderer of ``spec`` loaded on the worker (:func:`cornell_harness.workflows.cells.entry_for`)."""
    from cornell_harness.workflows.cells import entry_for

    entry = entry or entry_for(spec, settings)
    return sequence_task(entry, scene, spp, seed, references, motion, time_limit_s)


def write_sequence_results(folder: str | Path, outcome: SequenceOutcome) -> list[Path]:
    """``frames.csv`` (a row per renderer, seed and frame), ``sequences.csv`` and ``sequences.json`` (a row per
    renderer and seed), each written atomically; their paths."""
    folder = Path(folder)
    paths = [folder / "frames.csv", folder / "sequences.csv", folder / "sequences.json"]
    for path, rows in zip(paths[:2], (outcome.frame_rows, outcome.sequence_rows)):
        with atomic_path(path) as tmp:
            _frame(rows).to_csv(tmp, index=False)
    write_json_atomic(paths[2], [runner.json_row(json_safe(r)) for r in outcome.sequence_rows])
    return paths


def _frame(rows: list[dict]):
    import pandas as pd

    return pd.DataFrame([{k: json.dumps(v) if isinstance(v, (dict, list)) else v for k, v in r.items()}
                         for r in rows])

