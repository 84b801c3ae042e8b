"""The runner: renders through the one render path, records the outcome, and scores it.

Every command (compare, converge, gate, equal time, equal quality) renders
through :func:`cornell_harness.workflows.render.render_checked` (here or, with a
time limit, in a child process: :func:`render_sandboxed`) and records
through :func:`run_one` or :func:`run_checkpoints`. A renderer that is unavailable here, or does not
model a feature the scene uses, is never run; its record says why
(``status`` "unavailable" or "skipped"). A renderer that raises, or returns
an image of the wrong shape, is recorded as "failed" with the reason, and the
other renderers still run.

Every timed render records, beside ``time_s`` (the wall time of the render
proper, as the renderer measured it), the columns of
:data:`cornell_harness.evaluate.timing_quality.TIMING_COLUMNS` (:mod:`cornell_harness.workflows.timing`
measures the machine around the render call): ``cpu_time_s`` the CPU time of
the render proper as the renderer measured it (:class:`cornell_harness.adapters.api.Stopwatch`),
or, for a renderer that gives none, that of the whole render call, set-up
included (the row's ``info_cpu_time_of`` then says so); ``setup_s`` the set-up
the renderer reports (``info["setup_s"]``: scene build, compilation, warm-up);
``threads`` the threads it rendered on; ``load_before``/``load_after``,
``calibration_s`` and ``foreign_cpu``. Every checkpoint row of one render carries the render's
figures, and its own ``cpu_time_s`` where the renderer gave one.
"""

from __future__ import annotations

import json
import math
import traceback
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from cornell_harness.evaluate import metrics
from cornell_harness.evaluate import regions as named_regions
from cornell_harness.evaluate import timing_stats
from cornell_harness.evaluate.score import score_image
from cornell_harness.adapters.api import ESTIMATORS, Checkpoint, RenderResult, SettingsError, attribute, default_threads
from cornell_harness.adapters.registry import RendererEntry, estimator_of, missing_features
from cornell_harness.adapters.settings import canonical
from cornell_harness.store.atomic import json_safe
from cornell_harness.store.references import Reference
from cornell_harness.workflows.render import RenderError, RenderTimeout, render_checked
from cornell_harness.workflows.sandbox import run_sandboxed
from cornell_harness.workflows.timing import Timing, measure
from cornell_harness.scenes.model import Scene
from cornell_harness.scenes.spectral_scene import convention_used

STATUSES = ("ok", "skipped", "unavailable", "failed")


def scene_settings(scene: Scene) -> str:
    """The scene settings that define what a run computes, as canonical JSON."""
    cam = scene.camera
    return json.dumps({"max_depth": scene.max_depth, "width": cam.width, "height": cam.height,
                       "pixel_filter": scene.pixel_filter}, sort_keys=True)


