"""Experiments: convergence runs, equal-time and equal-quality comparisons, and their stored results.

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

import datetime as _dt
import json
import math
import re
import time
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import pandas as pd

from harness import convergence, runner
from harness.adapter import RendererEntry, missing_features
from harness.atomic import atomic_path, write_json_atomic
from harness.exr import read_exr, write_exr
from harness.reference import Reference
from harness.scene import Scene

CONFIG_FILE, RESULTS_FILE, SUMMARY_FILE = "experiment.json", "results.parquet", "summary.csv"


class ExperimentError(RuntimeError):
    """An experiment folder cannot be used as asked. ``str()`` says why and what to do."""


def cell_name(renderer: str, seed: int) -> str:
    """File stem of a cell; renderer names like ``pkg.mod:Class`` become file-safe."""
    return f"{re.sub(r'[^A-Za-z0-9_.-]+', '_', renderer)}__seed{seed}"


def write_parquet_atomic(frame: pd.DataFrame, path: Path) -> None:
    with atomic_path(path) as tmp:
        frame.to_parquet(tmp, index=False)


def _not_run_row(entry: RendererEntry, scene: Scene) -> dict | None:
    """The row of a renderer that will not run here (unavailable or missing a feature), else None."""
    rec = runner.RunRecord.new(scene, entry.name, spp=0, seed=0)
    if not entry.available:
        rec.status, rec.reason = "unavailable", entry.reason
    elif missing := missing_features(entry.renderer, scene):
        rec.status, rec.reason = "skipped", f"does not model {', '.join(missing)}"
    else:
        return None
    row = rec.row()
    row["spp"] = row["seed"] = math.nan
    return row


def render_cell(entry: RendererEntry, scene: Scene, spps: Sequence[int], seed: int,
                reference: Reference) -> tuple[list[dict], np.ndarray | None]:
    """Rows for every spp of one (renderer, seed), and its highest-spp image.

    A progressive renderer gives every checkpoint from one render; for one
    that does not, each missing spp is a render of its own (its time then
    is that render's time).
    """
    r = entry.renderer
    top = max(spps)
    base = runner.RunRecord.new(scene, entry.name, top, seed, approximations=tuple(getattr(r, "approximations", ())))
    try:
        base.version = str(r.version())
        result = r.render(scene, top, seed, checkpoints=list(spps))
        shots = {c.spp: (c.image, c.time_s) for c in result.checkpoints}
        shots[top] = (result.image, result.time_s)
        for spp in spps:
            if spp not in shots:
                extra = r.render(scene, spp, seed)
                shots[spp] = (extra.image, extra.time_s)
    except Exception as e:  # a renderer bug becomes a failed row; the experiment goes on
        base.status, base.reason = "failed", f"{type(e).__name__}: {e}"
        return [base.row()], None
    rows = []
    for spp in sorted(spps):
        image, t = shots[spp]
        rec = runner.RunRecord.new(scene, entry.name, spp, seed, version=base.version, time_s=float(t),
                                   approximations=base.approximations, info=dict(result.info))
        rec.metrics = runner.score(np.asarray(image, np.float32), reference, spp)
        rows.append(rec.row())
    return rows, np.asarray(result.image, np.float32)


def _cell_is_done(path: Path, scene: Scene, spps: Sequence[int]) -> pd.DataFrame | None:
    """The stored rows of a finished cell, if they match this scene and spp list."""
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


def _prepare_dir(out: Path, config: dict) -> None:
    out.mkdir(parents=True, exist_ok=True)
    path = out / CONFIG_FILE
    if path.exists():
        old = json.loads(path.read_text())
        if old.get("scene_hash") != config["scene_hash"]:
            raise ExperimentError(
                f"{path}: this folder holds results of scene hash {old.get('scene_hash')}, not "
                f"{config['scene_hash']}; use another --out or delete the folder")
    write_json_atomic(path, config)


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
    _prepare_dir(out, {
        "kind": kind, "scene": str(scene.path), "scene_name": scene.name, "scene_hash": scene.content_hash(),
        "renderers": [e.name for e in entries], "spp": spps, "seeds": list(seeds), "command": command,
        "targets": [list(t) for t in targets],
        "deterministic": [e.name for e in entries if getattr(e.renderer, "deterministic", False)],
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    })
    frames, not_run = [], []
    for entry in entries:
        if (row := _not_run_row(entry, scene)) is not None:
            not_run.append(row)
            continue
        for seed in (seeds[:1] if getattr(entry.renderer, "deterministic", False) else seeds):
            name = cell_name(entry.name, seed)
            cell_path = out / "cells" / f"{name}.parquet"
            rows = _cell_is_done(cell_path, scene, spps)
            cached = rows is not None
            if not cached:
                rows_list, image = render_cell(entry, scene, spps, seed, reference)
                rows = pd.DataFrame(rows_list)
                if image is not None:  # image first: a cell's rows promise its image exists
                    write_exr(out / "images" / f"{name}.exr", image)
                    write_parquet_atomic(rows, cell_path)
            frames.append(rows)
            write_parquet_atomic(pd.concat(frames + [pd.DataFrame(not_run)], ignore_index=True), out / RESULTS_FILE)
            if on_cell:
                on_cell(name, cached)
    results = pd.concat(frames + [pd.DataFrame(not_run)], ignore_index=True)
    write_parquet_atomic(results, out / RESULTS_FILE)
    return results


def load_results(out: Path) -> tuple[dict, pd.DataFrame]:
    """The config and results table of an experiment folder."""
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


def summary_table(runs: pd.DataFrame, images: dict[str, list[np.ndarray]], reference: Reference,
                  targets=convergence.DEFAULT_TARGETS, deterministic: Sequence[str] = ()) -> pd.DataFrame:
    """Derived figures per renderer, with the bias/variance split from the stored images."""
    summary = convergence.summarize(runs, targets)
    if summary.empty:
        return summary
    bv = [convergence.bias_variance(images.get(r, []), reference.image, reference.variance, r in deterministic)
          for r in summary["renderer"]]
    return pd.concat([summary, pd.DataFrame(bv)], axis=1)


# -- equal time and equal quality ------------------------------------------------------

def spp_for_time_budget(entry: RendererEntry, scene: Scene, budget_s: float, seed: int) -> int:
    """The spp that should take ``budget_s`` seconds, from two short timed renders (1 and 4 spp).

    Per-render overhead (scene set-up) and per-sample cost are separated by
    the two timings. The calibration renders are not counted in the budget;
    the final render's own time is what is reported.
    """
    r = entry.renderer
    t1 = r.render(scene, 1, seed).time_s
    t4 = r.render(scene, 4, seed).time_s
    per_spp = max((t4 - t1) / 3.0, 1e-9)
    overhead = max(t1 - per_spp, 0.0)
    return max(1, int((budget_s - overhead) / per_spp))


def render_to_target(entry: RendererEntry, scene: Scene, reference: Reference, metric: str, target: float,
                     seed: int, max_spp: int) -> runner.RunRecord:
    """Renders at 1, 2, 4, ... spp until ``metric`` ≤ ``target`` (or ``max_spp``); the record says which.

    The reported time is that of the render that reached the target (a
    renderer that resumed its last render would need at most that). A
    deterministic renderer stops early once two doublings of spp leave its error unchanged.
    """
    spp, previous, stalls = 1, None, 0
    deterministic = getattr(entry.renderer, "deterministic", False)
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


def parse_duration(text: str) -> float:
    """``"10s"``, ``"2m"``, ``"500ms"``, ``"1.5"`` (seconds) → seconds."""
    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+)\s*(ms|s|m|min|h)?\s*", text)
    if not m:
        raise ValueError(f"time budget {text!r}: expected e.g. 10s, 2m, 500ms")
    scale = {"ms": 1e-3, "s": 1.0, None: 1.0, "m": 60.0, "min": 60.0, "h": 3600.0}[m.group(2)]
    value = float(m.group(1)) * scale
    if value <= 0:
        raise ValueError(f"time budget {text!r}: must be positive")
    return value


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


# -- reports ---------------------------------------------------------------------------

#: Libraries whose versions every report records.
LIBRARIES = ("cornell-harness", "numpy", "scipy", "pandas", "colour-science", "scikit-image", "OpenImageIO",
             "mitsuba", "drjit", "embreex", "numba", "pyrender2", "flip-evaluator")


def provenance(config: dict, runs: pd.DataFrame) -> dict:
    """Versions of renderers and libraries, machine, seeds, date: what a reader needs to reproduce."""
    import importlib.metadata as md
    import os
    import platform

    versions = {}
    for lib in LIBRARIES:
        try:
            versions[lib] = md.version(lib)
        except md.PackageNotFoundError:
            pass
    for renderer, g in runs.groupby("renderer", sort=False):
        v = g["version"].dropna()
        if len(v):
            versions[f"renderer {renderer}"] = str(v.iloc[0])
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next((ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")), cpu)
    except OSError:
        pass
    seeds = sorted({int(s) for s in runs["seed"].dropna()})
    return {"versions": versions, "machine": f"{cpu}, {os.cpu_count()} CPUs, {platform.system()} {platform.release()}, "
                                             f"Python {platform.python_version()}",
            "seeds": seeds, "date": config.get("date", ""), "kind": config.get("kind", "")}


def write_experiment_report(out: Path, scene: Scene, reference: Reference, thresholds: dict | None = None,
                            sections=(), title: str | None = None) -> Path:
    """(Re)build ``out/report.html`` and ``out/summary.csv`` from what is stored in ``out``; no rendering."""
    from reports.html import write_report

    config, runs = load_results(out)
    images = final_images(out, runs)
    targets = [tuple(t) for t in config.get("targets", convergence.DEFAULT_TARGETS)]
    summary = summary_table(runs, images, reference, targets, config.get("deterministic", ()))
    if not summary.empty:
        with atomic_path(Path(out) / SUMMARY_FILE) as tmp:
            summary.to_csv(tmp, index=False)
    shown = {r: imgs[0] for r, imgs in images.items() if imgs}
    return write_report(Path(out) / "report.html", scene=scene, reference=reference, runs=runs, images=shown,
                        summary=summary if not summary.empty else None, thresholds=thresholds,
                        provenance=provenance(config, runs), command=config.get("command", ""),
                        sections=sections, title=title)
