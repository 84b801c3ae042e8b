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


def _resolve(cfg: GateConfig, i: int, exp: Expectation, overrides: dict[str, RendererEntry] | None):
    """Scene, reference and renderer (with its settings) of an expectation; config errors name the field.

    Run for every expectation before anything renders, so a typo fails in
    seconds, not after the expectations before it have rendered.
    """
    try:
        scene = resolve_scene(exp.scene)
        ref = load_reference(scene)
    except (SceneError, ReferenceError) as e:
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
             on_start: Callable[[Expectation], None] | None = None) -> list[Outcome]:
    """Render every expectation and check it. ``overrides`` replaces renderers by name (tests use it).

    ``seed_offset`` shifts every expectation's seed (false-alarm measurements
    run the same gate over many seeds).
    """
    baseline = load_baseline(cfg)
    metrics, seeds = baseline.get("expectations", {}), baseline.get("seeds", {})
    resolved = [_resolve(cfg, i, exp, overrides) for i, exp in enumerate(cfg.expectations)]
    outcomes = []
    for exp, (scene, ref, entry) in zip(cfg.expectations, resolved):
        if on_start:
            on_start(exp)
        seed = exp.seed + seed_offset
        spp = exp.spp
        if spp is None:
            spp = spp_for_time_budget(entry, scene, exp.time_s, seed) if entry.available else 1
        rec = runner.run_one(entry, scene, spp, seed, ref, checkpoints=_checkpoints(exp, spp))
        # A baseline compares like with like: the same seed, so the same noise. Runs at other seeds
        # (false-alarm measurements) are not compared: a metric's spread between seeds can exceed the margin.
        same_seed = seeds.get(exp.name, seed) == seed
        outcomes.append(evaluate(exp, rec, ref, cfg, metrics.get(exp.name) if same_seed else None))
    return outcomes


def load_baseline(cfg: GateConfig) -> dict:
    if cfg.baseline is None or not cfg.baseline.exists():
        return {}
    try:
        data = json.loads(cfg.baseline.read_text())
        return {"expectations": data["expectations"], "seeds": data.get("seeds", {})}
    except (json.JSONDecodeError, KeyError, TypeError) as e:
        raise GateConfigError(cfg.baseline, "(file)", f"not a gate baseline ({e}); rerun with --update-baseline")


def write_baseline(cfg: GateConfig, outcomes: Sequence[Outcome]) -> Path:
    if cfg.baseline is None:
        raise GateConfigError(cfg.path, "baseline", "set baseline = \"FILE.json\" to record a baseline")
    data = {"expectations": {o.expectation.name: runner.json_safe(o.record.metrics) for o in outcomes
                             if o.record.status == "ok"},
            "seeds": {o.expectation.name: o.record.seed for o in outcomes}}
    write_json_atomic(cfg.baseline, data)
    return cfg.baseline
