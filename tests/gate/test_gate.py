"""The CI gate: config validation, verdicts and where they point, outputs, baselines."""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from tests.conftest import ROOT, run_cbox
from cornell_harness.evaluate import agreement
from cornell_harness.gate.checks import evaluate
from cornell_harness.gate.config import GateConfigError, load_config
from cornell_harness.gate.run import run_gate

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


def config_error(path: str, field: str, words: str = ""):
    """pytest.raises for the one-line config error of gate file ``path``: it starts ``path: field: `` and says
    ``words``."""
    return pytest.raises(GateConfigError, match="^" + re.escape(f"{path}: {field}: ") + ".*" + re.escape(words))


# -- the statistical test ------------------------------------------------------------

def test_sidak_level():
    assert agreement.sidak_level(0.01, 1) == pytest.approx(0.01)
    lvl = agreement.sidak_level(0.01, 771)
    assert 1 - (1 - lvl) ** 771 == pytest.approx(0.01)
    # An early sequential look's family-wise level: the naive 1 - (1 - a)^(1/n) rounds it to 0.
    assert agreement.sidak_level(1e-30, 786) == pytest.approx(1e-30 / 786, rel=1e-9)


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
    ('[[expect]]\nscene = "cornell-box"\nrenderer = "x"\nspp = 4\nmax = { ssim = "high" }\n', "expect[0].max.ssim"),
    ('[[expect]]\nscene = 3\nrenderer = "x"\nspp = 4\n', "expect[0].scene"),
    ("[[expect]\n", "(syntax)"),
    ('[[expect]]\nname = 3\nscene = "cornell-box"\nrenderer = "x"\nspp = 4\nfinite_only = true\n', "expect[0].name"),
])
def test_bad_config_names_file_and_field(tmp_path, text, field):
    path = _config(tmp_path, text, head="")
    with config_error(path, field):
        load_config(path)


BUDGET = '[[expect]]\nscene = "cornell-box"\nrenderer = "x"\nspp = 4\n'


@pytest.mark.parametrize("text, field, message", [
    (BUDGET + "max = { delta_e2000_mean = -1 }\n", "expect[0].max.delta_e2000_mean",
     "delta_e2000_mean is at least 0, so -1 would fail every render"),
    (BUDGET + "min = { ssim = 1.5 }\n", "expect[0].min.ssim", "ssim is between -1 and 1, so 1.5 would fail every render"),
    (BUDGET + "min = { ssim = -2 }\n", "expect[0].min.ssim", "so -2 would pass every render"),
    (BUDGET + "max = { flip_mean = 1.5 }\n", "expect[0].max.flip_mean", "between 0 and 1, so 1.5 would pass every"),
    (BUDGET + "abs_max = { mean_radiance_rel_error = -0.1 }\n", "expect[0].abs_max.mean_radiance_rel_error",
     "|mean_radiance_rel_error| is at least 0"),
    (BUDGET + 'max = { "region.caustic.rmse" = -1 }\n', "expect[0].max.region.caustic.rmse",
     "region.caustic.rmse is at least 0"),
    (BUDGET + "max = { rmse = 0.5 }\nmin = { rmse = 0.9 }\n", "expect[0].min.rmse",
     "0.9 is above max.rmse = 0.5: every render would fail one of them"),
    (BUDGET + "abs_max = { rmse = 0.1 }\nmin = { rmse = 0.2 }\n", "expect[0].min.rmse", "above abs_max.rmse = 0.1"),
])
def test_a_budget_no_render_can_meet_or_break_is_refused(tmp_path, text, field, message):
    """A budget outside its metric's range (the registry's, as --fail's) or a min above its max decides every
    render alike: refused, naming the field."""
    path = _config(tmp_path, text, head="")
    with pytest.raises(GateConfigError) as e:
        load_config(path)
    assert str(e.value).startswith(f"{path}: {field}: ") and message in str(e.value), str(e.value)


