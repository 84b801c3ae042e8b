"""Running a gate: render every expectation, check it, and keep or compare the baseline.

Everything an expectation names is resolved first, for every expectation,
before anything renders (:func:`_resolve`): its scene and reference, the
regions its region metrics name, its renderer with its settings, the
renderer's estimator against ``unbiased = true``, and the settings of a
consistency check's smaller budget. The expectations then render wherever
the executor puts them (:func:`render_expectation`, in this process by
default) and are checked here.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from cornell_harness.adapters.registry import ESTIMATORS, RendererEntry, RendererError, estimator_of, resolve
from cornell_harness.adapters.settings import SettingsError
from cornell_harness.evaluate.regions import region_masks
from cornell_harness.evaluate.registry import region_metric
from cornell_harness.evaluate.score import metric_value
from cornell_harness.evaluate.sequential import doubling
from cornell_harness.gate.checks import Outcome, evaluate
from cornell_harness.gate.config import Expectation, GateConfig, GateConfigError
from cornell_harness.gate.sequential import Design, StopRule, design, evaluate_sequential
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.model import SceneError
from cornell_harness.store.atomic import json_safe, write_json_atomic
from cornell_harness.store.references import ReferenceError, load_reference
from cornell_harness.workflows import runner
from cornell_harness.workflows.cells import entry_for
from cornell_harness.workflows.compare import spp_for_time_budget
from cornell_harness.workflows.sequence_run import sequence_record, sequence_references
from cornell_harness.workflows.executor import DaskExecutor, InProcess, Task, task_key
from cornell_harness.workflows.render import RenderError, RenderTimeout, render_checked
from cornell_harness.workflows.sandbox import run_sandboxed


def _checkpoints(exp: Expectation, spp: int) -> list[int]:
    """The spps a render of ``spp`` must return images at: the RMSE slope's (spp/64 ..) and a consistency slope's."""
    starts = [max(1, spp // 64)] if exp.slope else []
    if exp.consistency is not None and exp.consistency.slope is not None:
        starts.append(exp.consistency.first_spp(spp))
    return sorted({s for first in starts for s in doubling(first, spp)})


def _check_regions(cfg: GateConfig, i: int, exp: Expectation, scene) -> None:
    """Every region a budget or consistency metric names must be one of the scene's."""
    for field, key in exp.region_metrics():
        region = region_metric(key)[0]
        if region not in scene.regions:
            raise GateConfigError(cfg.path, f"expect[{i}].{field}", f"scene {scene.name!r} has no region "
                                  f"{region!r}; its regions: {', '.join(scene.regions) or '(none)'}")
    for region in exp.margins.regions() if exp.margins else ():
        if region not in scene.regions:
            raise GateConfigError(cfg.path, f"expect[{i}].margin.region.{region}", f"scene {scene.name!r} has no "
                                  f"region {region!r}; its regions: {', '.join(scene.regions) or '(none)'}")


def _check_estimator(cfg: GateConfig, i: int, exp: Expectation, entry: RendererEntry) -> None:
    """``unbiased = true`` only for a renderer whose estimator is unbiased (the z-tests assume it)."""
    if entry.renderer is None:  # did not load: it will not run, and says why
        return
    try:
        estimator = estimator_of(entry.renderer)
    except RendererError as e:
        raise GateConfigError(cfg.path, f"expect[{i}].renderer", str(e)) from None
    if exp.unbiased and estimator != ESTIMATORS[0]:
        raise GateConfigError(cfg.path, f"expect[{i}].unbiased", f"renderer {entry.name!r} declares estimator = "
                              f"{estimator!r}: the agreement, variance and outlier tests assume an unbiased "
                              "estimator and would fail it for its bias; check it with a budget (max, min, abs_max) "
                              "or a consistency check")


def _smaller_entry(cfg: GateConfig, i: int, exp: Expectation, entry: RendererEntry) -> RendererEntry | None:
    """The renderer of a ``max_ratio`` consistency check's smaller budget (None without one), its settings checked."""
    c = exp.consistency
    if c is None or c.max_ratio is None:
        return None
    small = entry
    for key, value in c.smaller_settings.items():  # one at a time, so an error names its key
        try:
            small = small.with_settings({key: value})
        except SettingsError as e:
            raise GateConfigError(cfg.path, f"expect[{i}].consistency.smaller.{key}", str(e)) from None
    return small


