"""Render in a child process with a wall-time bound and a memory bound: the sandbox.

A renderer can hang, leak, crash the interpreter or take the machine's memory;
none of that may take the harness down or go unmeasured. :func:`run_sandboxed`
renders a list of (scene, spp, seed) with one renderer (or one animated scene's frames, :func:`run_sandboxed_sequence`) in a fresh process
(``python -m cornell_harness.workflows.sandbox --worker FOLDER``) and returns a
:class:`SandboxOutcome`: how it ended, its wall time, its peak resident
memory, and the images (with variances and render times) it made::

    from cornell_harness.workflows.sandbox import run_sandboxed

    out = run_sandboxed("pathtracer", [(scene, 64, 0), (scene, 64, 1)], time_bound_s=60, rss_bound_mb=4096)
    if out.problem() is None:          # ended "ok", every image of its scene's shape
        image, variance = out.images[0], out.variances[0]   # variance None if the renderer gives none
    else:
        print(out.ended, out.message)  # "timeout", "memory", "error" (the renderer raised) or "crashed"

``spec`` is anything :func:`cornell_harness.adapters.registry.resolve` takes (a
registered name, ``module:Class``, or a declared command-line renderer's
``/abs/path/renderers.toml#NAME``); the parent's ``sys.path`` is passed on,
so a ``module:Class`` importable here is importable in the child. Scenes
travel by pickle, images come back as ``.npz`` files in a temporary folder.

Bounds
------
- **time**: the process's wall time covers interpreter start, imports, JIT or
  LLVM compilation, scene set-up, every render and writing the result. When
  it passes ``time_bound_s`` the worker is ended with everything it started
  (:func:`cornell_harness.processes.end`: SIGTERM, then SIGKILL after a grace period).
- **memory**: the resident set (``VmRSS``) of the process and of the
  processes it started (a command-line renderer's program,
  :mod:`cornell_harness.adapters.commands`), summed, is polled every :data:`POLL_S`
  seconds; when it passes ``rss_bound_mb`` the process group is killed. Its
  peak is the larger of the kernel's high-water mark of the worker's resident
  set, ``VmHWM`` (read by the worker itself as its last act, and polled by the
  parent, which covers a killed worker), and the largest polled sum. Past the
  bound there is no grace period: SIGKILL at once.
  ``ru_maxrss`` from ``wait4`` is not used on Linux: it carries the parent's
  resident set at fork into the child, so it would count the parent's memory. Without ``/proc`` (macOS) the peak is
  ``ru_maxrss`` and only the time bound is enforced.

An interrupt (a signal, :mod:`cornell_harness.cli.interrupt`) in the parent ends the worker before it
propagates. The worker's temporary files (a command renderer's run folder) go into the sandbox's own
folder (its ``$TMPDIR``), which the parent removes however the worker ended.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import pickle
import subprocess
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from cornell_harness import processes
from cornell_harness.workflows.timing import Timing

#: Seconds between two polls of the worker's wall time and resident memory.
POLL_S = 0.02
#: The last lines of a dead worker's stderr kept as its traceback (a fault handler's dump, an import error).
STDERR_LINES = 40


@dataclass
class SandboxOutcome:
    """What a sandboxed run gave: how it ended, its time and memory, its images (in the order asked for)."""

    ended: str  # "ok", "timeout", "memory", "error" (the renderer raised), "crashed" (no result)
    time_s: float
    peak_rss_mb: float
    message: str = ""
    traceback: str = ""  # the child's traceback when the renderer raised, or its last stderr lines when it died
    version: str | None = None
    images: list = dataclasses.field(default_factory=list)
    variances: list = dataclasses.field(default_factory=list)  # None where the renderer returned none
    render_times: list = dataclasses.field(default_factory=list)  # each render's own time_s
    cpu_times: list = dataclasses.field(default_factory=list)  # each render's own cpu_time_s (None: not given)
    timings: list = dataclasses.field(default_factory=list)  # each render call's cornell_harness.workflows.timing.Timing
    shapes: list = dataclasses.field(default_factory=list)  # (H, W, 3) each render was asked for
    infos: list = dataclasses.field(default_factory=list)  # each render's RenderResult.info
    checkpoints: list = dataclasses.field(default_factory=list)  # each render's [(spp, image, time_s, cpu, variance)]
    spps: list = dataclasses.field(default_factory=list)  # each render's spp (below the asked one: stopped early)
    seeds: list = dataclasses.field(default_factory=list)  # each render's seed, as its result gave it
    state: dict = dataclasses.field(default_factory=dict)  # a sequence's state (SequenceResult.state)

    def problem(self) -> str | None:
        """Why the images cannot be used (None: they can)."""
        if self.ended != "ok":
            return self.message
        for img, shape in zip(self.images, self.shapes):
            if np.shape(img) != shape:
                return f"image has shape {np.shape(img)}, expected {shape}"
        return None


def run_sandboxed(spec: str, renders: Sequence[tuple], time_bound_s: float, rss_bound_mb: float = math.inf,
                  settings: dict | None = None) -> SandboxOutcome:
    """Render ``renders`` ((scene, spp, seed), (scene, spp, seed, checkpoints) or (scene, spp, seed, checkpoints,
    stop), in order) with ``spec`` and its ``settings`` in a fresh process, within the bounds. Each render goes
    through :func:`cornell_harness.workflows.render.render_checked`, the harness's one render path; a ``stop``
    rule (picklable) travels with its render and runs in the child."""
    renders = list(renders)
    outcome = _run(spec, renders, "renders", time_bound_s, rss_bound_mb, settings)
    outcome.shapes = [(r[0].camera.height, r[0].camera.width, 3) for r in renders]
    return outcome


def run_sandboxed_sequence(spec: str, scene, spp: int, seed: int, frames: Sequence[int], time_bound_s: float,
                           rss_bound_mb: float = math.inf, settings: dict | None = None) -> SandboxOutcome:
    """Render ``frames`` of animated ``scene`` as one job in a fresh process, within the bounds, through
    :func:`cornell_harness.workflows.render.render_sequence_checked`: a stateful renderer's state lives in the
    child from the first frame to the last. The outcome has one image (and time, info) per frame, in order, and
    the renderer's ``state``; ``timings`` holds the whole sequence's one measure, once per frame."""
    frames = [int(i) for i in frames]
    outcome = _run(spec, [(scene, spp, seed, frames)], "sequence", time_bound_s, rss_bound_mb, settings)
    shape = (scene.camera.height, scene.camera.width, 3)
    outcome.shapes = [shape] * len(outcome.images)
    return outcome


def _run(spec: str, renders: list, kind: str, time_bound_s: float, rss_bound_mb: float,
         settings: dict | None) -> SandboxOutcome:
    with tempfile.TemporaryDirectory(prefix="cbox-sandbox-") as tmp:
        folder = Path(tmp)
        (folder / "job.json").write_text(json.dumps({"spec": spec, "settings": settings or {}, "kind": kind,
                                                     "sys_path": [p for p in sys.path if p]}))
        with open(folder / "renders.pkl", "wb") as f:
            pickle.dump(renders, f, protocol=pickle.HIGHEST_PROTOCOL)
        watched = _watch_worker(folder, time_bound_s, rss_bound_mb)
        return _read_outcome(folder, watched, time_bound_s, rss_bound_mb)


# ----------------------------------------------------------------------------------------
# The parent: start, watch, read back
# ----------------------------------------------------------------------------------------


@dataclass
class _Watched:
    killed: str | None  # "timeout", "memory" or None
    wall_s: float
    peak_rss_mb: float
    returncode: int


def _proc_status_mb(pid: int | str, field: str) -> float:
    """``field`` (VmRSS, VmHWM) of ``/proc/<pid>/status`` in MB; 0 if unreadable (the process is gone, no /proc)."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) / 1024.0
    except (OSError, ValueError):
        pass
    return 0.0


