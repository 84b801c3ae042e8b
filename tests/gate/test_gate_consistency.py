"""The gate for biased-but-consistent renderers (issue 11): the estimator declaration against the z-tests,
consistency checks (a slope over checkpoints, a ratio to a smaller budget) and budgets on region metrics.

Split from tests/gate/test_gate.py, whose helpers it uses, to keep each module near 500 lines.
"""

from __future__ import annotations


import numpy as np
import pytest

from cornell_harness.gate.checks import evaluate
from cornell_harness.gate.config import load_config
from cornell_harness.gate.run import run_gate
from tests.gate.test_gate import _config, config_error


def _expect(extra: str, renderer: str = "x", spp: int = 64, scene: str = "cornell-box") -> str:
    return f'[[expect]]\nscene = "{scene}"\nrenderer = "{renderer}"\nspp = {spp}\n' + extra


@pytest.mark.parametrize("extra, field, words", [
    ('consistency = { metric = "msee", slope = [-1.0, -0.5] }\n', "expect[0].consistency.metric: msee",
     "did you mean 'mse'"),
    ('consistency = { metric = "ssim", slope = [-1.0, -0.5] }\n', "expect[0].consistency.metric", "higher-is-better"),
    ('consistency = { metric = "region.caustic.rel_mes", slope = [-1.0, -0.5] }\n',
     "expect[0].consistency.metric: region.caustic.rel_mes", "did you mean 'region.caustic.rel_mse'"),
    ('consistency = { slop = [-1.0, -0.5] }\n', "expect[0].consistency.slop", "did you mean 'slope'"),
    ("consistency = 3\n", "expect[0].consistency", "expected a table"),
    ("consistency = { }\n", "expect[0].consistency", "exactly one of slope"),
    ("consistency = { slope = [-1.0, -0.5], max_ratio = 0.5, smaller = { spp = 2 } }\n", "expect[0].consistency",
     "exactly one of slope"),
    ("consistency = { slope = [-0.5, -1.0] }\n", "expect[0].consistency.slope", "low < high"),
    ("consistency = { slope = [-1.0, -0.5], from_spp = 64 }\n", "expect[0].consistency.from_spp", "below spp"),
    ("consistency = { slope = [-1.0, -0.5], smaller = { spp = 2 } }\n", "expect[0].consistency.smaller",
     "goes with max_ratio"),
    ("consistency = { max_ratio = 0.5 }\n", "expect[0].consistency.smaller", "max_ratio needs smaller"),
    ("consistency = { max_ratio = 1.5, smaller = { spp = 2 } }\n", "expect[0].consistency.max_ratio", "(0, 1]"),
    ("consistency = { max_ratio = 0.5, smaller = { spp = 64 } }\n", "expect[0].consistency.smaller",
     "must lower the budget"),
    ("consistency = { max_ratio = 0.5, smaller = { spp = 128 } }\n", "expect[0].consistency.smaller.spp",
     "at most spp"),
    ('max = { "region.caustic.pixels" = 3 }\n', "expect[0].max.region.caustic.pixels", "unknown region metric"),
    ('min = { "region..rmse" = 3 }\n', "expect[0].min.region..rmse", "region.<region>.<metric>"),
])
def test_consistency_and_region_budget_config_errors(tmp_path, extra, field, words):
    path = _config(tmp_path, _expect(extra), head="")
    with config_error(path, field, words):
        load_config(path)


def test_consistency_config_forms(tmp_path):
    """Both forms parse; a consistency table alone is an accuracy check; a region budget keeps its quoted key."""
    body = (_expect('consistency = { metric = "region.caustic.rel_mse", slope = [-0.9, -0.4] }\n'
                    'max = { "region.caustic.rel_mse" = 0.05 }\n', spp=256) +
            _expect("name = \"ratio\"\nconsistency = { max_ratio = 0.6, smaller = { spp = 16, "
                    "global_photons = 50000 } }\n"))
    slope, ratio = load_config(_config(tmp_path, body, head="")).expectations
    c = slope.consistency
    assert (c.metric, c.slope, c.max_ratio, c.first_spp(256), c.first_spp(8)) == \
        ("region.caustic.rel_mse", (-0.9, -0.4), None, 16, 1)
    assert slope.max == {"region.caustic.rel_mse": 0.05}
    assert slope.region_metrics() == [("max.region.caustic.rel_mse", "region.caustic.rel_mse"),
                                      ("consistency.metric", "region.caustic.rel_mse")]
    c = ratio.consistency
    assert (c.metric, c.slope, c.max_ratio, c.smaller_spp, c.smaller_settings) == \
        ("mse", None, 0.6, 16, {"global_photons": 50000})


