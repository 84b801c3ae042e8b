"""The CI gate: config validation, verdicts and where they point, outputs, baselines."""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from conftest import run_cbox
from harness.evaluate import agreement
from harness.gate.checks import evaluate
from harness.gate.config import GateConfigError, load_config
from harness.gate.run import run_gate
from test_adapters import TESTS

EXPECT = """
[[expect]]
scene = "cornell-box"
renderer = "{renderer}"
spp = 64
unbiased = true
"""


def _config(tmp_path, body: str, head: str = "alpha = 0.01\n") -> str:
    path = tmp_path / "gate.toml"
    path.write_text(head + body)
    return str(path)


# -- the statistical test ------------------------------------------------------------

def test_sidak_level():
    assert agreement.sidak_level(0.01, 1) == pytest.approx(0.01)
    lvl = agreement.sidak_level(0.01, 771)
    assert 1 - (1 - lvl) ** 771 == pytest.approx(0.01)


def test_agreement_false_alarm_rate_is_alpha():
    """Pure noise of the assumed variance: the family-wise rejection rate is α = 0.1 here.

    400 trials: the count of rejections is Binomial(400, 0.1) (mean 40, sd 6);
    the assertion [16, 64] fails with probability < 1e-4 for a correct test.
    """
    rng = np.random.default_rng(0)
    ref = np.full((32, 32, 3), 0.5)
    var = np.full_like(ref, 1e-3)
    rejections = sum(not agreement.agreement_test(ref + np.sqrt(2e-3) * rng.standard_normal(ref.shape), var, ref,
                                                  var, tile=8, alpha=0.1).passed for _ in range(400))
    assert 16 <= rejections <= 64, rejections


def test_agreement_locates_a_local_error():
    rng = np.random.default_rng(1)
    ref = np.full((64, 64, 3), 0.5)
    var = np.full_like(ref, 1e-4)
    img = ref + np.sqrt(2e-4) * rng.standard_normal(ref.shape)
    img[16:32, 48:64, 1] += 0.05  # one tile, green channel
    a = agreement.agreement_test(img, var, ref, var, tile=16, alpha=0.01)
    assert not a.passed
    worst = a.failures[0]
    assert worst["x"] == (48, 64) and worst["y"] == (16, 32) and worst["channel"] == "G"
    assert "pixels x 48-63, y 16-31, channel G" in a.message()


def test_agreement_rejects_what_it_cannot_evaluate():
    """A NaN variance (e.g. from a NaN sample) makes its tile and the whole image fail, not pass silently."""
    ref = np.full((32, 32, 3), 0.5)
    var = np.full_like(ref, 1e-4)
    bad = var.copy()
    bad[3, 5, 0] = np.nan
    a = agreement.agreement_test(ref, bad, ref, var, tile=16, alpha=0.01)
    assert not a.passed and a.p_min == 0.0
    assert any(f.get("x") == (0, 16) and f.get("channel") == "R" for f in a.failures)


# -- config ----------------------------------------------------------------------------

@pytest.mark.parametrize("text, field", [
    ("alpha = 2\n" + EXPECT.format(renderer="pathtracer"), "alpha"),
    ("alpha = 0.01\n", "expect"),
    ('[[expect]]\nscene = "cornell-box"\nrenderer = "pathtracer"\n', "expect[0].spp"),
    ('[[expect]]\nscene = "cornell-box"\nrenderer = "x"\nspp = 4\ntime = "1s"\n', "expect[0].spp"),
    ('[[expect]]\nscene = "cornell-box"\nrenderer = "x"\nspp = 0\n', "expect[0].spp"),
    ('[[expect]]\nscene = "cornell-box"\nrenderer = "x"\ntime = "soon"\n', "expect[0].time"),
    ('[[expect]]\nscene = "cornell-box"\nrenderer = "x"\nspp = 4\nslope = [-0.4, -0.6]\n', "expect[0].slope"),
    ('[[expect]]\nscene = "cornell-box"\nrenderer = "x"\nspp = 4\nmax = { ssim = "high" }\n', "expect[0].max"),
    ('[[expect]]\nscene = 3\nrenderer = "x"\nspp = 4\n', "expect[0].scene"),
    ("[[expect]\n", "(syntax)"),
])
def test_bad_config_names_file_and_field(tmp_path, text, field):
    path = _config(tmp_path, text, head="")
    with pytest.raises(GateConfigError, match="^" + re.escape(f"{path}: {field}: ")):
        load_config(path)


