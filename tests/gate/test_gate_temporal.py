"""Gate budgets on flicker, lag and ghosting: checked against the registry, refused with still-render checks, and
an expectation budgeting them renders the animated scene's frames and passes or fails on them."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from cornell_harness.gate import run as gate_run
from cornell_harness.gate.config import GateConfigError, load_config
from tests.sequence_fakes import moving_light, references


def config(tmp_path, body: str):
    path = tmp_path / "gate.toml"
    path.write_text('[[expect]]\nscene = "moving"\nrenderer = "tests.sequence_fakes:ExponentialTruth"\n' + body)
    return load_config(path)


def test_temporal_budgets_are_registry_names_and_go_with_frames_only(tmp_path):
    cfg = config(tmp_path, "spp = 2\nmax = { lag = 3, flicker = 0.05, rmse = 1 }\n")
    assert cfg.expectations[0].frames and cfg.expectations[0].max["lag"] == 3
    with pytest.raises(GateConfigError, match=r"max\.flickr: unknown metric \(did you mean 'flicker'\?\)"):
        config(tmp_path, "spp = 2\nmax = { flickr = 0.05 }\n")
    with pytest.raises(GateConfigError, match=r"min\.lag: unknown metric"):
        config(tmp_path, "spp = 2\nmin = { lag = 1 }\n")
    with pytest.raises(GateConfigError, match=r"max\.lag: lag is at least 0"):
        config(tmp_path, "spp = 2\nmax = { lag = -1 }\n")
    with pytest.raises(GateConfigError, match=r"expect\[0\]\.unbiased: goes with a still render"):
        config(tmp_path, "spp = 2\nunbiased = true\nmax = { ghosting = 0.1 }\n")


def test_a_long_history_fails_a_lag_budget_that_a_short_one_passes(tmp_path, monkeypatch):
    """Hysteresis 0.97 on 18 frames (the light stopping at 5) has not settled by the steady frames: its lag is
    inf, which no max budget passes, whatever its size, and the check says why."""
    scene = moving_light(frames=18, stop=5, size=12)
    monkeypatch.setattr(gate_run, "resolve_scene", lambda name, overrides=(): scene)
    monkeypatch.setattr(gate_run, "sequence_references", lambda sc, frames: references(sc, list(frames)))
    checks = {}
    for h in (0.1, 0.97):
        cfg = config(tmp_path, f"spp = 4\nsettings = {{ hysteresis = {h} }}\nmax = {{ lag = 100, flicker = 1 }}\n")
        (outcome,) = gate_run.run_gate(cfg, sandbox=False)
        checks[h] = {c.name: c for c in outcome.checks}
        assert checks[h]["finite"].passed and checks[h]["max.flicker"].passed
    assert checks[0.1]["max.lag"].passed and checks[0.1]["max.lag"].value <= 2
    unsettled = checks[0.97]["max.lag"]
    assert not unsettled.passed and unsettled.value == math.inf
    assert unsettled.message == "lag = inf, budget ≤ 100 (not settled within the sequence)"


def test_the_docs_example_budget_loads(tmp_path):
    """docs/temporal.md's gate.toml example is a valid config: an expectation on the stored animated scene's
    frames, budgeting lag and flicker."""
    text = (Path(__file__).resolve().parents[2] / "docs" / "temporal.md").read_text(encoding="utf-8")
    (example,) = re.findall(r"```toml\n(# gate\.toml.*?)```", text, re.S)
    (tmp_path / "gate.toml").write_text(example)
    (expectation,) = load_config(tmp_path / "gate.toml").expectations
    assert expectation.frames and expectation.scene == "cornell-box-moving-light"
    assert {"lag", "flicker"} <= set(expectation.max)
