"""``cbox gate --plan`` (cornell_harness.gate.plan): from a pilot render, the spp that resolves each region's
margin with power 1 − β, and the expectations whose budget, or whose reference's variance, cannot.

The renderer is the reference plus its own noise model (tests/user_renderers.py: ScaledMitsubaNoise), whose
reported variance is exact, so the plans are known; seeds fixed, renders instant.
"""

from __future__ import annotations

import numpy as np
import pytest

from cornell_harness.evaluate.relative_bias import critical_z
from cornell_harness.gate.config import load_config
from cornell_harness.gate.plan import BETA, plan_gate, plan_lines, target_half_width
from tests.conftest import cbox_in_process
from tests.gate.test_gate import _config
from tests.gate.test_gate_margins import _expect


#: Margins a 64 spp budget resolves on cornell-box (its thin back-edge region is noisy: a wide margin).
OK = 'image = 0.01, "region.back-edge" = 0.2'


def _plan(tmp_path, margins: list[str], pilot: int | None = None, spp: int = 64):
    body = "".join(_expect(f"margin = {{ {m} }}\n", name=f"e{i}", spp=spp) for i, m in enumerate(margins))
    return plan_gate(load_config(_config(tmp_path, body, head="")), pilot=pilot, sandbox=False)


def test_the_target_half_width_passes_an_unbiased_render_with_probability_one_minus_beta():
    """An unbiased estimate b ~ N(0, se²) with z·se at the target half-width passes (|b| + z·se ≤ m) at a rate
    of 1 − β: 20000 draws, sd of the rate 0.003, the band ±0.015 is 5 sd."""
    level, margin = 0.001, 0.05
    hw = float(target_half_width(margin, level))
    se = hw / critical_z(level)
    b = se * np.random.default_rng(3).standard_normal(20000)
    rate = np.mean(np.abs(b) + hw <= margin)
    assert rate == pytest.approx(1 - BETA, abs=0.015)


def test_a_margin_twice_as_wide_needs_about_a_quarter_of_the_spp(tmp_path):
    narrow, wide = _plan(tmp_path, ["image = 0.002", "image = 0.004"])
    ratio = wide.regions[0].spp / narrow.regions[0].spp
    # Exactly 1/4 without the reference's share of the variance, which does not fall with spp: a little less.
    assert 0.2 < ratio <= 0.25, ratio
    assert narrow.regions[0].region == "image" and narrow.regions[0].margin == 0.002


def test_a_pilot_at_twice_the_spp_gives_the_same_plan(tmp_path):
    (at4,), (at8,) = _plan(tmp_path, ["image = 0.002"], pilot=4), _plan(tmp_path, ["image = 0.002"], pilot=8)
    assert (at4.pilot_spp, at8.pilot_spp) == (4, 8)
    for a, b in zip(at4.regions, at8.regions):
        assert a.region == b.region
        assert b.spp == pytest.approx(a.spp, rel=0.1), a.region


def test_the_default_pilot_is_a_sixteenth_of_the_budget(tmp_path):
    (p,) = _plan(tmp_path, ["image = 0.01"], spp=64)
    assert p.pilot_spp == 4 and p.budget_spp == 64 and p.pilot_time_s is not None
    assert all(r.time_s == pytest.approx(p.pilot_time_s * r.spp / 4) for r in p.regions)


def test_a_margin_the_reference_variance_forbids_is_listed(tmp_path):
    ok, forbidden = _plan(tmp_path, [OK, "image = 0.0001"])
    assert ok.affordable and not ok.reference_bound
    assert [r.region for r in forbidden.reference_bound] == ["image"] and not forbidden.affordable
    assert forbidden.regions[0].spp == np.inf and forbidden.regions[0].time_s is None


def test_a_budget_below_the_plan_is_listed(tmp_path):
    (p,) = _plan(tmp_path, ["image = 0.001"], spp=64)  # about 630 spp for this margin
    assert not p.reference_bound and p.needed_spp > 64 and not p.affordable


