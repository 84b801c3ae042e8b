"""Convergence experiments: every metric at every spp checkpoint, per renderer and seed, resumable.

The folder layout is :mod:`harness.store.experiments`. A run that is
interrupted keeps every finished cell; running the same command again loads
finished cells instead of rendering them, and a longer spp list renders only
the checkpoints a cell lacks. One run at a time writes a folder.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import pandas as pd

from harness.adapters.registry import RendererEntry
from harness.evaluate import convergence
from harness.evaluate.regions import nested_regions, region_columns, region_masks
from harness.scenes.model import Scene
from harness.store.experiments import (RESULTS_FILE, cell_name, experiment_lock, prepare_dir, spps_to_render,
                                       stored_cell, write_parquet_atomic)
from harness.store.exr import read_exr_metadata, write_exr
from harness.store.references import Reference
from harness.workflows import runner


def _not_run_row(entry: RendererEntry, scene: Scene) -> dict | None:
    """The row of a renderer that will not run here (unavailable or missing a feature), else None."""
    rec = runner.RunRecord.new(scene, entry, spp=0, seed=0)
    if rec.status == "ok":
        return None
    row = rec.row()
    row["spp"] = row["seed"] = math.nan
    return row


def render_cell(entry: RendererEntry, scene: Scene, spps: Sequence[int], seed: int,
                reference: Reference) -> tuple[list[dict], np.ndarray | None]:
    """Rows for every spp of one (renderer, seed), and its highest-spp image (None if it failed)."""
    records = runner.run_checkpoints(entry, scene, spps, seed, reference)
    if records[-1].status != "ok":
        return [r.row() for r in records], None
    return [r.row() for r in records], records[-1].image


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
) -> pd.DataFrame:
    """Run (or resume) every (renderer, seed) cell; return the tidy results table.

    ``on_cell(name, cached)`` is called after each cell (for progress bars).
    """
    out = Path(out)
    spps = sorted({int(s) for s in spps})
    with experiment_lock(out, command):
        prepare_dir(out, {
            "kind": kind, "scene": str(scene.path), "scene_name": scene.name, "scene_hash": scene.content_hash(),
            "renderers": [e.name for e in entries], "spp": spps, "seeds": list(seeds), "command": command,
            "targets": [list(t) for t in targets],
            "deterministic": [e.name for e in entries if getattr(e.renderer, "deterministic", False)],
        })
        frames, not_run = [], []
        for entry in entries:
            if (row := _not_run_row(entry, scene)) is not None:
                not_run.append(row)
                continue
            for seed in (seeds[:1] if getattr(entry.renderer, "deterministic", False) else seeds):
                name = cell_name(entry.name, seed)
                rows, cached = _cell(out, name, entry, scene, spps, seed, reference)
                frames.append(rows)
                write_parquet_atomic(pd.concat(frames + [pd.DataFrame(not_run)], ignore_index=True),
                                     out / RESULTS_FILE)
                if on_cell:
                    on_cell(name, cached)
        results = pd.concat(frames + [pd.DataFrame(not_run)], ignore_index=True)
        write_parquet_atomic(results, out / RESULTS_FILE)
    return results


def _cell(out: Path, name: str, entry: RendererEntry, scene: Scene, spps: list[int], seed: int,
          reference: Reference) -> tuple[pd.DataFrame, bool]:
    """One cell's rows at ``spps`` (rendering only the spps it lacks), and whether nothing was rendered."""
    cell_path, image_path = out / "cells" / f"{name}.parquet", out / "images" / f"{name}.exr"
    stored = stored_cell(cell_path, scene)
    have = stored["spp"].astype(int).tolist() if stored is not None else []
    image_spp = read_exr_metadata(image_path).get("cbox:spp") if stored is not None else None
    todo = spps_to_render(have, int(image_spp) if image_spp else None, spps)
    if not todo:
        return stored[stored["spp"].astype(int).isin(spps)].reset_index(drop=True), True
    rows_list, image = render_cell(entry, scene, todo, seed, reference)
    rendered = pd.DataFrame(rows_list)
    if image is None:  # failed: its rows are reported, nothing is stored
        return rendered, False
    if todo[-1] == spps[-1]:  # image first: a cell's rows promise its image exists
        write_exr(image_path, image, {"cbox:spp": str(todo[-1])})
    kept = stored[~stored["spp"].astype(int).isin(todo)] if stored is not None else None
    rows = pd.concat([kept, rendered], ignore_index=True) if kept is not None and len(kept) else rendered
    rows = rows.sort_values("spp", kind="stable").reset_index(drop=True)
    write_parquet_atomic(rows, cell_path)
    return rows[rows["spp"].astype(int).isin(spps)].reset_index(drop=True), False


