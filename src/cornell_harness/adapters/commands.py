"""Command-line renderers: the adapter that runs an entry of a renderers file
(:mod:`cornell_harness.adapters.renderers_file`) as a renderer.

The program runs in a fresh temporary folder (its working directory) that holds
the exported scene (``scene/``) and its outputs, removed afterwards.

The executable, ``command[0]``: a bare name is looked for first in the
folder of the Python running cbox (a virtual environment's ``bin``, where
console scripts such as ``mitsuba`` are, even when the environment is not
activated: ``.venv/bin/cbox`` run with the system's ``PATH``), then on
``PATH``; a name with a ``/`` is a path, relative to the renderers file's
folder. A renderer whose executable or scene format is missing is
unavailable, with the reason.

A render (:class:`CommandRenderer`) exports the scene once, then runs the
program once per spp asked for: every progress checkpoint is a run of its
own at that spp and the same seed. A non-zero exit, a missing or unreadable
image, or one of the wrong size is a :class:`CommandFailed` quoting the tail
of the program's stderr: a failed run in the results, with the reason. A
run's ``time_s`` is its wall time (or what ``time`` reads), its
``cpu_time_s`` the program's CPU time, all its threads and its own children,
start-up included (the CPU time of the waited-for child, :func:`os.times`).

Each run of the program is one child of :mod:`cornell_harness.processes`: it
ends with the command that started it (a signal, an exception), and a run that
passes its time limit is ended with what it started and fails the render with
a :class:`CommandFailed` that says so. The limit is the entry's ``time_limit``,
or by default ``DEFAULT_LIMIT_START_S`` plus ``DEFAULT_LIMIT_PER_SAMPLE_S``
per sample (spp × width × height; :mod:`cornell_harness.adapters.renderers_file`): generous, it ends a hang,
not a slow program. Its ``$TMPDIR`` is its run folder, so what it leaves there goes with
the folder. A sandboxed render (``--time-limit``, the gate) is bounded by the
sandbox as well (:mod:`cornell_harness.workflows.sandbox`).
"""

from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Sequence

from cornell_harness import processes
from cornell_harness.adapters.api import Checkpoint, RenderResult, Stopwatch, default_threads
from cornell_harness.adapters.renderers_file import SPEC_SEPARATOR, Declaration, RenderersFileError, read_file
from cornell_harness.scenes.model import Scene
from cornell_harness.suggest import did_you_mean

#: Lines of the program's stderr a failure quotes, and their characters at most.
TAIL_LINES, TAIL_CHARS = 6, 600

class CommandFailed(RuntimeError):
    """The program failed (exit code, no image, wrong size); ``str()`` quotes the tail of its stderr."""


def load(spec: str) -> "CommandRenderer":
    """The renderer a spec of :func:`spec_of` names (its file read and checked again, in this process)."""
    file, _, name = spec.rpartition(SPEC_SEPARATOR)
    declared = read_file(file)
    if name not in declared:
        raise RenderersFileError(file, f"renderer.{name}", "not declared" + did_you_mean(name, declared)
                                 + f"; declared: {', '.join(declared)}")
    return CommandRenderer(declared[name])


# ----------------------------------------------------------------------------------------
# The adapter
# ----------------------------------------------------------------------------------------


def find_program(program: str, file: Path) -> str | None:
    """The executable ``program`` names: a path (relative to the renderers file's folder), or a bare name in
    the running Python's folder, then on ``PATH``; None when there is none."""
    if os.sep in program or (os.altsep and os.altsep in program):
        path = Path(program).expanduser()
        path = path if path.is_absolute() else file.parent / path
        return str(path) if path.is_file() and os.access(path, os.X_OK) else None
    here = Path(sys.executable).parent
    return shutil.which(program, path=str(here)) or shutil.which(program)


