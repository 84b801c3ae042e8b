"""Sequential expectations (cornell_harness.gate.sequential): looks at doubling spp, stopped at the first
verdict, error rates spent over the looks.

The renderers are the reference plus its own noise model, rendered progressively (tests/user_renderers.py:
ProgressiveNoise and its kin), so the statistics are known and nothing renders for long; seeds fixed.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from cornell_harness.adapters.registry import resolve
from cornell_harness.gate.config import GateConfigError, load_config
from cornell_harness.gate.run import run_gate
from cornell_harness.gate.sequential import design
from tests import user_renderers
from tests.gate.test_gate import _config, config_error

PROGRESSIVE = "tests.user_renderers:ProgressiveNoise"
BOX_MARGINS = ('margin = { image = 0.005, "region.walls" = 0.01, "region.boxes" = 0.01, "region.floor" = 0.01, '
               '"region.light" = 0.01, "region.back-edge" = 0.08 }\n')


def _expect(extra: str = BOX_MARGINS, renderer: str = PROGRESSIVE, scene: str = "cornell-box",
            budget: str = "max_spp = 1024\n") -> str:
    return f'[[expect]]\nscene = "{scene}"\nrenderer = "{renderer}"\n{budget}unbiased = true\n{extra}'


@pytest.mark.parametrize("extra, field, words", [
    ("", "expect[0].max_spp", "needs unbiased = true and a margin table"),
    (BOX_MARGINS + "slope = [-0.6, -0.4]\n", "expect[0].slope", "goes with spp, not max_spp"),
    (BOX_MARGINS + "max = { rmse = 1 }\n", "expect[0].max", "goes with spp, not max_spp"),
    (BOX_MARGINS + "first_spp = 1024\n", "expect[0].first_spp", "must be below max_spp (1024)"),
    (BOX_MARGINS + "spp = 64\n", "expect[0].spp", "give exactly one budget"),
])
def test_sequential_config_errors(tmp_path, extra, field, words):
    path = _config(tmp_path, _expect(extra), head="")
    with config_error(path, field, words):
        load_config(path)


def test_first_spp_goes_with_max_spp(tmp_path):
    path = _config(tmp_path, _expect(BOX_MARGINS + "first_spp = 4\n", budget="spp = 64\n"), head="")
    with pytest.raises(GateConfigError, match=re.escape("expect[0].first_spp: goes with max_spp")):
        load_config(path)


@pytest.mark.parametrize("head, field", [("beta = 0.5\n", "beta"), ('spending = "linear"\n', "spending")])
def test_beta_and_spending_are_checked(tmp_path, head, field):
    with pytest.raises(GateConfigError, match=re.escape(f": {field}: ")):
        load_config(_config(tmp_path, _expect(), head=head))


def test_the_looks_and_their_levels(tmp_path):
    cfg = load_config(_config(tmp_path, _expect(BOX_MARGINS + "first_spp = 100\n", budget="max_spp = 1000\n"),
                              head='beta = 0.1\nspending = "pocock"\n'))
    exp = cfg.expectations[0]
    assert exp.looks() == [100, 200, 400, 800, 1000] and exp.name.endswith("@max1000spp")
    d = design(exp, cfg)
    assert sum(d.pass_levels) == pytest.approx(2 * 0.1) and d.spending == "pocock"
    assert sum(d.fail_levels) == pytest.approx(1 - (1 - 0.01) ** (1 / 3))  # the agreement's share of alpha
    assert load_config(_config(tmp_path, _expect())).expectations[0].looks() == [64, 128, 256, 512, 1024]


def _run(tmp_path, body: str, seed: int = 0, head: str = "", overrides=None):
    return run_gate(load_config(_config(tmp_path, body, head=head)), seed_offset=seed, sandbox=False,
                    overrides=overrides)[0]


def test_a_gross_bias_fails_at_the_first_look_and_renders_no_further(tmp_path, monkeypatch):
    monkeypatch.setenv(user_renderers.ProgressiveNoise.BIAS_ENV, "0.2")
    user_renderers.ProgressiveNoise.samples = 0
    o = _run(tmp_path, _expect())
    assert o.verdict == "fail" and o.record.spp == 64
    assert user_renderers.ProgressiveNoise.samples == 64  # the rest of the 1024 spp never rendered
    agreement = next(c for c in o.checks if c.name == "agreement")
    assert "stopped at look 1 of 5 (64 of 1024 spp" in agreement.message


def test_a_clean_render_passes_before_its_budget(tmp_path, monkeypatch):
    monkeypatch.delenv(user_renderers.ProgressiveNoise.BIAS_ENV, raising=False)
    user_renderers.ProgressiveNoise.samples = 0
    o = _run(tmp_path, _expect())
    assert o.verdict == "pass", [c.message for c in o.checks if not c.passed]
    assert o.record.spp < 1024 and user_renderers.ProgressiveNoise.samples == o.record.spp
    info = o.record.info["sequential"]
    assert info["verdict"] == "pass" and info["stop_spp"] == o.record.spp and info["looks"][-1] == o.record.spp
    assert {c.name for c in o.checks} == {"finite", "agreement", "variance", "outliers", "equivalence"}


def test_a_renderer_that_cannot_stop_gets_the_same_verdict_from_its_checkpoints(tmp_path, monkeypatch):
    monkeypatch.delenv(user_renderers.ProgressiveNoise.BIAS_ENV, raising=False)
    stopping = _run(tmp_path, _expect(), seed=3)
    full = _run(tmp_path, _expect(renderer="tests.user_renderers:StopsNever"), seed=3)
    assert full.record.spp == 1024 and stopping.record.spp < 1024
    assert full.verdict == stopping.verdict and full.record.info["sequential"]["stop_spp"] == stopping.record.spp
    assert "cannot stop early and rendered all 1024 spp" in next(c.message for c in full.checks
                                                                 if c.name == "equivalence")


def test_the_variance_the_result_reports_is_checked(tmp_path, monkeypatch):
    """The stop rule saw no variance; the result's, 4 times too small, fails the variance check (z spread 2)."""
    monkeypatch.delenv(user_renderers.ProgressiveNoise.BIAS_ENV, raising=False)
    honest = _run(tmp_path, _expect())
    lying = _run(tmp_path, _expect(renderer="tests.user_renderers:UnderstatesItsResult"))
    checks = {o.record.renderer: next(c for c in o.checks if c.name == "variance") for o in (honest, lying)}
    assert all(not c.skipped for c in checks.values())
    assert checks[honest.record.renderer].passed, checks[honest.record.renderer].message
    assert not checks[lying.record.renderer].passed and "the result's variance" in checks[lying.record.renderer].message