def test_cli_bad_config_exit_2_one_line(tmp_path):
    path = _config(tmp_path, '[[expect]]\nscene = "cornell-box"\nrenderer = "x"\n', head="")
    proc = run_cbox("gate", "--config", path, "--out", str(tmp_path / "out"))
    assert proc.returncode == 2
    assert proc.stderr.strip() == f"cbox: error: {path}: expect[0].spp: give exactly one budget: spp = N or " \
                                  f"time = \"10s\""


def test_project_gate_config_is_valid():
    cfg = load_config(TESTS.parent / "gate.toml")
    names = {e.renderer for e in cfg.expectations}
    assert {"pathtracer", "mitsuba"} <= names and cfg.alpha == 0.01
    assert all(e.unbiased for e in cfg.expectations if e.renderer in ("pathtracer", "mitsuba"))


# -- verdicts and outputs --------------------------------------------------------------

def test_gate_passes_unbiased_and_fails_biased_with_outputs(tmp_path):
    body = EXPECT.format(renderer="user_renderers:ScaledMitsubaNoise") + \
        EXPECT.format(renderer="user_renderers:Biased1Percent") + \
        '[[expect]]\nname = "grey budget"\nscene = "cornell-box"\nrenderer = "user_renderers:FlatGrey"\nspp = 1\n' \
        'max = { delta_e2000_mean = 5.0 }\n'
    out = tmp_path / "out"
    proc = run_cbox("gate", "--config", _config(tmp_path, body), "--out", str(out), env_path=TESTS)
    assert proc.returncode == 1, proc.stderr
    junit = ET.parse(out / "gate-junit.xml").getroot()
    cases = {(c.get("classname"), c.get("name")): c.find("failure") is None for c in junit.iter("testcase")}
    assert cases[("cornell-box/user_renderers:ScaledMitsubaNoise@64spp", "agreement")] is True
    assert cases[("cornell-box/user_renderers:Biased1Percent@64spp", "agreement")] is False
    assert cases[("grey budget", "max.delta_e2000_mean")] is False
    assert cases[("grey budget", "finite")] is True
    md = (out / "gate-summary.md").read_text()
    assert "gate failed" in md and "**FAIL**" in md
    # The failure says by how much and where: a 1% bias shows on the whole image.
    assert "whole image, channel" in md and re.search(r"mean off by -(0\.9|1\.0)\d\d%", md)
    assert "budget ≤ 5" in proc.stdout and "off by" in proc.stdout
    html = (out / "report.html").read_text()
    assert "Gate failed" in html and "p-value per tile" in html and 'alt="|z| per tile"' in html


def test_nan_is_never_tolerated(tmp_path):
    from harness.store.references import load_reference
    from harness.scenes.library import resolve_scene
    from harness.adapters.registry import resolve
    from harness.workflows.runner import RunRecord
    from harness.evaluate import metrics

    cfg = load_config(_config(tmp_path, EXPECT.format(renderer="x")))
    scene = resolve_scene("cornell-box")
    ref = load_reference(scene)
    img = ref.image.copy()
    img[10, 20, 1] = np.nan
    (entry,) = resolve(["user_renderers:FlatGrey"])
    rec = RunRecord.new(scene, entry, 64, 0, time_s=1.0, image=img, metrics=metrics.image_metrics(img, ref.image))
    out = evaluate(cfg.expectations[0], rec, ref, cfg)
    finite = next(c for c in out.checks if c.name == "finite")
    assert not finite.passed and "1 NaN" in finite.message and "(x 20, y 10)" in finite.message


