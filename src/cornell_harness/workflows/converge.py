"""Convergence experiments: every metric at every spp checkpoint, per renderer and seed, resumable.

The folder layout is :mod:`cornell_harness.store.experiments`. A run that is
interrupted keeps every finished cell; running the same command again loads
finished cells instead of rendering them, and a longer spp list renders only
the checkpoints a cell lacks. One run at a time writes a folder. Cells
(:mod:`cornell_harness.workflows.cells`) render wherever the executor puts them
(:mod:`cornell_harness.workflows.executor`); the folder is written here only.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import time
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import pandas as pd

from cornell_harness.adapters.api import attribute, machine_cores
from cornell_harness.adapters.registry import RendererEntry
from cornell_harness.evaluate import convergence, timing_stats
from cornell_harness.evaluate.summary import ExperimentResults, summary_table
from cornell_harness.evaluate.timing_quality import auto_basis
from cornell_harness.scenes.model import Scene
from cornell_harness.store.atomic import atomic_path
from cornell_harness.store.experiments import (RESULTS_FILE, SUMMARY_FILE, cell_name, experiment_lock, final_images,
                                       load_results, prepare_dir, spps_to_render, stored_cell, write_parquet_atomic)
from cornell_harness.store.exr import ImageFileError, read_exr, write_exr
from cornell_harness.store.image_files import SPP_ATTRIBUTE, header_spp, read_image_file
from cornell_harness.store.references import Reference
from cornell_harness.workflows import runner
from cornell_harness.workflows.cells import Cell, entry_for, failed_rows, render_cell_task
from cornell_harness.workflows.executor import DaskExecutor, InProcess, Task, task_key


def _not_run_row(entry: RendererEntry, scene: Scene) -> dict | None:
    """The row of a renderer that will not run here (unavailable or missing a feature), else None."""
    rec = runner.RunRecord.new(scene, entry, spp=0, seed=0)
    if rec.status == "ok":
        return None
    row = rec.row()
    row["spp"] = row["seed"] = math.nan
    return row


#: Seconds at least between rewrites of results.parquet while cells finish (always written at the end).
RESULTS_EVERY_S = 1.0


def run_experiment(
    out: Path,
    scene: Scene,
    reference: Reference,
    entries: Sequence[RendererEntry],
    spps: Sequence[int],
    seeds: Sequence[int],
    command: str = "",
    kind: str = "converge",
    on_cell: Callable[[str, bool], None] | None = None,
    targets=convergence.DEFAULT_TARGETS,
    executor: InProcess | DaskExecutor | None = None,
    on_failed: Callable[[str, str], None] | None = None,
    time_repeats: int = 1,
    time_basis: str = "wall",
    on_repeat: Callable[[str, bool], None] | None = None,
    on_start: Callable[[str], None] | None = None,
) -> pd.DataFrame:
    """Run (or resume) every (renderer, seed) cell; return the tidy results table.

    Cells run on ``executor`` (default: in this process, in order;
    :mod:`cornell_harness.workflows.executor`), finished ones in any order; this
    process alone writes the folder, each cell as it arrives, and the table
    in the cells' planned order, so every backend writes the same table.
    ``on_cell(name, cached)`` is called after each cell (for progress bars),
    ``on_failed(name, reason)`` before it for a cell that failed;
    ``on_start(name)`` once, naming the first cell to render, as rendering starts.

    With ``time_repeats`` K > 1 each cell's final checkpoint is timed K times
    in all: the extra renders run after the cells, in rounds over the cells
    (:func:`_repeat_tasks`), each stored as it arrives, so a rerun keeps
    them and renders only those missing; ``on_repeat(name, stored)`` follows
    each. ``time_basis`` (wall or cpu, recorded in experiment.json) is the
    clock the summary's time-derived figures read (:func:`experiment_results`).
    """
    out = Path(out)
    spps = sorted({int(s) for s in spps})
    executor = executor or InProcess()
    with experiment_lock(out, command):
        prepare_dir(out, {
            "kind": kind, "scene": str(scene.path), "scene_name": scene.name, "scene_hash": scene.content_hash(),
            "renderers": [e.name for e in entries], "spp": spps, "seeds": list(seeds), "command": command,
            "targets": [list(t) for t in targets],
            "deterministic": [e.name for e in entries if attribute(e.renderer, "deterministic")],
            "time_repeats": time_repeats, "time_basis": time_basis,
        })
        table = _Table(out / RESULTS_FILE)
        pending: dict[str, tuple[list[int], Cell, RendererEntry, pd.DataFrame | None]] = {}
        timed: dict[str, tuple[Cell, RendererEntry, list[int]]] = {}  # every cell, by name: for its repeats
        for entry in entries:
            if (row := _not_run_row(entry, scene)) is not None:
                table.not_run.append(row)
                continue
            for seed in (seeds[:1] if attribute(entry.renderer, "deterministic") else seeds):
                name = cell_name(entry.name, seed)
                whole = Cell(name, entry.spec, dict(entry.settings), seed, tuple(spps), scene.content_hash(),
                             entry.time_limit_s)
                timed.setdefault(name, (whole, entry, []))[2].append(len(table.frames))
                stored, todo = _plan(out, name, scene, spps)
                if not todo:  # finished before: loaded, never rendered again
                    table.frames.append(stored[stored["spp"].astype(int).isin(spps)].reset_index(drop=True))
                    table.write(now=False)
                    if on_cell:
                        on_cell(name, True)
                    continue
                cell = Cell(name, entry.spec, dict(entry.settings), seed, tuple(todo), scene.content_hash(),
                            entry.time_limit_s)
                # The same work twice (a renderer named twice) renders once and fills both places.
                pending.setdefault(cell.key, ([], cell, entry, stored))[0].append(len(table.frames))
                table.frames.append(None)
        if pending:
            if on_start:
                on_start(next(iter(pending.values()))[1].name)
            shared = executor.share(scene), executor.share(reference)
            tasks = [Task(key, cell.label, render_cell_task, (cell, *shared, entry if executor.local else None))
                     for key, (_, cell, entry, _) in pending.items()]
            for outcome in executor.run(tasks):
                slots, cell, entry, stored = pending[outcome.task.key]
                if outcome.error is None:
                    rows = store_cell(out, cell, stored, *outcome.value, spps)
                else:  # recorded, not stored: a rerun renders it again
                    rows = pd.DataFrame(failed_rows(cell, entry, scene, outcome.error))
                for slot in slots:
                    table.frames[slot] = rows
                table.write(now=False)
                for _ in slots:
                    if on_failed and (rows["status"] == "failed").any():
                        on_failed(cell.name, str(rows["reason"].iloc[-1]))
                    if on_cell:
                        on_cell(cell.name, False)
        if time_repeats > 1:
            _run_repeats(out, scene, executor, table, timed, spps, time_repeats, on_repeat)
        results = table.write()
    return results


def _run_repeats(out: Path, scene: Scene, executor, table: "_Table", timed: dict, spps: list[int], k: int,
                 on_repeat: Callable[[str, bool], None] | None) -> None:
    """Time every finished cell's final checkpoint until it has ``k`` timings: the missing repeats as tasks
    (:func:`_repeat_tasks`), each outcome stored in the cell's file at once (:func:`add_timing`)."""
    have = {}
    for name, (_, _, slots) in timed.items():
        rows = table.frames[slots[0]]
        top = rows[rows["spp"].astype(int) == spps[-1]] if rows is not None and "spp" in rows else None
        if top is None or len(top) != 1 or top["status"].iloc[0] != "ok":
            continue  # failed, or not run: nothing to re-time
        have[name] = len(row_timings(top.iloc[0].to_dict())[0])
        for _ in range(min(have[name], k) - 1):
            if on_repeat:
                on_repeat(name, True)
    tasks = _repeat_tasks({n: timed[n][0] for n in have}, {n: timed[n][1] for n in have}, have, k, executor,
                          scene)
    digests: dict[str, str | None] = {}  # the first render's image, stored: a repeat's must be the same
    for outcome in executor.run(tasks.values()):
        name = outcome.task.args[0].name  # the cell's
        slots = timed[name][2]
        if name not in digests:
            try:
                digests[name] = image_digest(read_exr(out / "images" / f"{name}.exr"))
            except ImageFileError:  # not there to compare with: the repeat's timing still counts
                digests[name] = None
        value = outcome.value if outcome.error is None else (None, None, None, outcome.error)
        rows = add_timing(pd.read_parquet(out / "cells" / f"{name}.parquet"), spps[-1], value, digests[name])
        write_parquet_atomic(rows, out / "cells" / f"{name}.parquet")
        for slot in slots:
            table.frames[slot] = rows[rows["spp"].astype(int).isin(spps)].reset_index(drop=True)
        table.write(now=False)
        if on_repeat:
            on_repeat(name, False)


