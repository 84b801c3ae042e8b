"""Experiment folders: what ``cbox converge`` and ``cbox compare`` store, and reading it back.

An experiment folder ``DIR`` holds

- ``experiment.json``: what was asked (scene and its hash, renderers, spp
  list, seeds, command), the first run's date and each resume;
- ``.lock``: held by the run writing the folder (:func:`experiment_lock`);
- ``cells/<renderer>__seed<k>.parquet``: the rows of one *cell*, i.e. one
  renderer at one seed, one row per spp checkpoint rendered so far, written
  atomically once the cell is complete;
- ``images/<renderer>__seed<k>.exr``: the cell's highest-spp image (for
  the viewer and the bias/variance split; its header's ``cbox:spp`` says
  which), written before the cell's rows;
- ``results.parquet``: all rows, a tidy table with one row per (scene,
  renderer, settings, seed, spp), rewritten after each cell;
- ``summary.parquet``: the derived figures per renderer (raw names, full precision);
- ``report.html``, ``summary.csv``, ``summary.tex``, ``summary-wide.tex``: the report, and the summary for people
  (readable headers and units) and for papers (a LaTeX table), written with it (:mod:`cornell_harness.reports.summary_files`);
- ``report-options.json``: how the report names series and crops images (``--series-label``, ``--crop``),
  kept so that ``cbox report`` draws it the same way again.

A run that is interrupted keeps every finished cell; running the same
command again loads finished cells instead of rendering them, and a changed
spp list renders only the spps a cell lacks (:func:`spps_to_render`).
"""

from __future__ import annotations

import datetime as _dt
import fcntl
import json
import os
import re
import socket
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Iterator, Sequence

import numpy as np

from cornell_harness.scenes.model import Scene
from cornell_harness.store.atomic import atomic_path, write_json_atomic
from cornell_harness.store.exr import read_exr

if TYPE_CHECKING:  # pandas is imported where it is used: the CLI must start fast
    import pandas as pd

CONFIG_FILE, RESULTS_FILE, SUMMARY_FILE = "experiment.json", "results.parquet", "summary.parquet"
#: The report's presentation options (:func:`read_report_options`).
REPORT_OPTIONS_FILE = "report-options.json"
#: Held (flock) by the run writing the folder; its text names the holder.
LOCK_FILE = ".lock"


class ExperimentError(RuntimeError):
    """An experiment folder cannot be used as asked. ``str()`` says why and what to do."""


def cell_name(renderer: str, seed: int) -> str:
    """File stem of a cell; renderer names like ``pkg.mod:Class`` become file-safe."""
    return f"{re.sub(r'[^A-Za-z0-9_.-]+', '_', renderer)}__seed{seed}"


def write_parquet_atomic(frame: pd.DataFrame, path: Path) -> None:
    with atomic_path(path) as tmp:
        frame.to_parquet(tmp, index=False)


def stored_cell(path: Path, scene: Scene) -> pd.DataFrame | None:
    """The stored rows of a finished cell (every spp it has) made for this scene; None if there are none.

    A damaged file, a failed cell or one made for another scene hash is not
    trusted: the cell is rendered again.
    """
    import pandas as pd

    if not path.exists():
        return None
    try:
        rows = pd.read_parquet(path)
    except Exception:
        return None
    if (rows["status"] == "ok").all() and set(rows["scene_hash"]) == {scene.content_hash()}:
        return rows
    return None


def spps_to_render(stored: Sequence[int], image_spp: int | None, spps: Sequence[int]) -> list[int]:
    """The spps a cell must render to have a row at every spp of ``spps`` and its image at the highest.

    Rows already stored are kept, so a longer spp list renders only what is
    missing, and a shorter one renders nothing unless the stored image
    (``image_spp``, None if unknown) is not at its new highest spp. A
    progressive renderer renders them in one run up to the largest; it does
    not resume the stored render (see docs/experiments.md).
    """
    have = set(int(s) for s in stored)
    todo = {int(s) for s in spps} - have
    if image_spp != max(spps):
        todo.add(max(spps))
    return sorted(todo)


@contextmanager
def experiment_lock(out: Path, command: str) -> Iterator[None]:
    """Hold ``out/.lock`` for one run: a second run on the folder stops at once, naming the holder.

    An advisory ``flock`` (POSIX), not a lock file's mere existence: the
    kernel releases it when the holder exits or is killed, so a crashed run
    never leaves the folder locked. The file's text only names the holder.
    """
    out.mkdir(parents=True, exist_ok=True)
    path = out / LOCK_FILE
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = path.read_text(errors="replace").strip() or "another process"
            raise ExperimentError(f"{out}: in use by {holder}; wait for it to finish or give another --out") from None
        os.ftruncate(fd, 0)
        os.write(fd, f"pid {os.getpid()} on {socket.gethostname()} since {_now()}: {command or 'cbox'}\n".encode())
        yield
    finally:
        os.close(fd)  # closing releases the flock


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def prepare_dir(out: Path, config: dict) -> None:
    """Write ``experiment.json`` for a run: the first run's ``date`` is kept, each later one is listed in
    ``resumed`` (with its command); a folder holding another scene's results is refused."""
    out.mkdir(parents=True, exist_ok=True)
    path = out / CONFIG_FILE
    config = {**config, "date": _now(), "resumed": []}
    if path.exists():
        old = json.loads(path.read_text())
        if old.get("scene_hash") != config["scene_hash"]:
            raise ExperimentError(
                f"{path}: this folder holds results of scene hash {old.get('scene_hash')}, not "
                f"{config['scene_hash']}; use another --out or delete the folder")
        resumed = list(old.get("resumed", [])) + [{"date": config["date"], "command": config.get("command", "")}]
        config.update(date=old.get("date", config["date"]), resumed=resumed)
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


def read_report_options(out: Path) -> dict:
    """The presentation options stored with an experiment: ``series_labels`` (recorded series name → text)
    and ``crops`` (``[x, y, w, h]`` in pixels); empty when none were given or the file is unreadable (they
    only change how the report looks, never what it says)."""
    try:
        options = json.loads((Path(out) / REPORT_OPTIONS_FILE).read_text())
    except (OSError, ValueError):
        return {}
    return options if isinstance(options, dict) else {}


def write_report_options(out: Path, options: dict) -> None:
    write_json_atomic(Path(out) / REPORT_OPTIONS_FILE, options)