def test_budgets_at_the_ends_of_their_range_are_taken(tmp_path):
    path = _config(tmp_path, BUDGET + "max = { ssim = 1, rmse = 0 }\nmin = { ssim = -1, rmse = 0 }\n"
                   "abs_max = { mean_radiance_rel_error = 0 }\n", head="")
    exp = load_config(path).expectations[0]
    assert exp.max == {"ssim": 1.0, "rmse": 0.0} and exp.min == {"ssim": -1.0, "rmse": 0.0}


@pytest.mark.parametrize("text, line", [
    ('[[expect]]\nscene = "cornell-box"\nrenderer = "x"\n', 'expect[0].spp: give exactly one budget: spp = N, '
                                                             'time = "10s" or max_spp = N (sequential)'),
    # used to render, pass every check, then crash writing the JUnit file (exit 1, nothing written)
    ('[[expect]]\nname = 3\nscene = "cornell-box"\nrenderer = "pathtracer"\nspp = 1\nfinite_only = true\n',
     "expect[0].name: expected a string, got int"),
    (BUDGET.replace('"x"', '"pathtracer"') + "max = { delta_e2000_mean = -1 }\n",
     "expect[0].max.delta_e2000_mean: delta_e2000_mean is at least 0, so -1 would fail every render"),
])
def test_cli_bad_config_exit_2_one_line(tmp_path, text, line):
    path = _config(tmp_path, text, head="")
    proc = run_cbox("gate", "--config", path, "--out", str(tmp_path / "out"))
    assert proc.returncode == 2
    assert proc.stderr.strip() == f"cbox: error: {path}: {line}"


def test_project_gate_config_is_valid():
    cfg = load_config(ROOT / "gate.toml")
    names = {e.renderer for e in cfg.expectations}
    assert {"pathtracer", "mitsuba"} <= names and cfg.alpha == 0.01
    assert all(e.unbiased for e in cfg.expectations if e.renderer in ("pathtracer", "mitsuba"))


# -- verdicts and outputs --------------------------------------------------------------

def test_gate_passes_unbiased_and_fails_biased_with_outputs(tmp_path):
    body = EXPECT.format(renderer="tests.user_renderers:ScaledMitsubaNoise") + \
        EXPECT.format(renderer="tests.user_renderers:Biased1Percent") + \
        '[[expect]]\nname = "grey budget"\nscene = "cornell-box"\nrenderer = "tests.user_renderers:FlatGrey"\nspp = 1\n' \
        'max = { delta_e2000_mean = 5.0 }\n'
    out = tmp_path / "out"
    proc = run_cbox("gate", "--config", _config(tmp_path, body), "--out", str(out), env_path=ROOT)
    assert proc.returncode == 1, proc.stderr
    junit = ET.parse(out / "gate-junit.xml").getroot()
    cases = {(c.get("classname"), c.get("name")): c.find("failure") is None for c in junit.iter("testcase")}
    assert cases[("cornell-box/tests.user_renderers:ScaledMitsubaNoise@64spp", "agreement")] is True
    assert cases[("cornell-box/tests.user_renderers:Biased1Percent@64spp", "agreement")] is False
    assert cases[("grey budget", "max.delta_e2000_mean")] is False
    assert cases[("grey budget", "finite")] is True
    md = (out / "gate-summary.md").read_text()
    assert "gate failed" in md and "**FAIL**" in md
    # The failure says by how much and where: a 1% bias shows most on the light's region (emission seen directly,
    # where the noise is least).
    assert re.search(r"region light \(\d+ pixels\), channel B: z = -\d+\.\d\d, region mean off by -(0\.9\d|1\.0\d)%", md)
    assert "budget ≤ 5" in proc.stdout and "off by" in proc.stdout
    html = (out / "report.html").read_text()
    assert "Gate failed" in html and "p-value per tile" in html and 'alt="|z| per tile"' in html


def test_nan_is_never_tolerated(tmp_path):
    from cornell_harness.store.references import load_reference
    from cornell_harness.scenes.library import resolve_scene
    from cornell_harness.adapters.registry import resolve
    from cornell_harness.workflows.runner import RunRecord
    from cornell_harness.evaluate import metrics

    cfg = load_config(_config(tmp_path, EXPECT.format(renderer="x")))
    scene = resolve_scene("cornell-box")
    ref = load_reference(scene)
    img = ref.image.copy()
    img[10, 20, 1] = np.nan
    (entry,) = resolve(["tests.user_renderers:FlatGrey"])
    rec = RunRecord.new(scene, entry, 64, 0, time_s=1.0, image=img, metrics=metrics.image_metrics(img, ref.image))
    out = evaluate(cfg.expectations[0], rec, ref, cfg)
    finite = next(c for c in out.checks if c.name == "finite")
    assert not finite.passed and "1 NaN" in finite.message and "(x 20, y 10)" in finite.message