def _resolve(cfg: GateConfig, i: int, exp: Expectation, overrides: dict[str, RendererEntry] | None,
             stored: dict, scene_overrides: Sequence[str] = ()):
    """Scene, reference, renderer (with its settings) and a consistency check's smaller-budget renderer (or None)
    of an expectation; config errors name the field.

    Run for every expectation before anything renders, so a typo fails in
    seconds, not after the expectations before it have rendered. ``stored``
    keeps each scene and reference by name: several expectations share one.
    """
    try:
        key = (exp.scene, exp.frames)  # an expectation on the frames takes each frame's reference
        if key not in stored:
            scene = resolve_scene(exp.scene, scene_overrides)
            stored[key] = scene, (sequence_references(scene, range(scene.frame_count)) if exp.frames
                                  else load_reference(scene))
        scene, ref = stored[key]
    except SceneError as e:
        # A stored name that does not exist is this field's error; a broken scene file is that file's.
        where = e.message if e.field == "--scene" else str(e)
        raise GateConfigError(cfg.path, f"expect[{i}].scene", f"{exp.scene!r}: {where}") from None
    except ReferenceError as e:
        raise GateConfigError(cfg.path, f"expect[{i}].scene", str(e)) from None
    try:
        entry = (overrides or {}).get(exp.renderer) or resolve([exp.renderer])[0]
        if exp.settings:
            entry = entry.with_settings(exp.settings)
    except (RendererError, SettingsError) as e:
        field = "settings" if isinstance(e, SettingsError) else "renderer"
        raise GateConfigError(cfg.path, f"expect[{i}].{field}", str(e)) from None
    _check_regions(cfg, i, exp, scene)
    _check_estimator(cfg, i, exp, entry)
    _check_bias_settings(cfg, i, exp, entry)
    return scene, ref, entry, _smaller_entry(cfg, i, exp, entry)


def _check_bias_settings(cfg: GateConfig, i: int, exp: Expectation, entry: RendererEntry) -> None:
    """A ``bias_limit``'s settings must be the renderer's and take every effort."""
    if (b := exp.bias_limit) is None:
        return
    for key in b.setting:
        for effort in b.efforts:
            try:
                entry.with_settings({key: effort})
            except SettingsError as e:
                raise GateConfigError(cfg.path, f"expect[{i}].bias_limit.setting", str(e)) from None


def resolve_all(cfg: GateConfig, overrides: dict[str, RendererEntry] | None = None,
                scene_overrides: Sequence[str] = ()) -> list[tuple]:
    """(scene, reference, renderer, smaller-budget renderer or None) of every expectation, in order; a config
    error (GateConfigError, naming the field) before anything renders."""
    stored: dict = {}
    return [_resolve(cfg, i, exp, overrides, stored, scene_overrides) for i, exp in enumerate(cfg.expectations)]


@dataclass(frozen=True)
class GateJob:
    """One expectation's renders as plain data for whichever process renders them: the renderer as its spec
    and settings (and a consistency check's smaller-budget settings), the seed, the time limit."""

    expectation: Expectation
    spec: str
    settings: dict
    smaller_settings: dict | None
    seed: int
    time_limit_s: float | None
    design: Design | None = None  # a sequential expectation's looks and levels (gate.sequential)


def render_bias_efforts(job: GateJob, scene, ref, entry: RendererEntry) -> dict[str, np.ndarray] | str:
    """A ``bias_limit``'s renders: per metric, its error at every (seed, effort), a (seeds, efforts) array; or why
    they could not be made (a string).

    With ``setting`` each effort is one render per seed with those settings at the bias limit's spp; without,
    each seed is one render at the last effort's spp with the others as checkpoints. Sandboxed (a time limit):
    one child process per effort setting renders every seed.
    """
    b = job.expectation.bias_limit
    seeds = b.seed_list(job.seed)
    masks = region_masks(scene) if any(region_metric(m) for m in b.metrics) else None
    if b.setting:
        runs = [(entry.with_settings({k: e for k in b.setting}), b.spp, ()) for e in b.efforts]
    else:
        runs = [(entry, b.efforts[-1], b.efforts[:-1])]
    images: dict[tuple[int, int], np.ndarray] = {}  # (seed index, effort index) -> image
    try:
        for r, (e, spp, checkpoints) in enumerate(runs):
            if job.time_limit_s is None:
                done = [render_checked(e, scene, spp, s, list(checkpoints)) for s in seeds]
                results = [(d.image, {c.spp: c.image for c in d.checkpoints}) for d in done]
            else:
                out = run_sandboxed(e.spec, [(scene, spp, s, list(checkpoints)) for s in seeds], job.time_limit_s,
                                    settings=dict(e.settings))
                if out.ended == "timeout":
                    raise RenderTimeout(f"killed at its time limit of {job.time_limit_s:g} s", out.time_s)
                if (why := out.problem()) is not None:
                    raise RenderError(why)
                results = [(out.images[j], {c[0]: c[1] for c in out.checkpoints[j]}) for j in range(len(seeds))]
            for j, (final, shots) in enumerate(results):
                shots[spp] = final
                for i, effort in enumerate(b.efforts):
                    if b.setting and i == r:
                        images[j, i] = final
                    elif not b.setting:
                        images[j, i] = shots[effort]
    except (RenderError, RenderTimeout, KeyError) as ex:
        return f"the bias limit's renders failed: {ex}"
    # The signed error, as every report has it (a mean radiance skips broken pixels).
    return {m: np.array([[metric_value(images[j, i], ref, b.spp or effort, m, masks) for i, effort in enumerate(b.efforts)]
                         for j in range(len(seeds))]) for m in b.metrics}