def _repeat_tasks(cells: dict[str, Cell], entries: dict[str, RendererEntry], have: dict[str, int], k: int,
                  executor, scene: Scene) -> dict[str, Task]:
    """The repeats still missing, as tasks in rounds over the cells: every cell's second timing, then every
    third, ... (a cell that has some already joins at the round of its next). In-process they run in that
    order, so a change of load hits every renderer alike; on Dask the scheduler orders them (and spreads them
    over the workers): interleaving is then not promised."""
    shared = executor.share(scene) if any(n < k for n in have.values()) else None
    tasks = {}
    for index in range(2, k + 1):
        for name, cell in cells.items():
            if have[name] < index:
                key = task_key("repeat", cell.key, index)
                tasks[key] = Task(key, f"{cell.label} repeat {index}/{k}", repeat_cell_task,
                                  (cell, shared, entries[name] if executor.local else None))
    return tasks


def repeat_cell_task(cell: Cell, scene: Scene, entry: RendererEntry | None = None
                     ) -> tuple[float | None, float | None, str | None, str | None]:
    """One more timing of a cell's final checkpoint, the same render as its first (same spp, seed and
    checkpoints): (wall s, CPU s or None, the image's digest, None), or (None, None, None, why) where it raised
    (recorded in the row, not raised: in-process an exception would end the run)."""
    entry = entry or entry_for(cell.spec, cell.settings)
    try:
        result, timing = runner.render_timed(entry, scene, cell.spps[-1], cell.seed, cell.spps)
    except Exception as e:
        return None, None, None, f"{type(e).__name__}: {e}"
    return float(result.time_s), runner.cpu_time(result, timing), image_digest(result.image), None