def _synthetic(bias_at, spps=(4, 8, 16, 32, 64), size=16):
    """A hand-built run on a 16² synthetic reference: the image at each spp is the reference plus ``bias_at(spp)``
    on the left half (region "left") and exact on the right half (region "right")."""
    from cornell_harness.adapters.api import Checkpoint
    from cornell_harness.evaluate import metrics
    from cornell_harness.store.references import Reference
    from cornell_harness.workflows.runner import RunRecord

    rng = np.random.default_rng(7)
    ref_img = rng.uniform(0.2, 0.8, (size, size, 3))
    var = np.full_like(ref_img, 1e-8)
    ref = Reference(ref_img, var, ref_img, {"spp": 4096, "noise_spp": 64}, None)
    left = np.zeros((size, size), bool)
    left[:, : size // 2] = True
    masks = {"left": left, "right": ~left}

    def image(spp):
        img = ref_img.copy()
        img[left] += bias_at(spp)
        return img

    top = spps[-1]
    rec = RunRecord("synthetic", "r", "ok", top, 0, image=image(top),
                    metrics=metrics.image_metrics(image(top), ref_img),
                    checkpoints=[Checkpoint(s, image(s), 0.0) for s in spps[:-1]])
    return rec, ref, masks


def test_consistency_slope_passes_a_converging_run_and_fails_a_stuck_one(tmp_path):
    """MSE ∝ spp^-0.7 (bias 0.1·spp^-0.35) lies in [-0.9, -0.4]; a bias that stays (photon mapping at fixed photon
    counts, seen as spp grows) has slope 0 and fails. The slope is fitted from from_spp (default spp/16) to spp."""
    cfg = load_config(_config(tmp_path, _expect("consistency = { slope = [-0.9, -0.4] }\n") + _expect(
        'name = "left"\nconsistency = { metric = "region.left.rel_mse", slope = [-0.9, -0.4], from_spp = 8 }\n')))
    whole, region = cfg.expectations
    rec, ref, masks = _synthetic(lambda s: 0.1 * s ** -0.35)
    c = next(c for c in evaluate(whole, rec, ref, cfg).checks if c.name == "consistency.mse")
    assert c.passed and c.value == pytest.approx(-0.7, abs=1e-6)
    assert "mse-vs-spp slope -0.700 over spp 4..64" in c.message and "expected in [-0.9, -0.4]" in c.message
    c = next(c for c in evaluate(region, rec, ref, cfg, masks=masks).checks
             if c.name == "consistency.region.left.rel_mse")
    assert c.passed and "over spp 8..64" in c.message
    stuck, ref, masks = _synthetic(lambda s: 0.05)
    for exp, kw in ((whole, {}), (region, {"masks": masks})):
        c = next(c for c in evaluate(exp, stuck, ref, cfg, **kw).checks if c.name.startswith("consistency."))
        assert not c.passed and c.value == pytest.approx(0.0, abs=1e-6)


def test_consistency_slope_needs_checkpoints(tmp_path):
    cfg = load_config(_config(tmp_path, _expect("consistency = { slope = [-0.9, -0.4] }\n")))
    rec, ref, _ = _synthetic(lambda s: 0.1 / s, spps=(64,))
    (c,) = [c for c in evaluate(cfg.expectations[0], rec, ref, cfg).checks if c.name == "consistency.mse"]
    assert not c.passed and "needs a progressive renderer" in c.message


def test_region_budgets_read_the_run_regions(tmp_path):
    """``max = { "region.left.rmse" = … }`` is checked against rec.regions, image-wide metrics against rec.metrics."""
    cfg = load_config(_config(tmp_path, _expect('max = { "region.left.rmse" = 0.06, "region.right.rmse" = 1e-9 }\n'
                                                "abs_max = { mean_radiance_rel_error = 10.0 }\n")))
    rec, _, _ = _synthetic(lambda s: 0.05)
    rec.regions = {"left": {"rmse": 0.05}, "right": {"rmse": 0.0}}
    checks = {c.name: c for c in evaluate(cfg.expectations[0], rec, None, cfg).checks}
    assert checks["max.region.left.rmse"].passed and checks["max.region.left.rmse"].value == 0.05
    assert checks["max.region.right.rmse"].passed and checks["abs_max.mean_radiance_rel_error"].passed
    rec.regions["left"]["rmse"] = 0.07
    bad = next(c for c in evaluate(cfg.expectations[0], rec, None, cfg).checks if c.name == "max.region.left.rmse")
    assert not bad.passed and "region.left.rmse = 0.07, budget ≤ 0.06" in bad.message


@pytest.mark.parametrize("extra, renderer, field, words", [
    ('max = { "region.caustic.rmse" = 0.1 }\n', "tests.user_renderers:ShrinkingBias", "expect[0].max.region.caustic.rmse",
     "scene 'cornell-box' has no region 'caustic'; its regions: walls, boxes, floor, light, back-edge"),
    ('consistency = { metric = "region.caustic.rmse", slope = [-1.0, -0.5] }\n', "tests.user_renderers:ShrinkingBias",
     "expect[0].consistency.metric", "has no region 'caustic'"),
    ("consistency = { max_ratio = 0.5, smaller = { photns = 10 } }\n", "tests.user_renderers:ShrinkingBias",
     "expect[0].consistency.smaller.photns", "unknown setting 'photns' (did you mean 'photons'?)"),
    ("consistency = { max_ratio = 0.5, smaller = { photons = 0 } }\n", "tests.user_renderers:ShrinkingBias",
     "expect[0].consistency.smaller.photons", "setting photons=0"),
    ("unbiased = true\n", "tests.user_renderers:ShrinkingBias", "expect[0].unbiased",
     "declares estimator = 'consistent': the agreement, variance and outlier tests assume an unbiased estimator"),
])
def test_resolve_refuses_before_rendering(tmp_path, extra, renderer, field, words):
    """Missing regions, bad smaller-budget settings and z-tests for a consistent renderer: config errors, exit 2,
    found before the first expectation renders (the first one here would count a render)."""
    from tests.user_renderers import FlatGrey

    FlatGrey.calls = 0
    body = _expect("finite_only = true\n", "tests.user_renderers:FlatGrey") + _expect(extra, renderer)
    path = _config(tmp_path, body)
    with config_error(path, field.replace("[0]", "[1]"), words):
        run_gate(load_config(path), sandbox=False)
    assert FlatGrey.calls == 0


def test_consistency_ratio_renders_the_smaller_budget(tmp_path):
    """max_ratio through run_gate: fewer photons is a smaller budget (MSE ∝ 1/photons: 100 against 400 is a ratio
    of 1/4, within 0.5); fewer spp at the same photons is not (ratio 1: the bias stays), and fails. A region budget
    reads the run's regions (the floor's mean is off by 1/√400 = 5%)."""
    shrink = "tests.user_renderers:ShrinkingBias"
    body = (_expect('name = "photons"\nsettings = { photons = 400 }\nconsistency = { max_ratio = 0.5, '
                    'smaller = { spp = 4, photons = 100 } }\nabs_max = { "region.floor.mean_radiance_rel_error" = '
                    "0.06 }\n", shrink, spp=8) +
            _expect('name = "spp"\nsettings = { photons = 400 }\nconsistency = { max_ratio = 0.5, '
                    "smaller = { spp = 4 } }\n", shrink, spp=8))
    photons, spp = run_gate(load_config(_config(tmp_path, body)), sandbox=False)
    c = next(c for c in photons.checks if c.name == "consistency.mse")
    assert c.passed and c.value == pytest.approx(0.25, rel=1e-3) and c.limit == 0.5
    assert "at spp 8, photons=400 against" in c.message and "at spp 4, photons=100: ratio 0.250, limit ≤ 0.5" \
        in c.message
    floor = next(c for c in photons.checks if c.name == "abs_max.region.floor.mean_radiance_rel_error")
    assert floor.passed and floor.value == pytest.approx(0.05, rel=1e-3)
    c = next(c for c in spp.checks if c.name == "consistency.mse")
    assert not c.passed and c.value == pytest.approx(1.0) and "at spp 4: ratio 1.000" in c.message
    assert spp.record.row()["estimator"] == "consistent"