def test_baseline_regression(tmp_path):
    body = ('baseline = "base.json"\nregression_margin = 0.05\n' +
            EXPECT.format(renderer="tests.user_renderers:ScaledMitsubaNoise"))
    cfg_path = _config(tmp_path, body)
    first = run_cbox("gate", "--config", cfg_path, "--out", str(tmp_path / "a"), "--update-baseline", env_path=ROOT)
    assert first.returncode == 0, first.stderr
    base = json.loads((tmp_path / "base.json").read_text())
    name = "cornell-box/tests.user_renderers:ScaledMitsubaNoise@64spp"
    assert base["expectations"][name]["delta_e2000_mean"] > 0
    # Same seed, same metrics: passes against its own baseline.
    again = run_cbox("gate", "--config", cfg_path, "--out", str(tmp_path / "b"), env_path=ROOT)
    assert again.returncode == 0 and "baseline.delta_e2000_mean" in again.stdout
    # Pretend the baseline was 10% better: now a regression beyond the 5% margin.
    base["expectations"][name]["delta_e2000_mean"] *= 0.9
    (tmp_path / "base.json").write_text(json.dumps(base))
    worse = run_cbox("gate", "--config", cfg_path, "--out", str(tmp_path / "c"), env_path=ROOT)
    assert worse.returncode == 1
    assert "FAIL  " + name + "  baseline.delta_e2000_mean" in worse.stdout and "+11.1%" in worse.stdout
    # Another seed is other noise: not compared with a baseline recorded at seed 0.
    other = _config(tmp_path, body.replace("unbiased = true", "unbiased = true\nseed = 5"))
    moved = run_cbox("gate", "--config", other, "--out", str(tmp_path / "d"), env_path=ROOT)
    assert moved.returncode == 0 and "baseline." not in moved.stdout
    assert f"SKIP  {name}  baseline: skipped: the baseline was recorded at seed 0, this run is at seed 5" in moved.stdout
    # An expectation the baseline has no record of (added since) is not compared either, and says so.
    (tmp_path / "base.json").write_text(json.dumps({"expectations": {}, "seeds": {}}))
    new = run_cbox("gate", "--config", cfg_path, "--out", str(tmp_path / "e"), env_path=ROOT)
    assert new.returncode == 0 and f"SKIP  {name}  baseline: skipped: the baseline has no record" in new.stdout


def test_same_commit_same_verdict(tmp_path):
    """Seeds are fixed: two runs give identical metrics and checks, in the time-limited child process or not."""
    cfg = load_config(_config(tmp_path, EXPECT.format(renderer="pathtracer")))
    a = run_gate(cfg)[0]
    b = run_gate(cfg, sandbox=False)[0]
    assert a.record.metrics == b.record.metrics
    assert [(c.name, c.passed, c.message) for c in a.checks] == [(c.name, c.passed, c.message) for c in b.checks]


def test_project_gate_passes(tmp_path):
    """The acceptance check: `cbox gate` passes Mitsuba on every scene of gate.toml.

    Our path tracer's half of the project gate is run (in this process, the
    same images: test_same_commit_same_verdict) by
    tests/gate/test_gate_power.py::test_unmutated_path_tracer_passes_the_gate_at_its_seeds.
    """
    cfg = load_config(ROOT / "gate.toml")
    cfg.expectations = [e for e in cfg.expectations if e.renderer == "mitsuba"]
    assert len(cfg.expectations) >= 5
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


# -- the variance check and the outlier test (issue 9) ------------------------------------