def test_baseline_regression(tmp_path):
    body = ('baseline = "base.json"\nregression_margin = 0.05\n' +
            EXPECT.format(renderer="user_renderers:ScaledMitsubaNoise"))
    cfg_path = _config(tmp_path, body)
    first = run_cbox("gate", "--config", cfg_path, "--out", str(tmp_path / "a"), "--update-baseline", env_path=TESTS)
    assert first.returncode == 0, first.stderr
    base = json.loads((tmp_path / "base.json").read_text())
    name = "cornell-box/user_renderers:ScaledMitsubaNoise@64spp"
    assert base["expectations"][name]["delta_e2000_mean"] > 0
    # Same seed, same metrics: passes against its own baseline.
    again = run_cbox("gate", "--config", cfg_path, "--out", str(tmp_path / "b"), env_path=TESTS)
    assert again.returncode == 0 and "baseline.delta_e2000_mean" in again.stdout
    # Pretend the baseline was 10% better: now a regression beyond the 5% margin.
    base["expectations"][name]["delta_e2000_mean"] *= 0.9
    (tmp_path / "base.json").write_text(json.dumps(base))
    worse = run_cbox("gate", "--config", cfg_path, "--out", str(tmp_path / "c"), env_path=TESTS)
    assert worse.returncode == 1
    assert "FAIL  " + name + "  baseline.delta_e2000_mean" in worse.stdout and "+11.1%" in worse.stdout
    # Another seed is other noise: not compared with a baseline recorded at seed 0.
    other = _config(tmp_path, body.replace("unbiased = true", "unbiased = true\nseed = 5"))
    moved = run_cbox("gate", "--config", other, "--out", str(tmp_path / "d"), env_path=TESTS)
    assert moved.returncode == 0 and "baseline." not in moved.stdout


def test_same_commit_same_verdict(tmp_path):
    """Seeds are fixed: two runs give identical metrics and checks."""
    cfg = load_config(_config(tmp_path, EXPECT.format(renderer="pathtracer")))
    from harness.scenes.loader import load_scene  # noqa: F401

    a = run_gate(cfg)[0]
    b = run_gate(cfg)[0]
    assert a.record.metrics == b.record.metrics
    assert [(c.name, c.passed, c.message) for c in a.checks] == [(c.name, c.passed, c.message) for c in b.checks]


def test_project_gate_passes(tmp_path):
    """The acceptance check: `cbox gate` passes our path tracer and Mitsuba on cornell-box."""
    cfg = load_config(TESTS.parent / "gate.toml")
    cfg.expectations = [e for e in cfg.expectations if e.renderer in ("pathtracer", "mitsuba")]
    outcomes = run_gate(cfg)
    for o in outcomes:
        assert o.passed, [c.message for c in o.checks if not c.passed]


def test_slope_check(tmp_path):
    """An optional RMSE-vs-spp slope range: met by our unbiased path tracer, failed by an impossible range.

    One progressive render gives the checkpoints 1..64; at 256² the single-seed
    slope lies within ±0.1 of -0.5 (the range here is ±0.2).
    """
    body = EXPECT.format(renderer="pathtracer") + "slope = [-0.7, -0.3]\n" + \
        EXPECT.format(renderer="pathtracer").replace('[[expect]]', '[[expect]]\nname = "too steep"') + \
        "slope = [-2.0, -1.0]\n"
    cfg = load_config(_config(tmp_path, body))
    ok, steep = run_gate(cfg)
    good = next(c for c in ok.checks if c.name == "slope.rmse_spp")
    bad = next(c for c in steep.checks if c.name == "slope.rmse_spp")
    assert good.passed and -0.7 <= good.value <= -0.3 and "spp 1..64" in good.message
    assert not bad.passed and bad.value == good.value