def _watch_worker(folder: Path, time_bound_s: float, rss_bound_mb: float) -> _Watched:
    """Start the worker on ``folder`` and wait for it, ending it at either bound."""
    (folder / "tmp").mkdir()
    env = dict(os.environ, TMPDIR=str(folder / "tmp"))  # what the worker leaves there goes with the folder
    with open(folder / "stdout.txt", "wb") as out, open(folder / "stderr.txt", "wb") as err:
        t0 = time.perf_counter()
        proc = processes.start([sys.executable, "-m", "cornell_harness.workflows.sandbox", "--worker", str(folder)],
                               stdin=subprocess.DEVNULL, stdout=out, stderr=err, env=env)
        try:
            status, usage, killed, peak = _poll(proc.pid, t0, time_bound_s, rss_bound_mb)
        except BaseException:  # interrupted: never leave a worker behind
            processes.end([proc.pid])
            proc.wait()
            raise
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)  # reaped by wait4: Popen must not wait again
    if not os.path.exists("/proc/self/status"):  # no /proc (macOS): ru_maxrss, bytes there
        peak = usage.ru_maxrss / (1024.0 * 1024.0 if sys.platform == "darwin" else 1024.0)
    return _Watched(killed, wall, peak, proc.returncode)


def _poll(pid: int, t0: float, time_bound_s: float, rss_bound_mb: float):
    """Wait for ``pid`` to end; (wait status, rusage, what ended it or None, polled peak RSS in MB). The
    resident set counts every process the worker started (a command-line renderer's program)."""
    killed, peak = None, 0.0
    while True:
        done, status, usage = os.wait4(pid, os.WNOHANG)
        if done:
            processes.end([pid])  # what the worker left behind in its group, if anything
            return status, usage, killed, peak
        elapsed = time.perf_counter() - t0
        rss = sum(_proc_status_mb(p, "VmRSS") for p in [pid, *processes.descendants(pid)])
        peak = max(peak, _proc_status_mb(pid, "VmHWM"), rss)
        if killed is None and elapsed > time_bound_s:
            killed = "timeout"
            processes.end([pid])
        elif killed is None and rss > rss_bound_mb:
            killed = "memory"
            processes.end([pid], grace_s=0.0)
        time.sleep(POLL_S)