def render_expectation(job: GateJob, scene, ref, entry: RendererEntry | None = None,
                       small: RendererEntry | None = None) -> tuple[runner.RunRecord, runner.RunRecord | None, dict
                                                                    | str | None]:
    """The expectation's run (and its smaller-budget run, and its bias limit's errors), scored: the task a
    backend runs.

    In-process the caller's ``entry`` and ``small`` render it (a test's override among them); on a worker
    the job's spec is loaded there. A time budget is turned into spp here, on the machine that renders.
    """
    exp, seed = job.expectation, job.seed
    entry = entry or entry_for(job.spec, job.settings)
    if exp.frames:  # the animated scene's frames, scored as one record (ref: each frame's reference)
        return sequence_record(entry, scene, exp.spp, seed, ref, job.time_limit_s), None, None
    if small is None and job.smaller_settings is not None:
        small = entry_for(job.spec, job.smaller_settings)
    spp, stop = exp.spp, None
    if job.design is not None:  # sequential: one render to max_spp, its looks as checkpoints, stopped at a verdict
        spp, checkpoints = exp.max_spp, exp.looks()
        stop = StopRule(job.design, ref, region_masks(scene), exp.tile, exp.margins)
    else:
        if spp is None:
            spp = spp_for_time_budget(entry, scene, exp.time_s, seed) if entry.available else 1
        checkpoints = _checkpoints(exp, spp)
    rec = runner.run_one(entry, scene, spp, seed, ref, checkpoints=checkpoints, time_limit_s=job.time_limit_s,
                         stop=stop)
    smaller = None
    if small is not None and rec.status == "ok":  # the same renderer and seed at the smaller budget
        smaller = runner.run_one(small, scene, exp.consistency.smaller_spp or spp, seed, ref,
                                 time_limit_s=job.time_limit_s)
    bias = None
    if exp.bias_limit is not None and rec.status == "ok":
        bias = render_bias_efforts(job, scene, ref, entry)
    return rec, smaller, bias


def run_gate(cfg: GateConfig, overrides: dict[str, RendererEntry] | None = None, seed_offset: int = 0,
             on_start: Callable[[Expectation], None] | None = None,
             on_done: Callable[[Outcome], None] | None = None, sandbox: bool = True,
             scene_overrides: Sequence[str] = (), executor: InProcess | DaskExecutor | None = None) -> list[Outcome]:
    """Render every expectation and check it; every scene, renderer and setting is resolved first.

    ``overrides`` replaces renderers by name (tests and the mutant benchmark use it); an override is
    an object of this process, so it renders here, without the time limit. Every other renderer
    renders in a child process killed at its expectation's ``time_limit`` (``sandbox=False``: all in
    this process, for measurements that run the gate hundreds of times). ``seed_offset`` shifts
    every expectation's seed (false-alarm measurements run the same gate over many seeds).
    ``on_start(expectation)`` and ``on_done(outcome)`` report progress as expectations finish.
    ``scene_overrides`` (``KEY=VALUE``, ``cbox gate --set``) derive every expectation's scene
    (:mod:`cornell_harness.scenes.overrides`); each derived scene needs its own reference, and the baseline,
    recorded on the config's own scenes, is not compared. The expectations render on ``executor``
    (default: here, in order; :mod:`cornell_harness.workflows.executor`) and are checked here as they finish;
    the outcomes come back in the config's order.
    """
    executor = executor or InProcess()
    if overrides and not executor.local:
        raise ValueError("renderer overrides are objects of this process: run them with the in-process executor")
    baseline = load_baseline(cfg) if not scene_overrides else {}
    metrics, seeds = baseline.get("expectations", {}), baseline.get("seeds", {})
    resolved = resolve_all(cfg, overrides, scene_overrides)
    shared: dict = {}  # (scene name, frames) -> the executor's handles on its scene and reference(s), sent once
    tasks = []
    for i, (exp, (scene, ref, entry, small)) in enumerate(zip(cfg.expectations, resolved)):
        seed = exp.seed + seed_offset
        limit = exp.time_limit_s if sandbox and exp.renderer not in (overrides or {}) else None
        job = GateJob(exp, entry.spec, dict(entry.settings), None if small is None else dict(small.settings),
                      seed, limit, design(exp, cfg) if exp.max_spp else None)
        if (exp.scene, exp.frames) not in shared:
            shared[exp.scene, exp.frames] = executor.share(scene), executor.share(ref)
        local = (entry, small) if executor.local else (None, None)
        tasks.append(Task(task_key("expectation", str(cfg.path), i, repr(exp), seed, limit), exp.name,
                          render_expectation, (job, *shared[exp.scene, exp.frames], *local)))
    index = {t.key: i for i, t in enumerate(tasks)}
    outcomes: list[Outcome | None] = [None] * len(tasks)
    if on_start and tasks:
        on_start(cfg.expectations[0])
    for result in executor.run(tasks):
        i = index[result.task.key]
        exp, (scene, ref, entry, _) = cfg.expectations[i], resolved[i]
        if result.error is None:
            rec, smaller, bias = result.value
        else:  # its worker died or it raised, past its retries: a failed run, checked as one
            rec, smaller, bias = runner.RunRecord.new(scene, entry, exp.spp or 0, tasks[i].args[0].seed), None, None
            rec.status, rec.reason = "failed", f"not rendered: {result.error}"
        masks = region_masks(scene) if exp.region_metrics() or exp.unbiased else None  # regions are agreement tests
        base = _baseline_of(cfg, exp, rec, metrics, seeds, bool(scene_overrides))
        if exp.max_spp:
            outcomes[i] = evaluate_sequential(exp, rec, ref, cfg, masks)
        else:
            outcomes[i] = evaluate(exp, rec, ref, cfg, base, smaller, masks, bias)
        if on_done:
            on_done(outcomes[i])
        if on_start and (following := next((j for j in range(len(tasks)) if outcomes[j] is None), None)) is not None:
            on_start(cfg.expectations[following])
    return outcomes