def _unbiased(renderer: str, settings: str = "", spp: int = 256, seed: int = 0) -> str:
    """An unbiased cornell-box expectation named ``{seed}``, e.g. ``tests.user_renderers:HotPixel`` with ``x = 3, y = 4``."""
    return (f'[[expect]]\nname = "{seed}"\nscene = "cornell-box"\nrenderer = "{renderer}"\nspp = {spp}\n'
            f"seed = {seed}\nunbiased = true\n" + (f"settings = {{ {settings} }}\n" if settings else ""))


def _checks(tmp_path, body: str) -> dict:
    """{(expectation name, check name): Check} of ``body`` at α = 0.01: what run_gate does, without the metrics.

    (run_gate also scores every image, ΔE and SSIM included, which takes
    longer than these renderers' renders; the checks here need none of it.)
    """
    from cornell_harness.adapters.registry import resolve
    from cornell_harness.evaluate.regions import region_masks
    from cornell_harness.scenes.library import resolve_scene
    from cornell_harness.store.references import load_reference
    from cornell_harness.workflows import runner

    cfg = load_config(_config(tmp_path, body))
    out = {}
    for exp in cfg.expectations:
        scene = resolve_scene(exp.scene)
        entry = resolve([exp.renderer])[0]
        entry = entry.with_settings(exp.settings) if exp.settings else entry
        rec = runner.run_one(entry, scene, exp.spp, exp.seed, None)  # no reference: no scoring
        checks = evaluate(exp, rec, load_reference(scene), cfg, masks=region_masks(scene)).checks
        out.update({(exp.name, c.name): c for c in checks})
    return out


def test_alpha_is_split_over_the_three_statistical_tests(tmp_path):
    """The config's α is per expectation: agreement, variance and outliers each get 1 − (1 − α)^(1/3)."""
    from cornell_harness.gate.checks import STATISTICAL_TESTS, statistical_alpha

    assert STATISTICAL_TESTS == ("agreement", "variance", "outliers")
    share = statistical_alpha(0.01)
    assert 1 - (1 - share) ** 3 == pytest.approx(0.01)
    out = run_gate(load_config(_config(tmp_path, _unbiased("tests.user_renderers:ScaledMitsubaNoise", spp=64))))[0]
    assert out.agreement.alpha == pytest.approx(share)
    # The scene's named regions are agreement tests too (3 channels each), in the same Šidák family.
    assert set(out.agreement.z_regions) == {"walls", "boxes", "floor", "light", "back-edge"}
    assert out.agreement.tests == out.agreement.z_tiles.size + 3 + 3 * 5
    assert "15 on 5 regions" in out.checks[1].message
    names = [c.name for c in out.checks]
    assert names[:4] == ["finite", "agreement", "variance", "outliers"]
    assert all("α = 0.01 per expectation, Šidák-split over agreement, variance, outliers: 0.00334 each" in c.message
               for c in out.checks if c.name in STATISTICAL_TESTS)


def test_variance_check_false_alarm_rate_is_at_most_alpha():
    """Pure normal noise of exactly the stated variance, tolerance 0 (the boundary of the null): ≤ α rejections.

    With δ = 0 and spp = 10¹² the interval is [1, 1 + 10⁻⁶]: at its lower end
    P(|z| < Φ⁻¹(3/4)) = 1/2 exactly, the worst case of the interval
    hypothesis; Hoeffding's bound makes each side's rate ≤ α/2. With
    α = 0.2 over 200 trials a correct test rejects at most Binomial(200, 0.2)
    times (mean 40); the assertion ≤ 60 fails with probability < 1e-3
    (Hoeffding is conservative: the real rate is far below α).
    """
    from cornell_harness.evaluate.variance_check import variance_check

    rng = np.random.default_rng(3)
    ref = np.full((32, 32, 3), 0.5)
    var = np.full_like(ref, 1e-3)
    rejections = sum(not variance_check(ref + np.sqrt(2e-3) * rng.standard_normal(ref.shape), var, ref, var, 10**12,
                                        alpha=0.2, tolerance=0.0).passed for _ in range(200))
    assert rejections <= 60, rejections