def summary_table(runs: pd.DataFrame, images: dict[str, list[np.ndarray]], reference: Reference, scene: Scene,
                  targets=convergence.DEFAULT_TARGETS, deterministic: Sequence[str] = ()) -> pd.DataFrame:
    """Derived figures per renderer, with the bias/variance split from the stored images.

    For a scene with named regions the split is also given per region, as
    columns ``region.<name>.bias2``, ``.variance`` and ``.bias2_fraction``
    (:func:`harness.evaluate.convergence.region_bias_variance`).
    """
    summary = convergence.summarize(runs, targets)
    if summary.empty:
        return summary
    masks = region_masks(scene)
    rows = []
    for r in summary["renderer"]:
        finals, det = images.get(r, []), r in deterministic
        row = convergence.bias_variance(finals, reference.image, reference.variance, det)
        if masks:
            row.update(region_columns(convergence.region_bias_variance(finals, reference.image, reference.variance,
                                                                       masks, det)))
        rows.append(row)
    return pd.concat([summary, pd.DataFrame(rows)], axis=1)


#: The per-region columns :func:`summary_table` adds, in table order.
REGION_SPLIT = ("bias2", "variance", "bias2_fraction")


def region_split(summary: pd.DataFrame) -> pd.DataFrame:
    """The per-region bias/variance columns of a summary as long rows: renderer, region, bias2, variance,
    bias2_fraction (empty without them); in summary order, regions in column order."""
    rows = []
    for rec in summary.to_dict("records") if summary is not None else []:
        for region, values in nested_regions(rec).items():
            if any(k in values for k in REGION_SPLIT):
                rows.append({"renderer": rec["renderer"], "region": region,
                             **{k: values.get(k, math.nan) for k in REGION_SPLIT}})
    return pd.DataFrame(rows, columns=["renderer", "region", *REGION_SPLIT])


def _continue(head: list[int], last: int) -> list[int]:
    a, b = head[-2], head[-1]
    steps = []
    if a > 0 and b > a and b % a == 0:
        steps.append(lambda x: x * (b // a))
    if b > a:
        steps.append(lambda x: x + (b - a))
    for step in steps:
        out = list(head)
        while out[-1] < last:
            out.append(step(out[-1]))
        if out[-1] == last:
            return out
    raise ValueError


def parse_spp_list(text: str) -> list[int]:
    """``"1,2,4,...,256"``, ``"1,2,4,8"`` or ``"1-256"`` (powers of two) → sorted spp list.

    With ``...`` the numbers before it are continued to the last one, by a
    constant ratio if that reaches it exactly (1,2,4,...,256), else by a
    constant difference (10,20,...,50).
    """
    t = text.replace(" ", "").replace("…", "...")
    try:
        if m := re.fullmatch(r"(\d+)-(\d+)", t):
            out = [int(m.group(1))]
            while out[-1] * 2 <= int(m.group(2)):
                out.append(out[-1] * 2)
        elif "..." in t.split(","):
            parts = t.split(",")
            i = parts.index("...")
            if i < 2 or i != len(parts) - 2:
                raise ValueError
            out = _continue([int(p) for p in parts[:i]], int(parts[-1]))
        else:
            out = [int(p) for p in t.split(",")]
    except ValueError:
        raise ValueError(f"spp list {text!r}: expected e.g. 1,2,4,8 or 1,2,4,...,256 or 1-256") from None
    if not out or min(out) < 1:
        raise ValueError(f"spp list {text!r}: every spp must be >= 1")
    return sorted(set(out))
