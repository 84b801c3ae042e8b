"""The unit of work of a sweep: a cell, one renderer with its settings at one seed on one scene, rendered at a
list of spp checkpoints; its content-hash key, and rendering it in any process.

A :class:`Cell` travels to a worker as plain data: the renderer as its spec
(``package.module:Class``) and settings, re-resolved in the worker process
(:func:`entry_for`), so Embree and Mitsuba scenes are built there, inside the
renderer's ``render``, never pickled; in-process the caller's own renderer
object renders it. The scene and reference travel as the executor shares
them (:meth:`cornell_harness.workflows.executor.DaskExecutor.share`). The worker
sends back the cell's metric rows and final image (compressed by the
executor); the client alone writes the experiment folder
(:mod:`cornell_harness.workflows.converge`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from cornell_harness.adapters.registry import RendererEntry, resolve
from cornell_harness.adapters.settings import canonical
from cornell_harness.scenes.model import Scene
from cornell_harness.store.references import Reference
from cornell_harness.workflows import runner
from cornell_harness.workflows.executor import task_key

#: Renderers a worker process loaded, by (spec, canonical settings): loaded at its first cell, kept for the next.
_LOADED: dict[tuple[str, str], RendererEntry] = {}


@dataclass(frozen=True)
class Cell:
    """One (renderer with its settings, seed) of a sweep, at the spp checkpoints it still lacks."""

    name: str  # the cell's file stem (cornell_harness.store.experiments.cell_name)
    spec: str  # package.module:Class, loadable on any worker
    settings: dict = field(hash=False)
    seed: int = 0
    spps: tuple[int, ...] = ()
    scene_hash: str = ""
    time_limit_s: float | None = None  # each render's (RendererEntry.time_limit_s); not what the cell computes

    @property
    def key(self) -> str:
        """Content hash of what the cell computes: the same key is the same work (rendered once at a time)."""
        return task_key("cell", self.scene_hash, self.spec, canonical(self.settings), self.seed, list(self.spps))

    @property
    def label(self) -> str:
        """``pathtracer seed 2``, for progress."""
        return self.name.replace("__seed", " seed ")


def entry_for(spec: str, settings: dict) -> RendererEntry:
    """The renderer of ``spec`` with ``settings``, loaded once per worker process."""
    key = (spec, canonical(settings))
    if key not in _LOADED:
        (entry,) = resolve([spec])
        _LOADED[key] = entry.with_settings(settings) if entry.available else entry
    return _LOADED[key]


def render_cell(entry: RendererEntry, scene: Scene, spps: Sequence[int], seed: int,
                reference: Reference) -> tuple[list[dict], np.ndarray | None]:
    """Rows for every spp of one (renderer, seed), and its highest-spp image (None if it failed)."""
    records = runner.run_checkpoints(entry, scene, spps, seed, reference)
    if records[-1].status != "ok":
        return [r.row() for r in records], None
    return [r.row() for r in records], records[-1].image


def render_cell_task(cell: Cell, scene: Scene, reference: Reference,
                     entry: RendererEntry | None = None) -> tuple[list[dict], np.ndarray | None]:
    """The task a backend runs for a cell: :func:`render_cell`. In-process the caller's own ``entry`` renders
    it (the same object, its caches warm); on a worker, the cell's spec loaded there."""
    entry = (entry or entry_for(cell.spec, cell.settings)).with_time_limit(cell.time_limit_s)
    return render_cell(entry, scene, cell.spps, cell.seed, reference)


def failed_rows(cell: Cell, entry: RendererEntry, scene: Scene, reason: str) -> list[dict]:
    """The row of a cell the executor gave up on (it raised, or its workers died, past its retries)."""
    rec = runner.RunRecord.new(scene, entry, spp=cell.spps[-1], seed=cell.seed)
    rec.status, rec.reason = "failed", f"not rendered: {reason}"
    return [rec.row()]