@pytest.mark.parametrize("factor, seed", [(100.0, 0), (100.0, 1), (10.0, 0), (10.0, 1)])
def test_variance_check_rejects_bias_hidden_by_overstated_variance(tmp_path, factor, seed):
    """1% too dark and reporting 10× or 100× its variance, on cornell-box at 256 spp: the variance check fails.

    Its z-scores have spread 1/√F (0.33, 0.10): 93-99.5% of |z| fall below
    the lower cut Φ⁻¹(3/4)/1.1, where a renderer within the tolerance has at
    most 50% + 0.7% (α/3 = 0.00334, N = 61504 pixels); by Hoeffding the
    check misses it with probability < exp(−2N·0.4²) ≈ 0 at any seed. At
    100× the agreement test's tiles and whole image pass it (issue 9); its
    region tests (issue 29) catch it on the light's region alone, emission
    seen directly, where the noise is nearly nothing even at 100×.
    """
    checks = _checks(tmp_path, _unbiased("tests.user_renderers:LyingVariance", f"variance_factor = {factor}", seed=seed))
    v = checks[(str(seed), "variance")]
    assert not v.passed and v.value == pytest.approx(1 / np.sqrt(factor), rel=0.1)
    assert "reports more variance than its residuals show" in v.message and "× too much" in v.message
    if factor == 100.0:  # what the variance check is for: no tile and not the whole image see the bias
        agr = checks[(str(seed), "agreement")]
        assert agr.passed or re.fullmatch(r"3 of \d+ tests reject .*; worst: region light [^;]*; region light [^;]*; "
                                          r"region light [^;]* \[α = .*", agr.message), agr.message


@pytest.mark.parametrize("renderer, settings", [("tests.user_renderers:ScaledMitsubaNoise", ""),
                                                ("tests.user_renderers:LyingVariance", "scale = 1.0, variance_factor = 1.0")])
def test_variance_check_passes_a_correct_variance(tmp_path, renderer, settings):
    """Noise of exactly the reported variance passes, seeds 0-2 at 256 spp.

    Overstatement: a renderer within the tolerance fails with probability
    ≤ α/6 = 0.00167 per run; these have spread ≈ 0.99 (the tolerance at
    256 spp is [0.909, 1.163]), so their fraction of |z| below the lower cut
    is ≈ 0.46 against a limit of 0.507 (N = 61504 pixels): Hoeffding puts
    each run's false-alarm probability below exp(−2N·0.043²) < 1e-90.
    Understatement: Σd²/Σv is 0.95-1.12 (the model's noise is heavy-tailed, so the sum of squares spreads),
    where the test's H₀ allows up to √2: its t is −3.6 or below against a critical value of +2.9.
    """
    body = "".join(_unbiased(renderer, settings, seed=s) for s in range(3))
    checks = _checks(tmp_path, body)
    for s in range(3):
        v = checks[(str(s), "variance")]
        assert v.passed and 0.95 < v.value < 1.05, v.message
        ratio = float(v.message.split("Σd²/Σv = ")[1].split(" ")[0])
        assert 0.85 < ratio < 1.2, v.message


def test_variance_check_names_a_bias_that_outweighs_the_noise(tmp_path):
    """1% too dark with a correct variance (seed 0, 256 spp): ŝ is right, so nothing is overstated, but the
    residuals' sum of squares carries the bias squared (the light, bright and nearly noiseless, dominates it):
    Σd²/Σv ≈ 1.7, which the understatement test cannot tell from a variance 1.7× too small, and says so."""
    checks = _checks(tmp_path, _unbiased("tests.user_renderers:Biased1Percent", "", seed=0))
    v = checks[("0", "variance")]
    assert 0.95 < v.value < 1.05, v.message
    assert not v.passed and "too little" in v.message and "or it is biased" in v.message, v.message
    assert not checks[("0", "agreement")].passed  # the bias is the agreement test's failure first