def test_plan_prints_a_line_per_expectation_and_region_and_writes_nothing(tmp_path, capsys):
    body = _expect(f"margin = {{ {OK} }}\n", name="fine") + _expect("margin = { image = 0.0001 }\n",
                                                                         name="tight")
    path = _config(tmp_path, body, head="")
    code, out, _ = cbox_in_process(capsys, "gate", "--plan", "--config", path, "--pilot-spp", "2")
    assert code == 0, out
    lines = out.splitlines()
    regions = ["image", "walls", "boxes", "floor", "light", "back-edge"]  # cornell-box's, the image first
    for name in ("fine", "tight"):
        start = lines.index(next(line for line in lines if line.startswith(f"{name}: budget 64 spp; pilot 2 spp")))
        assert [line.split(":")[0].strip() for line in lines[start + 1:start + 7]] == regions
    assert "tight: the reference's variance alone forbids image" in out
    assert "1 expectation(s) cannot resolve their margins" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gate.toml"]


def test_plan_config_error_is_exit_2(tmp_path, capsys):
    path = _config(tmp_path, _expect('margin = { "region.caustic" = 0.05 }\n'), head="")
    code, out, err = cbox_in_process(capsys, "gate", "--plan", "--config", path)
    assert code == 2 and "expect[0].margin.region.caustic" in err


def test_help_documents_plan(capsys):
    code, out, _ = cbox_in_process(capsys, "gate", "--help")
    assert code == 0 and "--plan" in out and "--pilot-spp" in out


@pytest.mark.parametrize("margin, affordable", [("image = 0.05, \"region.back-edge\" = 0.5", True),
                                                ("image = 0.002, \"region.back-edge\" = 0.5", False)])
def test_a_time_budget_is_planned_in_time(tmp_path, margin, affordable):
    """tests.user_renderers:Clocked reports 0.25 s + 0.0625 s per spp: 8 s buy 124 spp, the pilot 124 // 16."""
    body = _expect(f"margin = {{ {margin} }}\n", renderer="tests.user_renderers:Clocked").replace("spp = 64",
                                                                                                 'time = "8s"')
    (p,) = plan_gate(load_config(_config(tmp_path, body, head="")), sandbox=False)
    assert (p.budget_spp, p.budget_s, p.pilot_spp) == (None, 8.0, 7)
    assert p.pilot_time_s == pytest.approx(0.25 + 0.0625 * 7)
    assert p.affordable == affordable
    assert not p.reference_bound
    assert (max(r.time_s for r in p.regions) <= 8.0) == affordable  # by time: its spp is not known before


def test_pilot_spp_goes_with_plan(tmp_path, capsys):
    code, _, err = cbox_in_process(capsys, "gate", "--pilot-spp", "2", "--config", _config(tmp_path, _expect("")))
    assert code == 2 and "--pilot-spp" in err and "goes with --plan" in err


def test_a_pilot_that_fails_is_listed_with_why(tmp_path):
    body = _expect("margin = {}\n", renderer="tests.user_renderers:Crashes", name="crash")
    (p,) = plan_gate(load_config(_config(tmp_path, body, head="")), sandbox=False)
    assert p.regions == [] and "the pilot did not render" in p.problem and not p.affordable
    assert f"  crash: {p.problem}" in plan_lines([p])


def test_a_sequential_expectation_is_planned_against_its_last_look(tmp_path):
    body = ('[[expect]]\nscene = "cornell-box"\nrenderer = "tests.user_renderers:ScaledMitsubaNoise"\nmax_spp = 64\n'
            f'unbiased = true\nmargin = {{ {OK} }}\n')
    (p,) = plan_gate(load_config(_config(tmp_path, body, head="")), sandbox=False)
    assert p.budget_spp == 64 and p.pilot_spp == 4 and p.regions