def _baseline_of(cfg: GateConfig, exp: Expectation, rec: runner.RunRecord, metrics: dict, seeds: dict,
                 derived: bool) -> dict | str | None:
    """The baseline metrics ``rec`` is compared with; why it is not (a string: its baseline checks are skipped,
    and say so); None without a baseline in the config."""
    if cfg.baseline is None:
        return None
    if derived:
        return "the baseline was recorded on the config's own scenes, not on scenes derived with --set"
    if exp.name not in metrics:
        return "the baseline has no record of this expectation; record it with cbox gate --update-baseline"
    # A baseline compares like with like: the same seed, so the same noise. Runs at other seeds
    # (false-alarm measurements) are not compared: a metric's spread between seeds can exceed the margin.
    if (seed := seeds.get(exp.name, rec.seed)) != rec.seed:
        return f"the baseline was recorded at seed {seed}, this run is at seed {rec.seed}: other noise, not compared"
    return metrics[exp.name]


def load_baseline(cfg: GateConfig) -> dict:
    if cfg.baseline is None or not cfg.baseline.exists():
        return {}
    try:
        data = json.loads(cfg.baseline.read_text())
        return {"expectations": data["expectations"], "seeds": data.get("seeds", {})}
    except (json.JSONDecodeError, KeyError, TypeError) as e:
        raise GateConfigError(cfg.baseline, "(file)", f"not a gate baseline ({e}); rerun with --update-baseline")


def baseline_refusal(outcomes: Sequence[Outcome]) -> str | None:
    """Why this run must not become the baseline (a check other than a baseline check failed), or None."""
    bad = [f"{o.expectation.name} {c.name}" for o in outcomes for c in o.checks
           if c.failed and not c.name.startswith("baseline.")]
    if bad:
        return f"{len(bad)} check(s) failed ({', '.join(bad[:3])}{', ...' if len(bad) > 3 else ''})"
    return None


def write_baseline(cfg: GateConfig, outcomes: Sequence[Outcome]) -> tuple[Path, list[str]]:
    """Record the run's metrics as the baseline; returns the file and one ``old → new`` line per change."""
    if cfg.baseline is None:
        raise GateConfigError(cfg.path, "baseline", "set baseline = \"FILE.json\" to record a baseline")
    old = load_baseline(cfg).get("expectations", {})
    data = {"expectations": {o.expectation.name: json_safe(o.record.metrics) for o in outcomes
                             if o.record.status == "ok"},
            "seeds": {o.expectation.name: o.record.seed for o in outcomes}}
    changes = []
    for name, new in data["expectations"].items():
        for metric in cfg.regression_metrics:
            before, after = old.get(name, {}).get(metric), new.get(metric)
            if before != after:
                shown = "(none)" if before is None else f"{before:.6g}"
                changes.append(f"{name} {metric}: {shown} → {'(none)' if after is None else f'{after:.6g}'}")
    write_json_atomic(cfg.baseline, data)
    return cfg.baseline, changes
