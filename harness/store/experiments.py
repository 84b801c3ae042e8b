"""Experiment folders: what ``cbox converge`` and ``cbox compare`` store, and reading it back.

An experiment folder ``DIR`` holds

- ``experiment.json``: what was asked (scene and its hash, renderers, spp
  list, seeds, command, date);
- ``cells/<renderer>__seed<k>.parquet``: the rows of one *cell*, i.e. one
  renderer at one seed, one row per spp checkpoint, written atomically once
  the cell is complete;
- ``images/<renderer>__seed<k>.exr``: the cell's highest-spp image (for
  the viewer and the bias/variance split), written before the cell's rows;
- ``results.parquet``: all rows, a tidy table with one row per (scene,
  renderer, settings, seed, spp), rewritten after each cell;
- ``summary.csv``, ``report.html``: derived figures and the report.

A run that is interrupted keeps every finished cell; running the same
command again loads finished cells instead of rendering them.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np

from harness.scenes.model import Scene
from harness.store.atomic import atomic_path, write_json_atomic
from harness.store.exr import read_exr

if TYPE_CHECKING:  # pandas is imported where it is used: the CLI must start fast
    import pandas as pd

CONFIG_FILE, RESULTS_FILE, SUMMARY_FILE = "experiment.json", "results.parquet", "summary.csv"


class ExperimentError(RuntimeError):
    """An experiment folder cannot be used as asked. ``str()`` says why and what to do."""


def cell_name(renderer: str, seed: int) -> str:
    """File stem of a cell; renderer names like ``pkg.mod:Class`` become file-safe."""
    return f"{re.sub(r'[^A-Za-z0-9_.-]+', '_', renderer)}__seed{seed}"


def write_parquet_atomic(frame: pd.DataFrame, path: Path) -> None:
    with atomic_path(path) as tmp:
        frame.to_parquet(tmp, index=False)


def cell_is_done(path: Path, scene: Scene, spps: Sequence[int]) -> pd.DataFrame | None:
    """The stored rows of a finished cell, if they match this scene and spp list."""
    import pandas as pd

    if not path.exists():
        return None
    try:
        rows = pd.read_parquet(path)
    except Exception:  # a damaged file is re-rendered, not trusted
        return None
    if (rows["status"] == "ok").all() and set(rows["scene_hash"]) == {scene.content_hash()} \
            and sorted(rows["spp"].astype(int)) == sorted(spps):
        return rows
    return None


def prepare_dir(out: Path, config: dict) -> None:
    out.mkdir(parents=True, exist_ok=True)
    path = out / CONFIG_FILE
    if path.exists():
        old = json.loads(path.read_text())
        if old.get("scene_hash") != config["scene_hash"]:
            raise ExperimentError(
                f"{path}: this folder holds results of scene hash {old.get('scene_hash')}, not "
                f"{config['scene_hash']}; use another --out or delete the folder")
    write_json_atomic(path, config)


def load_results(out: Path) -> tuple[dict, pd.DataFrame]:
    """The config and results table of an experiment folder."""
    import pandas as pd

    out = Path(out)
    cfg_path, res_path = out / CONFIG_FILE, out / RESULTS_FILE
    for p in (cfg_path, res_path):
        if not p.exists():
            raise ExperimentError(f"{p}: not found; is {out} the --out folder of cbox converge or cbox compare?")
    return json.loads(cfg_path.read_text()), pd.read_parquet(res_path)


def final_images(out: Path, runs: pd.DataFrame) -> dict[str, list[np.ndarray]]:
    """Stored highest-spp images per renderer, in seed order."""
    images: dict[str, list[np.ndarray]] = {}
    ok = runs[runs["status"] == "ok"]
    for renderer, g in ok.groupby("renderer", sort=False):
        for seed in sorted(g["seed"].dropna().astype(int).unique()):
            path = Path(out) / "images" / f"{cell_name(renderer, seed)}.exr"
            if path.exists():
                images.setdefault(renderer, []).append(read_exr(path))
    return images