def _read_outcome(folder: Path, watched: _Watched, time_bound_s: float, rss_bound_mb: float) -> SandboxOutcome:
    """The outcome from how the worker ended and what it left in ``folder``."""
    wall, peak = watched.wall_s, watched.peak_rss_mb
    if watched.killed == "timeout":
        return SandboxOutcome("timeout", wall, peak, f"did not end within the {time_bound_s:g} s bound: killed")
    if watched.killed == "memory":
        return SandboxOutcome("memory", wall, peak, f"resident memory passed the {rss_bound_mb:.0f} MB bound: killed")
    result_path = folder / "result.json"
    if not result_path.exists():
        lines = (folder / "stderr.txt").read_text(errors="replace").strip().splitlines()
        return SandboxOutcome("crashed", wall, peak,
                              f"worker exited with code {watched.returncode} and no result: {' | '.join(lines[-3:])}",
                              traceback="\n".join(lines[-STDERR_LINES:]))
    result = json.loads(result_path.read_text())
    outcome = SandboxOutcome("ok", wall, max(peak, float(result.get("vm_hwm_mb") or 0.0)),
                             version=result.get("version"), state=result.get("state") or {})
    for i, r in enumerate(result["renders"]):
        with np.load(folder / f"render-{i}.npz") as z:
            outcome.images.append(z["image"])
            outcome.variances.append(z["variance"] if "variance" in z.files else None)
            outcome.checkpoints.append([(spp, z[f"checkpoint-{spp}"], t, cpu, z.get(f"checkpoint-variance-{spp}"))
                                        for spp, t, cpu in r.get("checkpoints", [])])
        outcome.spps.append(int(r["spp"]))
        outcome.seeds.append(r.get("seed"))
        outcome.render_times.append(float(r["time_s"]))
        outcome.cpu_times.append(r.get("cpu_time_s"))
        outcome.timings.append(Timing(**r["timing"]))
        outcome.infos.append(r.get("info", {}))
    if result.get("error"):
        outcome.ended, outcome.message = "error", f"renderer raised {result['error']}"
        outcome.traceback = result.get("traceback") or ""
    return outcome