@dataclass
class RunRecord:
    """One renderer on one scene at one (spp, seed): outcome, image and metrics."""

    scene: str
    renderer: str
    status: str
    spp: int
    seed: int
    scene_hash: str = ""
    scene_settings: str = "{}"
    settings: str = "{}"  # the renderer's settings, every declared one (canonical JSON)
    estimator: str = ESTIMATORS[0]  # the adapter's declaration (cornell_harness.adapters.registry.estimator_of)
    reason: str | None = None
    version: str | None = None
    time_s: float | None = None
    cpu_time_s: float | None = None  # the columns of cornell_harness.evaluate.timing_quality.TIMING_COLUMNS
    setup_s: float | None = None
    threads: int | None = None
    load_before: float | None = None
    load_after: float | None = None
    calibration_s: float | None = None
    foreign_cpu: float | None = None
    approximations: tuple[str, ...] = ()
    info: dict = field(default_factory=dict)
    metrics: dict = field(default_factory=dict)
    regions: dict = field(default_factory=dict)  # region -> metric -> value, when the scene names regions
    image: np.ndarray | None = field(default=None, repr=False)
    variance: np.ndarray | None = field(default=None, repr=False)  # of the image, when the renderer gives it
    checkpoints: list = field(default_factory=list, repr=False)  # cornell_harness.adapters.api.Checkpoint
    # (wall, CPU or None) of each timing of this render when it was re-timed (--time-repeats); time_s is then
    # their median (cornell_harness.evaluate.timing_stats). Empty: the one timing time_s.
    time_samples: list = field(default_factory=list, repr=False)
    # The scene's rgb_convention ("" for a scene without spectra): with the render's info, the row's
    # rgb_convention column (cornell_harness.scenes.spectral_scene.convention_used).
    scene_rgb_convention: str = ""
    # An unbiased render's agreement test against the reference, as cbox compare gives it
    # (cornell_harness.workflows.compare.judge_agreement): "pass" or "fail", and its smallest p; None otherwise.
    agreement: str | None = None
    agreement_p_min: float | None = None

    @classmethod
    def new(cls, scene: Scene, entry: RendererEntry, spp: int, seed: int, **fields) -> "RunRecord":
        rec = cls(scene.name, entry.name, "ok", spp, seed, scene.content_hash(), scene_settings(scene),
                  canonical(entry.settings), **fields)
        rec.scene_rgb_convention = scene.spectral.rgb_convention if scene.spectral is not None else ""
        if entry.renderer is not None:
            rec.estimator = estimator_of(entry.renderer)
        if not entry.available:
            rec.status, rec.reason = "unavailable", entry.reason
        elif missing := missing_features(entry.renderer, scene):
            rec.status, rec.reason = "skipped", f"does not model {', '.join(missing)}"
        else:
            rec.approximations = attribute(entry.renderer, "approximations")
        return rec

    def failed(self, error: Exception) -> "RunRecord":
        """This record marked failed by ``error`` (a renderer bug is reported, never raised)."""
        self.status, self.reason = "failed", f"{type(error).__name__}: {error}"
        # A sandboxed render's error carries the child's traceback: here we would see only its re-raise.
        self.info = {"traceback": getattr(error, "traceback", "") or traceback.format_exc(limit=8)}
        return self

    def row(self) -> dict:
        """Flat, JSON-serialisable record (no image): one row of the results table.

        Region metrics become columns ``region.<name>.<metric>`` (:func:`cornell_harness.evaluate.regions.region_columns`).
        """
        out = {
            "scene": self.scene,
            "scene_hash": self.scene_hash,
            "renderer": self.renderer,
            "status": self.status,
            "reason": self.reason,
            "version": self.version,
            "settings": self.settings,
            "estimator": self.estimator,
            "scene_settings": self.scene_settings,
            "rgb_convention": convention_used(self.scene_rgb_convention, self.info),
            "approximations": json.dumps(list(self.approximations)),
            "spp": self.spp,
            "seed": self.seed,
            "time_s": None if self.time_s is None else round(self.time_s, 4),
            "cpu_time_s": _rounded(self.cpu_time_s, 4),
            "setup_s": _rounded(self.setup_s, 4),
            "threads": self.threads,
            "load_before": _rounded(self.load_before, 3),
            "load_after": _rounded(self.load_after, 3),
            "calibration_s": _rounded(self.calibration_s, 5),
            "foreign_cpu": _rounded(self.foreign_cpu, 3),
        }
        if self.agreement is not None:
            out.update(agreement=self.agreement, agreement_p_min=_rounded(self.agreement_p_min, 6))
        out.update(self.metrics)
        out.update(named_regions.region_columns(self.regions))
        if "mse" in self.metrics and self.time_s:
            out["efficiency"] = 1.0 / (self.metrics["mse"] * self.time_s) if self.metrics["mse"] > 0 else math.inf
        for k, v in self.info.items():
            out[f"info_{k}"] = v if isinstance(v, (str, int, float, bool)) or v is None else json.dumps(v)
        timings = self.time_samples or ([(self.time_s, self.cpu_time_s)]
                                        if self.time_s is not None else [])
        out.update(timing_stats.repeat_columns([w for w, _ in timings], [c for _, c in timings]))
        return out

    def timed(self, result: RenderResult, timing: Timing) -> "RunRecord":
        """This record with the timing figures of ``result``, rendered in a call measured as ``timing``."""
        self.cpu_time_s = cpu_time(result, timing)
        if result.cpu_time_s is None:
            self.info["cpu_time_of"] = CALL_CPU_NOTE
        setup = result.info.get("setup_s")
        self.setup_s = float(setup) if isinstance(setup, (int, float)) else None
        self.threads = threads_of(result.info)
        self.load_before, self.load_after = timing.load_before, timing.load_after
        self.calibration_s, self.foreign_cpu = timing.calibration_s, timing.foreign_cpu
        return self


