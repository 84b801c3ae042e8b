"""Equal-time and equal-quality comparisons: the spp a time budget buys, the time a target error costs."""

from __future__ import annotations

import datetime as _dt
from pathlib import Path
from typing import Sequence

import pandas as pd

from harness.adapters.api import attribute
from harness.adapters.registry import RendererEntry
from harness.scenes.model import Scene
from harness.store.atomic import atomic_path, json_safe, write_json_atomic
from harness.store.experiments import (CONFIG_FILE, RESULTS_FILE, ExperimentError, cell_name, experiment_lock,
                                       write_parquet_atomic)
from harness.store.exr import write_exr
from harness.store.references import Reference
from harness.workflows import runner
from harness.workflows.render import render_checked


def spp_for_time_budget(entry: RendererEntry, scene: Scene, budget_s: float, seed: int) -> int:
    """The spp that should take ``budget_s`` seconds, from two short timed renders (1 and 4 spp).

    Per-render overhead (scene set-up) and per-sample cost are separated by
    the two timings. Where the 1-spp render reads as long as the 4-spp one
    (stalled by a busy machine: load only adds time), the difference says nothing
    about the per-sample cost (floored at 1e-9 s it gives ~10⁹ spp, a
    render without end); t4 / 4 is then used, an upper bound on
    the per-sample cost (the overhead is ≥ 0): fewer samples than the budget
    buys, never more. The calibration renders are not counted in the budget;
    the final render's own time is what is reported.
    """
    t1 = render_checked(entry, scene, 1, seed).time_s
    t4 = render_checked(entry, scene, 4, seed).time_s
    per_spp = (t4 - t1) / 3.0 if t4 > t1 else t4 / 4.0
    per_spp = max(per_spp, 1e-9)  # a renderer that reports no time at all
    overhead = max(t4 - 4.0 * per_spp, 0.0)  # (4·t1 - t4) / 3 when t4 > t1; 0 in the fallback
    return max(1, int((budget_s - overhead) / per_spp))


def render_to_target(entry: RendererEntry, scene: Scene, reference: Reference, metric: str, target: float,
                     seed: int, max_spp: int) -> runner.RunRecord:
    """Renders at 1, 2, 4, ... spp until ``metric`` ≤ ``target`` (or ``max_spp``); the record says which.

    The reported time is that of the render that reached the target (a
    renderer that resumed its last render would need at most that). A
    deterministic renderer stops early once two doublings of spp leave its error unchanged.
    """
    spp, previous, stalls = 1, None, 0
    deterministic = attribute(entry.renderer, "deterministic")
    while True:
        rec = runner.run_one(entry, scene, spp, seed, reference)
        if rec.status != "ok":
            return rec
        value = rec.metrics.get(metric)
        if value is None:
            raise ExperimentError(f"--target-error: unknown metric {metric!r}")
        rec.info["target"] = f"{metric}<={target:g}"
        rec.info["target_reached"] = bool(value <= target)
        # A deterministic renderer whose error stopped changing for two doublings will not reach it
        # with more samples (1e-6: GL rasterisers are repeatable only to float rounding).
        same = deterministic and previous is not None and abs(value - previous) <= 1e-6 * abs(previous)
        stalls = stalls + 1 if same else 0
        if value <= target or spp >= max_spp or stalls >= 2:
            return rec
        spp, previous = min(2 * spp, max_spp), value


def store_comparison(out: Path, scene: Scene, records: Sequence[runner.RunRecord], command: str) -> None:
    """A comparison as an experiment folder: images, results table, CSV and JSON (a report can then be built)."""
    with experiment_lock(out, command):
        _store(out, scene, records, command)


def _store(out: Path, scene: Scene, records: Sequence[runner.RunRecord], command: str) -> None:
    for r in records:
        if r.image is not None:
            write_exr(out / "images" / f"{cell_name(r.renderer, r.seed)}.exr", r.image)
    rows = [r.row() for r in records]
    frame = pd.DataFrame(rows)
    write_json_atomic(out / CONFIG_FILE, {
        "kind": "compare", "scene": str(scene.path), "scene_name": scene.name, "scene_hash": scene.content_hash(),
        "renderers": [r.renderer for r in records], "spp": sorted({r.spp for r in records}),
        "seeds": sorted({r.seed for r in records}), "command": command,
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")})
    write_parquet_atomic(frame, out / RESULTS_FILE)
    with atomic_path(out / "metrics.csv") as tmp:
        frame.to_csv(tmp, index=False)
    write_json_atomic(out / "metrics.json", [json_safe(r) for r in rows])