def test_variance_check_skipped_without_a_reported_variance():
    """A renderer that reports no variance is tested with the reference's noise model: nothing of its own to check."""
    from cornell_harness.adapters.registry import resolve
    from cornell_harness.evaluate import metrics
    from cornell_harness.scenes.library import resolve_scene
    from cornell_harness.store.references import load_reference
    from cornell_harness.workflows.runner import RunRecord

    cfg = load_config(ROOT / "gate.toml")
    exp = next(e for e in cfg.expectations if e.unbiased and e.scene == "cornell-box")
    scene = resolve_scene("cornell-box")
    ref = load_reference(scene)
    (entry,) = resolve(["tests.user_renderers:FlatGrey"])
    rec = RunRecord.new(scene, entry, 256, 0, time_s=1.0, image=ref.image.copy(),
                        metrics=metrics.image_metrics(ref.image, ref.image))
    v = next(c for c in evaluate(exp, rec, ref, cfg).checks if c.name == "variance")
    assert v.passed and v.message.startswith("skipped: the renderer reports no variance")


@pytest.mark.parametrize("x, y, seed", [(20, 128, 0), (20, 128, 1), (69, 150, 0), (236, 128, 2)])
def test_outlier_check_catches_one_pixel_twice_as_bright(tmp_path, x, y, seed):
    """One pixel ×2 on cornell-box at 256 spp (red wall, tall box's edge, green wall): the outlier check fails there.

    Those pixels sit at z ≈ 37, 22 and 31 (median of the channels' z with
    the reference's variance) against a threshold of 11.4 (the noise batch's
    Pareto tail, family-wise α/3 = 0.00334 over 65536 pixels); the pixel's
    noise is doubled too (sd 2 on z), so a seed misses them with probability
    < Φ(−5.3) ≈ 6e-8. The tiled agreement test does not see them (their
    16×16 tile moves by z ≈ 1.6-2.8).
    """
    settings = f"x = {x}, y = {y}, factor = 2.0"
    c = _checks(tmp_path, _unbiased("tests.user_renderers:HotPixel", settings, seed=seed))
    o = c[(str(seed), "outliers")]
    assert not o.passed and o.value > o.limit > 5
    assert "1 outlier pixel(s) of 65536" in o.message and f"worst: pixel x {x}, y {y}, channels R, G, B" in o.message
    assert "render/reference R " in o.message


def test_outlier_check_passes_clean_renders(tmp_path):
    """The same renderer without the hot pixel (factor 1), seeds 0-3: no outlier.

    Each run is a false alarm with probability ≤ α/3 = 0.00334 (union bound
    over the pixels with the tail fitted to the reference's noise batch); the
    largest |z| of these normal-noise images is about 3-4, far below the
    threshold 11.4.
    """
    body = "".join(_unbiased("tests.user_renderers:HotPixel", "factor = 1.0", seed=s) for s in range(4))
    checks = _checks(tmp_path, body)
    for s in range(4):
        o = checks[(str(s), "outliers")]
        assert o.passed and o.value < 5.0 < o.limit, o.message
        assert "no outlier pixel" in o.message


def test_outlier_test_threshold_and_where():
    """Synthetic: normal noise batch (threshold near the normal one), a hot pixel and a NaN variance are found."""
    from cornell_harness.evaluate.outliers import outlier_test

    rng = np.random.default_rng(5)
    ref = np.full((64, 64, 3), 0.5)
    var_ref = np.full_like(ref, 1e-6)  # of a reference of 1024 spp: per-sample variance 1.024e-3
    noise = ref + np.sqrt(var_ref * (1024 / 128 + 1)) * rng.standard_normal(ref.shape)
    img = ref + np.sqrt(var_ref * (1024 / 256 + 1)) * rng.standard_normal(ref.shape)
    clean = outlier_test(img, None, ref, var_ref, noise, 1024, 128, 256, alpha=0.01)
    assert clean.passed and 4.5 < clean.threshold.value < 9.0
    img[7, 11] *= 1.01  # +0.005 against an sd of 0.0022: z ≈ 2.2, within the noise
    img[40, 3] *= 1.05  # z ≈ 11
    var = np.full_like(ref, 4e-6)
    var[12, 30, 2] = np.nan
    o = outlier_test(img, var, ref, var_ref, noise, 1024, 128, 256, alpha=0.01)
    where = [(f["x"], f["y"]) for f in o.failures]
    assert not o.passed and where[0] in ((30, 12), (3, 40)) and set(where) == {(30, 12), (3, 40)}
    assert "pixel x 3, y 40, channels R, G, B" in o.message()