#: What ``info_cpu_time_of`` says of a row whose renderer gave no CPU time of its render proper.
CALL_CPU_NOTE = "the whole render call, set-up included (the renderer gives no CPU time of its render proper)"


def render_timed(entry: RendererEntry, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = (),
                 stop: Callable[[Checkpoint], bool] | None = None) -> tuple[RenderResult, Timing]:
    """:func:`render_checked` measured (:func:`cornell_harness.workflows.timing.measure`): every timed render of the
    harness (a run, a repeat, a time budget's calibration) is this call; its CPU time is :func:`cpu_time`.
    An entry with a time limit renders in a child process ended at it (:func:`render_sandboxed`). ``stop`` may end
    the render at a checkpoint (:func:`cornell_harness.workflows.render.render_checked`)."""
    if entry.time_limit_s is not None:
        return render_sandboxed(entry, scene, spp, seed, checkpoints, entry.time_limit_s, stop)
    return measure(lambda: render_checked(entry, scene, spp, seed, checkpoints, stop))


def cpu_time(result: RenderResult, timing: Timing) -> float:
    """The CPU time of a render: of its render proper where the renderer measured it, else of the whole call
    measured as ``timing`` (set-up included: :data:`CALL_CPU_NOTE`)."""
    return float(timing.cpu_s if result.cpu_time_s is None else result.cpu_time_s)


def _rounded(value: float | None, digits: int) -> float | None:
    return None if value is None else round(float(value), digits)


def threads_of(info: dict) -> int | None:
    """The threads a render ran on: what the renderer says (``info["threads"]``), else the share it was given."""
    given = info.get("threads")
    if isinstance(given, int) and not isinstance(given, bool) and given > 0:
        return given
    try:
        return default_threads()
    except SettingsError:
        return None


def rows_frame(records: Sequence["RunRecord"]):
    """The records' rows as a results table (pandas imported here: the sandbox's child never needs it)."""
    import pandas as pd

    return pd.DataFrame([r.row() for r in records])


#: Fields a results row holds as JSON text (a table cell is a scalar); objects again in JSON output.
JSON_TEXT_FIELDS = ("settings", "scene_settings", "approximations", "time_samples_s", "cpu_time_samples_s")


def json_row(row: dict) -> dict:
    """A results row as strict JSON (``--json``): region metrics nested under "regions", the
    :data:`JSON_TEXT_FIELDS` as the objects they hold (never JSON inside a string), non-finite floats None."""
    out = {k: v for k, v in row.items() if not (isinstance(k, str) and k.startswith(named_regions.REGION_PREFIX))}
    for key in JSON_TEXT_FIELDS:
        if isinstance(out.get(key), str):
            try:
                out[key] = json.loads(out[key])
            except ValueError:  # not written by this version: left as it is
                pass
    if regions := named_regions.nested_regions(row):
        out["regions"] = regions
    return json_safe(out)


def json_record(rec: "RunRecord") -> dict:
    """One run as strict JSON (``cbox compare --json``): :func:`json_row` of its row."""
    return json_row(rec.row())


def render_sandboxed(entry: RendererEntry, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int],
                     time_limit_s: float, stop: Callable[[Checkpoint], bool] | None = None
                     ) -> tuple[RenderResult, Timing]:
    """:func:`render_checked` in a child process that is killed after ``time_limit_s`` (a hang cannot stall CI),
    with the child's measure of the call (:func:`cornell_harness.workflows.timing.measure`).

    Raises :class:`RenderTimeout` (carrying the time) when it is killed, RenderError for anything else
    that went wrong there.
    """
    out = run_sandboxed(entry.spec, [(scene, spp, seed, list(checkpoints), stop)], time_limit_s,
                        settings=dict(entry.settings))
    if out.ended == "timeout":
        raise RenderTimeout(f"killed at its time limit of {time_limit_s:g} s (ran {out.time_s:.1f} s)", out.time_s)
    if (why := out.problem()) is not None:
        raise RenderError(why, out.traceback)
    shots = [Checkpoint(s, image, t, cpu_time_s=cpu, variance=var) for s, image, t, cpu, var in out.checkpoints[0]]
    return (RenderResult(out.images[0], out.render_times[0], out.spps[0], seed, shots, out.infos[0], out.variances[0],
                         cpu_time_s=out.cpu_times[0]), out.timings[0])


