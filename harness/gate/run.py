"""Running a gate: render every expectation, check it, and keep or compare the baseline."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Callable, Sequence

from harness.adapters.registry import RendererEntry, RendererError, resolve
from harness.adapters.settings import SettingsError
from harness.gate.checks import Outcome, evaluate
from harness.gate.config import Expectation, GateConfig, GateConfigError
from harness.scenes.library import resolve_scene
from harness.scenes.model import SceneError
from harness.store.atomic import write_json_atomic
from harness.store.references import ReferenceError, load_reference
from harness.workflows import runner
from harness.workflows.compare import spp_for_time_budget


def _checkpoints(exp: Expectation, spp: int) -> list[int]:
    if not exp.slope:
        return []
    out, s = [], max(1, spp // 64)
    while s < spp:
        out.append(s)
        s *= 2
    return out + [spp]


def _resolve(cfg: GateConfig, i: int, exp: Expectation, overrides: dict[str, RendererEntry] | None,
             stored: dict):
    """Scene, reference and renderer (with its settings) of an expectation; config errors name the field.

    Run for every expectation before anything renders, so a typo fails in
    seconds, not after the expectations before it have rendered. ``stored``
    keeps each scene and reference by name: several expectations share one.
    """
    try:
        if exp.scene not in stored:
            scene = resolve_scene(exp.scene)
            stored[exp.scene] = scene, load_reference(scene)
        scene, ref = stored[exp.scene]
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
    return scene, ref, entry


def run_gate(cfg: GateConfig, overrides: dict[str, RendererEntry] | None = None, seed_offset: int = 0,
             on_start: Callable[[Expectation], None] | None = None,
             on_done: Callable[[Outcome], None] | None = None, sandbox: bool = True) -> list[Outcome]:
    """Render every expectation and check it; every scene, renderer and setting is resolved first.

    ``overrides`` replaces renderers by name (tests and the mutant benchmark use it); an override is
    an object of this process, so it renders here, without the time limit. Every other renderer
    renders in a child process killed at its expectation's ``time_limit`` (``sandbox=False``: all in
    this process, for measurements that run the gate hundreds of times). ``seed_offset`` shifts
    every expectation's seed (false-alarm measurements run the same gate over many seeds).
    ``on_start(expectation)`` and ``on_done(outcome)`` report progress as expectations finish.
    """
    baseline = load_baseline(cfg)
    metrics, seeds = baseline.get("expectations", {}), baseline.get("seeds", {})
    stored: dict = {}
    resolved = [_resolve(cfg, i, exp, overrides, stored) for i, exp in enumerate(cfg.expectations)]
    outcomes = []
    for exp, (scene, ref, entry) in zip(cfg.expectations, resolved):
        if on_start:
            on_start(exp)
        seed = exp.seed + seed_offset
        spp = exp.spp
        if spp is None:
            spp = spp_for_time_budget(entry, scene, exp.time_s, seed) if entry.available else 1
        limit = exp.time_limit_s if sandbox and exp.renderer not in (overrides or {}) else None
        rec = runner.run_one(entry, scene, spp, seed, ref, checkpoints=_checkpoints(exp, spp), time_limit_s=limit)
        # A baseline compares like with like: the same seed, so the same noise. Runs at other seeds
        # (false-alarm measurements) are not compared: a metric's spread between seeds can exceed the margin.
        same_seed = seeds.get(exp.name, seed) == seed
        outcomes.append(evaluate(exp, rec, ref, cfg, metrics.get(exp.name) if same_seed else None))
        if on_done:
            on_done(outcomes[-1])
    return outcomes


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
           if not c.passed and not c.name.startswith("baseline.")]
    if bad:
        return f"{len(bad)} check(s) failed ({', '.join(bad[:3])}{', ...' if len(bad) > 3 else ''})"
    return None


def write_baseline(cfg: GateConfig, outcomes: Sequence[Outcome]) -> tuple[Path, list[str]]:
    """Record the run's metrics as the baseline; returns the file and one ``old → new`` line per change."""
    if cfg.baseline is None:
        raise GateConfigError(cfg.path, "baseline", "set baseline = \"FILE.json\" to record a baseline")
    old = load_baseline(cfg).get("expectations", {})
    data = {"expectations": {o.expectation.name: runner.json_safe(o.record.metrics) for o in outcomes
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