def image_digest(image: np.ndarray) -> str:
    """A digest of an image's float32 pixels: the same render, bit for bit, the same digest."""
    return hashlib.sha256(np.ascontiguousarray(image, dtype=np.float32).tobytes()).hexdigest()


def row_timings(row: dict) -> tuple[list[float], list[float | None]]:
    """A results row's timings, wall and CPU (None where unknown): its ``time_samples_s`` (K of them), or
    for a row written before repeats were recorded its one ``time_s``."""
    text, cpu_text = row.get("time_samples_s"), row.get("cpu_time_samples_s")
    if isinstance(text, str):
        wall = [float(x) for x in json.loads(text)]
        cpu = json.loads(cpu_text) if isinstance(cpu_text, str) else []
        return wall, [float(c) for c in cpu] if len(cpu) == len(wall) else [None] * len(wall)
    cpu = row.get("cpu_time_s")
    known = cpu is not None and not (isinstance(cpu, float) and math.isnan(cpu))
    return [float(row["time_s"])], [float(cpu) if known else None]


def add_timing(rows: pd.DataFrame, spp: int, repeat: tuple, first_digest: str | None) -> pd.DataFrame:
    """A cell's rows with one more timing of its row at ``spp``: ``repeat`` is :func:`repeat_cell_task`'s
    (wall, cpu, digest, error). ``time_s`` (and ``cpu_time_s``) become the medians, the repeat columns follow
    (:func:`cornell_harness.evaluate.timing_stats.repeat_columns`) and so does ``efficiency``; an image unlike the
    first counts in ``info_repeat_images_differ``, an error is kept in ``info_time_repeat_error``."""
    wall_s, cpu_s, digest, error = repeat
    records = rows.to_dict("records")
    (i,) = [j for j, r in enumerate(records) if int(r["spp"]) == spp]
    row = records[i]
    if error is not None:
        row["info_time_repeat_error"] = error
        return pd.DataFrame(records)
    wall, cpu = row_timings(row)
    wall.append(wall_s)
    cpu.append(cpu_s)
    cols = timing_stats.repeat_columns(wall, cpu)
    median_wall, median_cpu = timing_stats.medians(wall, cpu)
    cols["time_s"] = round(median_wall, 4)
    if median_cpu is not None:
        cols["cpu_time_s"] = median_cpu
    if "efficiency" in rows and row.get("mse") is not None and cols["time_s"]:  # as RunRecord.row() has it
        cols["efficiency"] = 1.0 / (row["mse"] * cols["time_s"]) if row["mse"] > 0 else math.inf
    if first_digest is not None and digest != first_digest:
        before = row.get("info_repeat_images_differ")
        cols["info_repeat_images_differ"] = (0 if before is None or before != before else int(before)) + 1
    row.update(cols)
    return pd.DataFrame(records)