class CommandRenderer:
    """A declared program as a :class:`~cornell_harness.adapters.api.Renderer`: export, run, read back."""

    def __init__(self, declaration: Declaration):
        self.declaration = d = declaration
        self.name = d.name
        self.features = d.models
        self.quantities = (d.quantity,)
        self.estimator = d.estimator

    def program(self) -> str | None:
        return find_program(self.declaration.command[0], self.declaration.file)

    def unavailable_reason(self) -> str | None:
        d = self.declaration
        if self.program() is None:
            where = "" if os.sep in d.command[0] else f" in {Path(sys.executable).parent} or on PATH"
            return f"program {d.command[0]!r} not found{where} ({d.file}, renderer.{d.name}.command)"
        from cornell_harness.scenes.export import format_module

        try:
            format_module(d.scene_format)
        except ImportError as e:
            return f"scene format {d.scene_format!r} cannot be written here: {e}"
        return None

    def version(self) -> str:
        """The program's path and its file's modification time: what changes when the program is rebuilt."""
        program = self.program()
        if program is None:
            return "not found"
        stamp = time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(os.stat(program).st_mtime))
        return f"{program} (modified {stamp} UTC), {self.declaration.spec}"

    def render(self, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = ()) -> RenderResult:
        """The scene exported once, then one run of the program per spp (each checkpoint its own run)."""
        from cornell_harness.scenes.export import export_scene

        d = self.declaration
        program = self.program()
        if program is None:
            raise CommandFailed(self.unavailable_reason())
        with tempfile.TemporaryDirectory(prefix=f"cbox-{d.name}-") as tmp:
            folder = Path(tmp)
            main = export_scene(scene, d.scene_format, folder / "scene")
            shots = []
            for c in sorted(set(checkpoints) - {spp}):
                image, _, t, cpu = self._run(program, folder, main, scene, c, seed)
                shots.append(Checkpoint(c, image, t, cpu_time_s=cpu))
            image, variance, t, cpu = self._run(program, folder, main, scene, spp, seed)
        return RenderResult(image, t, spp, seed, shots, {"program": program, "scene_format": d.scene_format},
                            variance, cpu_time_s=cpu)

    def _run(self, program: str, folder: Path, main: Path, scene: Scene, spp: int, seed: int):
        """One run at ``spp``: (image, variance or None, seconds, CPU seconds of the program's whole run, its
        start-up included: the CPU time of the children this process waited for, :class:`Stopwatch`)."""
        d = self.declaration
        cam = scene.camera
        out = folder / f"out-{spp}spp.exr"
        values = {"scene": str(main), "out": str(out), "spp": spp, "seed": seed, "width": cam.width,
                  "height": cam.height, "threads": default_threads()}
        argv = [program, *(arg.format(**values) for arg in d.command[1:])]
        variance = None if d.variance is None else folder / d.variance.format(**values)
        for stale in (out, variance):
            if stale is not None and stale.exists():
                stale.unlink()
        stdout, stderr = folder / f"stdout-{spp}.txt", folder / f"stderr-{spp}.txt"

        def failed(what: str) -> CommandFailed:
            return CommandFailed(f"{d.name} at {spp} spp: {what}; stderr: {_tail(stderr)}")

        with open(stdout, "wb") as o, open(stderr, "wb") as e:
            clock = Stopwatch()
            try:
                code = processes.run(argv, d.run_time_limit_s(spp, cam.width, cam.height), cwd=folder,
                                     stdin=subprocess.DEVNULL, stdout=o, stderr=e,
                                     env=dict(os.environ, TMPDIR=str(folder)))
            except processes.TimeLimitExceeded as limit:
                raise failed(f"{limit} (ran {limit.time_s:.1f} s; the renderers file's time_limit sets it)") from None
            wall, cpu = clock.read()
        if code != 0:
            raise failed(f"exited with code {code}" if code > 0 else f"killed by signal {-code}")
        expected = (cam.height, cam.width, 3)
        image = _read(out, expected, failed, "image")
        var = None if variance is None else _read(variance, expected, failed, "variance image")
        return image, var, wall if d.time == "wall" else _seconds(d.time, stdout, failed), cpu


def _read(path: Path, expected: tuple[int, int, int], failed, what: str):
    from cornell_harness.store.exr import ImageFileError, read_exr

    if not path.exists():
        raise failed(f"exited 0 but wrote no {what} at {path.name}")
    try:
        image = read_exr(path)
    except ImageFileError as e:
        raise failed(f"its {what} cannot be read: {e}") from None
    if image.shape != expected:
        raise failed(f"its {what} is {image.shape[1]}x{image.shape[0]}, expected {expected[1]}x{expected[0]} "
                     "(the scene's resolution)")
    return image


def _seconds(pattern: str, stdout: Path, failed) -> float:
    """The seconds the last match of ``pattern`` in the program's stdout reads."""
    matches = re.findall(pattern, stdout.read_text(errors="replace"))
    if not matches:
        raise failed(f"its stdout has no match of the time regex {pattern!r}")
    try:
        seconds = float(matches[-1])
    except ValueError:
        seconds = math.nan
    if not math.isfinite(seconds) or seconds < 0:
        raise failed(f"the time regex read {matches[-1]!r}, not a number of seconds")
    return seconds


def _tail(path: Path) -> str:
    """The last lines of a program's stderr as one line, or ``(empty)``."""
    lines = [ln.strip() for ln in path.read_text(errors="replace").splitlines() if ln.strip()]
    text = " | ".join(lines[-TAIL_LINES:])
    if len(text) > TAIL_CHARS:
        text = "…" + text[-(TAIL_CHARS - 1):]
    return text or "(empty)"