# ----------------------------------------------------------------------------------------
# The worker
# ----------------------------------------------------------------------------------------


def _render_job(spec: str, settings: dict, kind: str, folder: Path, result: dict) -> None:
    """Render every (scene, spp, seed[, checkpoints[, stop]]) of ``folder/renders.pkl`` with ``spec``, each to
    ``render-<i>.npz``; or (``kind`` "sequence") its one (scene, spp, seed, frames), each frame to one."""
    from cornell_harness.adapters.registry import resolve
    from cornell_harness.workflows.render import render_checked, render_sequence_checked
    from cornell_harness.workflows.timing import measure

    (entry,) = resolve([spec])
    entry = entry.with_settings(settings) if settings else entry
    if not entry.available:
        raise RuntimeError(f"renderer {entry.name!r} is unavailable: {entry.reason}")
    renderer = entry.renderer
    try:
        result["version"] = str(renderer.version())
    except Exception as e:  # a version probe must not fail the run
        result["version"] = f"unknown ({type(e).__name__})"
    with open(folder / "renders.pkl", "rb") as f:
        renders = pickle.load(f)
    if kind == "sequence":
        (scene, spp, seed, frames), = renders
        seq, timed = measure(lambda: render_sequence_checked(entry, scene, spp, seed, frames))
        result["state"] = json.loads(json.dumps(dict(seq.state), default=str))
        for i, res in enumerate(seq.frames):
            _write_render(folder, i, res, timed, result)
        return
    for i, (scene, spp, seed, *rest) in enumerate(renders):
        checkpoints, stop = (list(rest) + [(), None])[:2]
        res, timed = measure(lambda: render_checked(entry, scene, spp, seed, checkpoints, stop))
        _write_render(folder, i, res, timed, result)


def _write_render(folder: Path, i: int, res, timed, result: dict) -> None:
    """Render ``i``'s images to ``render-<i>.npz`` and its figures to ``result``."""
    arrays = {"image": np.asarray(res.image)}
    if res.variance is not None:
        arrays["variance"] = np.asarray(res.variance)
    arrays.update({f"checkpoint-{c.spp}": np.asarray(c.image) for c in res.checkpoints})
    arrays.update({f"checkpoint-variance-{c.spp}": np.asarray(c.variance) for c in res.checkpoints
                   if c.variance is not None})
    np.savez(folder / f"render-{i}.npz", **arrays)
    info = json.loads(json.dumps(dict(res.info), default=str))  # what JSON cannot hold, as text
    result["renders"].append({"spp": int(res.spp), "seed": int(res.seed), "time_s": float(res.time_s), "info": info,
                              "cpu_time_s": _number(res.cpu_time_s), "timing": timed.as_dict(),
                              "checkpoints": [(c.spp, float(c.time_s), _number(c.cpu_time_s))
                                              for c in res.checkpoints]})


def _number(value) -> float | None:
    return None if value is None else float(value)


def _worker_main(folder: Path) -> int:
    """The worker process: render the job in ``folder``, write images and ``result.json``."""
    job = json.loads((folder / "job.json").read_text())
    for p in job["sys_path"]:  # e.g. the folder of a module:Class renderer given on the command line
        if p not in sys.path:
            sys.path.append(p)
    result: dict = {"version": None, "renders": [], "error": None}
    try:
        _render_job(job["spec"], job.get("settings", {}), job.get("kind", "renders"), folder, result)
    except Exception as e:  # the renderer's failure is the result
        result["error"] = f"{type(e).__name__}: {e}"
        result["traceback"] = traceback.format_exc()
    result["vm_hwm_mb"] = _proc_status_mb("self", "VmHWM")
    (folder / "result.json").write_text(json.dumps(result))
    return 0 if result["error"] is None else 3


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--worker":
        sys.exit(_worker_main(Path(sys.argv[2])))
    print("usage: python -m cornell_harness.workflows.sandbox --worker FOLDER (internal; see run_sandboxed)", file=sys.stderr)
    sys.exit(2)