def run_one(entry: RendererEntry, scene: Scene, spp: int, seed: int, reference: Reference | None,
            checkpoints: Sequence[int] = (), time_limit_s: float | None = None,
            stop: Callable[[Checkpoint], bool] | None = None) -> RunRecord:
    """Render and score one renderer; never raises for the renderer's own failures.

    With ``time_limit_s`` (or the entry's own) the render runs in a child process (:func:`render_sandboxed`);
    one that is killed at the limit is recorded as failed with ``info["timed_out"]`` and the time it ran.
    A render that ``stop`` ended early is recorded at the spp it reached.
    """
    rec = RunRecord.new(scene, entry, spp, seed)
    if rec.status != "ok":
        return rec
    try:
        rec.version = str(entry.renderer.version())
        result, timing = render_timed(entry.with_time_limit(time_limit_s), scene, spp, seed, checkpoints, stop)
    except RenderTimeout as e:
        rec.status, rec.reason, rec.time_s = "failed", str(e), e.time_s
        rec.info = {"timed_out": True}
        return rec
    except Exception as e:  # any renderer bug must be reported, not crash the run
        return rec.failed(e)
    rec.spp = int(result.spp) if stop is not None else spp
    rec.time_s, rec.info, rec.image = float(result.time_s), dict(result.info), result.image
    rec.variance, rec.checkpoints = result.variance, list(result.checkpoints)
    rec.timed(result, timing)
    if reference is None:
        rec.metrics = metrics.invalid_pixel_counts(result.image)
    else:
        rec.metrics, rec.regions = score(scene, result.image, reference, rec.spp, result.variance)
    return rec


def run_checkpoints(entry: RendererEntry, scene: Scene, spps: Sequence[int], seed: int,
                    reference: Reference) -> list[RunRecord]:
    """One scored record per spp of one (renderer, seed); the last holds the highest-spp image.

    A progressive renderer gives every checkpoint from one render; for one
    that does not, each missing spp is a render of its own (its time then is
    that render's time). A failure gives a single failed record.
    """
    spps = sorted(set(spps))
    top = run_one(entry, scene, spps[-1], seed, None, checkpoints=spps)
    if top.status != "ok":
        return [top]
    shots = {c.spp: (c.image, c.time_s, c.cpu_time_s) for c in top.checkpoints}
    shots[top.spp] = (top.image, top.time_s, top.cpu_time_s)
    try:
        for spp in spps:
            if spp not in shots:
                extra, timing = render_timed(entry, scene, spp, seed)
                shots[spp] = (extra.image, extra.time_s, cpu_time(extra, timing))
    except Exception as e:  # as in run_one: recorded, not raised
        return [top.failed(e)]
    out = []
    for spp in spps:
        image, t, cpu = shots[spp]
        # The cell's machine figures on every row; the CPU time of the checkpoint where the renderer gave one.
        rec = RunRecord.new(scene, entry, spp, seed, version=top.version, time_s=float(t), info=dict(top.info),
                            cpu_time_s=cpu, setup_s=top.setup_s, threads=top.threads, load_before=top.load_before,
                            load_after=top.load_after, calibration_s=top.calibration_s,
                            foreign_cpu=top.foreign_cpu)
        # Only the highest-spp image comes with the renderer's own variance.
        rec.image = image
        rec.metrics, rec.regions = score(scene, image, reference, spp, top.variance if spp == top.spp else None)
        out.append(rec)
    out[-1].variance = top.variance
    return out


def score(scene: Scene, image: np.ndarray, reference: Reference, spp: int,
          variance: np.ndarray | None = None) -> tuple[dict, dict]:
    """A run's metrics (every image metric and the noise yardsticks) and its regions' (per named region of the
    scene; {} without regions), by the one scorer (:func:`cornell_harness.evaluate.score.score_image`).

    ``variance`` is the image's own variance of its mean, when the renderer gives it; otherwise the noise
    model at ``spp`` stands in for it in a region's ``mean_z``. Masks are cached per scene.
    """
    result = score_image(image, reference, spp, masks=named_regions.region_masks(scene), variance=variance)
    return result.values, result.regions