class _Table:
    """``results.parquet`` of a run: the cells' rows in planned order (whatever order they finish in), then the
    renderers that did not run; rewritten as cells finish, but not after every one of thousands of quick cells:
    the cells are the record (a rerun rebuilds the table from them)."""

    def __init__(self, path: Path):
        self.path = path
        self.frames: list[pd.DataFrame | None] = []  # per planned cell, None until it is done
        self.not_run: list[dict] = []
        self._last, self._cost = -math.inf, 0.0  # when it was last written, and how long that took

    def write(self, now: bool = True) -> pd.DataFrame | None:
        """The table so far, written; unless ``now``, only once the last write is RESULTS_EVERY_S old and ten
        times its own duration (a client writing a large table spends at most a tenth of its time on it)."""
        if not now and time.monotonic() - self._last < max(RESULTS_EVERY_S, 10 * self._cost):
            return None
        start = time.monotonic()
        table = pd.concat([f for f in self.frames if f is not None] + [pd.DataFrame(self.not_run)],
                          ignore_index=True)
        write_parquet_atomic(table, self.path)
        self._last = time.monotonic()
        self._cost = self._last - start
        return table


def _plan(out: Path, name: str, scene: Scene, spps: list[int]) -> tuple[pd.DataFrame | None, list[int]]:
    """A cell's stored rows (None if none) and the spps it must still render (:func:`spps_to_render`)."""
    stored = stored_cell(out / "cells" / f"{name}.parquet", scene)
    have = stored["spp"].astype(int).tolist() if stored is not None else []
    image_spp = _image_spp(out / "images" / f"{name}.exr") if stored is not None else None
    return stored, spps_to_render(have, image_spp, spps)


def store_cell(out: Path, cell: Cell, stored: pd.DataFrame | None, rows_list: list[dict],
                image: np.ndarray | None, spps: list[int]) -> pd.DataFrame:
    """Write a rendered cell (image first, then its rows, each atomically); its rows at ``spps``."""
    cell_path, image_path = out / "cells" / f"{cell.name}.parquet", out / "images" / f"{cell.name}.exr"
    todo = list(cell.spps)
    rendered = pd.DataFrame(rows_list)
    if image is None:  # failed: its rows are reported, nothing is stored
        return rendered
    if todo[-1] == spps[-1]:  # image first: a cell's rows promise its image exists
        write_exr(image_path, image, {SPP_ATTRIBUTE: str(todo[-1])})
    kept = stored[~stored["spp"].astype(int).isin(todo)] if stored is not None else None
    rows = pd.concat([kept, rendered], ignore_index=True) if kept is not None and len(kept) else rendered
    rows = rows.sort_values("spp", kind="stable").reset_index(drop=True)
    write_parquet_atomic(rows, cell_path)
    return rows[rows["spp"].astype(int).isin(spps)].reset_index(drop=True)


def _image_spp(path: Path) -> int | None:
    """The spp a cell's stored image was rendered at (its header), None if unknown: then it is rendered again."""
    try:
        return header_spp(read_image_file(path))
    except ImageFileError:
        return None


def experiment_results(out: Path, scene: Scene, reference: Reference,
                       summary_dir: Path | None = None, time_basis: str | None = None) -> ExperimentResults:
    """What the experiment folder ``out`` holds, and its summary (:mod:`cornell_harness.evaluate.summary`); no
    rendering. With ``summary_dir`` (the folder itself, or where its report goes) the summary is written
    there as ``summary.parquet`` (not when nothing ran; raw names, full precision): every experiment's is
    written here (the readable ``summary.csv`` and ``summary.tex`` are the report's).

    ``time_basis`` (wall, cpu or auto; default: the one experiment.json records, else wall) is the clock the
    summary's time-derived figures read; the returned config holds the one used. Results without that
    column (CPU times of an older run) get it as NaN, with a warning: never wall time passed off as CPU."""
    config, runs = load_results(out)
    basis = time_basis or config.get("time_basis", "wall")
    if basis == "auto":  # cpu where these timings were contended
        basis = auto_basis(runs, machine_cores())
    config = {**config, "time_basis": basis}
    column = timing_stats.TIME_BASES[basis]
    if basis != "wall" and (column not in runs or not runs[column].notna().any()):  # no CPU times: NaN, said
        logging.getLogger(__name__).warning("--time-basis %s: %s holds no %s; time-derived figures are NaN",
                                            basis, out, column)
        runs = runs.assign(**{column: math.nan})
    images = final_images(out, runs)
    targets = [tuple(t) for t in config.get("targets", convergence.DEFAULT_TARGETS)]
    summary = summary_table(runs, images, reference, scene, targets, config.get("deterministic", ()),
                            time_column=column)
    if summary_dir is not None and not summary.empty:
        with atomic_path(Path(summary_dir) / SUMMARY_FILE) as tmp:
            summary.to_parquet(tmp, index=False)
    return ExperimentResults(config, runs, images, summary)