def test_the_stop_rule_travels_to_the_sandbox(tmp_path, monkeypatch):
    monkeypatch.setenv(user_renderers.ProgressiveNoise.BIAS_ENV, "0.2")
    o = run_gate(load_config(_config(tmp_path, _expect(), head="")))[0]  # a spec: rendered in a child process
    assert o.verdict == "fail" and o.record.spp == 64


def test_a_glass_shadow_error_of_10_percent_cannot_pass_a_5_percent_margin(tmp_path):
    """The issue's example: glass-shadow scaled by 1.10 against a 5% margin fails or stays inconclusive."""
    body = _expect('margin = { "region.glass-shadow" = 0.05 }\n', "tests.user_renderers:RegionProgressiveNoise",
                   "cornell-box-caustics", "max_spp = 4096\n")
    verdicts = [_run(tmp_path, body, seed).verdict for seed in range(4)]
    assert "pass" not in verdicts, verdicts


def _rates(tmp_path, body: str, seeds: int, renderer) -> tuple[list[str], list[int]]:
    outcomes = [_run(tmp_path, body, seed, overrides={renderer: resolve([renderer])[0]}) for seed in range(seeds)]
    return [o.verdict for o in outcomes], [o.record.spp for o in outcomes]


def test_false_fail_and_false_pass_rates_over_seeds(tmp_path, monkeypatch):
    """Clean: fails at rate <= alpha = 0.01; a bias at the margin: passes at rate <= beta = 0.05.

    Over 10 seeds, 2 or more false fails has probability < 0.005 at alpha = 0.01, and 3 or more false passes
    < 0.012 at beta = 0.05: the false-alarm rate of this test."""
    monkeypatch.delenv(user_renderers.ProgressiveNoise.BIAS_ENV, raising=False)
    verdicts, spps = _rates(tmp_path, _expect(), 10, PROGRESSIVE)
    assert verdicts.count("fail") <= 1, verdicts
    assert np.mean(spps) < 1024  # it stops early on clean runs
    monkeypatch.setenv(user_renderers.ProgressiveNoise.BIAS_ENV, "0.01")  # walls' margin; the image's is 0.005
    verdicts, _ = _rates(tmp_path, _expect(), 10, PROGRESSIVE)
    assert verdicts.count("pass") <= 2, verdicts
