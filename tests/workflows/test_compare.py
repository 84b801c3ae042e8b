"""Equal-time comparisons with repeated timings: the spp a budget buys with its interval, calibration and
repeats interleaved over the renderers, the timing columns, and the CPU time basis. No verdict here reads
the wall clock: the renderers report clocks of their own (tests.user_renderers.Clocked, Jittery)."""

from __future__ import annotations

import json
import math

import pytest

from cornell_harness.adapters.api import RenderResult
from cornell_harness.adapters.registry import resolve
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.workflows import compare as cmp
from cornell_harness.workflows import runner
from cornell_harness.workflows.timing import Timing
from tests.user_renderers import Jittery, JitteryToo, Unrepeatable

#: Jittery's clock: Clocked's (0.25 s + 1/16 s per spp) times 1, 1.25 and 0.8 by turns of two renders.
OVERHEAD, PER_SPP = 0.25, 0.0625


@pytest.fixture
def scene():
    return resolve_scene("cornell-box").with_resolution(8, 8)


@pytest.fixture
def log(tmp_path, monkeypatch):
    """The order renders ran in, "NAME SPP SEED" per line (Jittery writes it), counts reset."""
    path = tmp_path / "renders.log"
    monkeypatch.setenv("CBOX_TEST_RENDER_LOG", str(path))
    Jittery.calls = JitteryToo.calls = Unrepeatable.calls = 0
    return lambda: [tuple(line.split()[:2]) for line in path.read_text().splitlines()] if path.exists() else []


def _times(factor: float, spp: int) -> float:
    return factor * (OVERHEAD + PER_SPP * spp)


def test_budget_choice_gives_the_spp_of_the_medians_and_an_interval_from_the_rounds():
    """Three rounds at clock factors 1, 1.25 and 0.8: the median times buy (2 - 0.25) / (1/16) = 28 spp; the
    rounds alone would buy 28, 21.6 and 36, whose interval (Student-t on log, K = 3) is wider than their range."""
    factors = (1.0, 1.25, 0.8)
    choice = cmp.budget_choice([_times(f, 1) for f in factors], [_times(f, 4) for f in factors], 2.0)
    assert choice.spp == 28 and choice.basis == "wall"
    assert choice.samples == pytest.approx([28.0, 21.6, 36.0])
    assert choice.spp_low <= 21 and choice.spp_high >= 36
    one = cmp.budget_choice([_times(1.0, 1)], [_times(1.0, 4)], 2.0)
    assert (one.spp, one.spp_low, one.spp_high) == (28, None, None)


def test_calibration_rounds_are_interleaved_over_the_renderers(scene, log):
    """K rounds of (1 spp, 4 spp) per renderer run as A B A B ..., never A A A B B B: load that changes during
    calibration then hits both alike. Jittery's clock spreads over the rounds, so its spp gets an interval.
    28 spp need no probe (28 // 8 is not above 4); the progress still counts three per round and renderer, as
    Comparison.renders does."""
    entries = resolve(["tests.user_renderers:Jittery", "tests.user_renderers:JitteryToo"])
    labels = []
    choices = cmp.calibrate_time_budget(entries, scene, 2.0, 0, repeats=3, on_render=labels.append)
    round_ = [("jittery", "1"), ("jittery", "4"), ("jittery-too", "1"), ("jittery-too", "4")]
    assert log() == round_ * 3
    assert len(labels) == 3 * 3 * 2 and sum("probe not needed" in label for label in labels) == 3 * 2
    for choice in choices:
        assert choice.spp == 28 and choice.fit_spp == (1, 4) and choice.spp_low <= 21 and choice.spp_high >= 36


def test_the_probe_rounds_follow_the_first_ones_interleaved_and_the_line_through_4_spp_and_the_probe_decides(
        scene, log):
    """8 s buy Clocked's (8 - 0.25) / (1/16) = 124 spp by the 1- and 4-spp renders; the probe then renders 124 // 8
    = 15 spp, in rounds interleaved over the renderers after the first ones, and the line through the median
    4-spp and 15-spp times (Clocked's own, exact) buys the same 124. Jittery's clock (1, 1, 1.25 on the probe
    rounds) spreads what each round buys around it."""
    entries = resolve(["tests.user_renderers:Jittery", "tests.user_renderers:JitteryToo"])
    choices = cmp.calibrate_time_budget(entries, scene, 8.0, 0, repeats=3)
    first = [("jittery", "1"), ("jittery", "4"), ("jittery-too", "1"), ("jittery-too", "4")]
    assert log() == first * 3 + [("jittery", "15"), ("jittery-too", "15")] * 3
    for choice in choices:
        assert (choice.spp, choice.fit_spp) == (124, (4, 15)) and choice.spp_low < 124 < choice.spp_high, choice
    info = {}
    choices[0].record_in(info, 8.0)
    assert info["time_budget_fit_spp"] == [4, 15]


def _cpu_clocked(cpu_of_spp):
    """A stand-in for the render path whose CPU time is ``cpu_of_spp(spp)``, exactly; its wall time is three
    times that and a second more (a budget spent in wall seconds would buy far fewer samples)."""
    import numpy as np

    def render(entry, scene, spp, seed, checkpoints=(), stop=None):
        image = np.full((scene.camera.height, scene.camera.width, 3), 0.5, np.float32)
        cpu = cpu_of_spp(spp)
        result = RenderResult(image, 1.0 + 3.0 * cpu, spp, seed)
        result.cpu_time_s = cpu
        return result
    return render


def test_a_cpu_budget_of_a_renderer_with_a_fixed_cost_lands_within_it(scene, monkeypatch):
    """CPU time 0.5 s + 1/16 s per spp (photon tracing inside the clock, then the camera pass), reported
    exactly: 10 CPU seconds buy (10 - 0.5) · 16 = 152 spp, whose render takes the budget to the sample;
    the probe was 152 // 8 = 19 spp."""
    (entry,) = resolve(["tests.user_renderers:Jittery"])
    monkeypatch.setattr(runner, "render_checked", _cpu_clocked(lambda spp: 0.5 + 0.0625 * spp))
    (choice,) = cmp.calibrate_time_budget([entry], scene, 10.0, 0, repeats=3, basis="cpu")
    assert (choice.spp, choice.fit_spp, choice.basis) == (152, (4, 19), "cpu")
    assert choice.spp_low == choice.spp_high == 152
    assert 10.0 - 0.0625 < 0.5 + 0.0625 * choice.spp <= 10.0


def _passes(spp: int) -> int:
    """Passes of doubling size (1, 1, 2, 4, ...) a render of ``spp`` samples takes."""
    return 1 + max(0, math.ceil(math.log2(spp)))


def test_a_cost_not_yet_linear_at_4_spp_is_extrapolated_from_the_probe(scene, monkeypatch):
    """A fixed cost per pass of doubling size (20 ms; Mitsuba renders so) on top of 30 ms per spp: a 1- or
    4-spp render is mostly pass cost, so the line through them alone (43 ms per spp) would buy 230 spp,
    7.1 s of a 10 s budget (-29%); through 4 spp and the probe it lands within 10% of the budget, below it."""
    def cpu(spp):
        return 0.02 * _passes(spp) + 0.03 * spp

    (entry,) = resolve(["tests.user_renderers:Jittery"])
    monkeypatch.setattr(runner, "render_checked", _cpu_clocked(cpu))
    (choice,) = cmp.calibrate_time_budget([entry], scene, 10.0, 0, repeats=1, basis="cpu")
    without_probe = int(cmp.spp_for_calibration(cpu(1), cpu(4), 10.0))
    assert without_probe == 230 and cpu(without_probe) < 0.75 * 10.0
    assert choice.fit_spp == (4, without_probe // 8) and 0.9 * 10.0 <= cpu(choice.spp) <= 10.0


def test_calibration_failure_is_that_renderers_alone(scene, log):
    entries = resolve(["tests.user_renderers:Crashes", "tests.user_renderers:Jittery"])
    crashed, choice = cmp.calibrate_time_budget(entries, scene, 2.0, 0, repeats=3)
    assert isinstance(crashed, RuntimeError) and choice.spp == 28
    assert log() == [("jittery", "1"), ("jittery", "4")] * 3


def test_repeats_are_interleaved_and_give_the_median_with_its_interval(scene, log):
    """retime: K timings per record in rounds over the renderers; time_s is their median, the row carries
    K, the interval and the raw timings; the same seed gives the same image, so nothing is counted as
    differing."""
    entries = resolve(["tests.user_renderers:Jittery", "tests.user_renderers:JitteryToo"])
    records = [runner.run_one(e, scene, 16, 0, None) for e in entries]
    first_images = [r.image.copy() for r in records]
    cmp.retime(entries, records, scene, 3)
    assert log() == [("jittery", "16"), ("jittery-too", "16")] * 3
    clock = OVERHEAD + PER_SPP * 16  # 1.25 s; Jittery's calls 0, 1, 2 read factors 1, 1, 1.25
    for rec, image in zip(records, first_images):
        row = rec.row()
        samples = json.loads(row["time_samples_s"])
        assert samples == pytest.approx([clock, clock, 1.25 * clock])
        assert row["time_repeats"] == 3 and row["time_s"] == pytest.approx(clock, abs=1e-4)
        assert row["time_s_low"] <= row["time_s"] <= row["time_s_high"] and row["time_s_high"] > 1.25 * clock
        assert "info_repeat_images_differ" not in row and (rec.image == image).all()


def test_one_timing_keeps_the_contract_of_a_row_without_repeats(scene, log):
    entries = resolve(["tests.user_renderers:Jittery"])
    records = [runner.run_one(entries[0], scene, 4, 0, None)]
    cmp.retime(entries, records, scene, 1)
    row = records[0].row()
    assert log() == [("jittery", "4")]
    assert row["time_repeats"] == 1 and math.isnan(row["time_s_low"]) and math.isnan(row["time_s_high"])
    assert json.loads(row["time_samples_s"]) == [row["time_s"]]


def test_a_repeat_whose_image_differs_is_counted_and_the_first_kept(scene, log):
    (entry,) = resolve(["tests.user_renderers:Unrepeatable"])
    rec = runner.run_one(entry, scene, 4, 0, None)
    first = rec.image.copy()
    cmp.retime([entry], [rec], scene, 3)
    assert rec.info["repeat_images_differ"] == 2 and (rec.image == first).all()
    assert rec.row()["time_repeats"] == 3


def test_skipped_and_failed_records_are_not_repeated(scene, log):
    entries = resolve(["tests.user_renderers:Crashes", "tests.user_renderers:Jittery"])
    records = [runner.run_one(e, scene, 4, 0, None) for e in entries]
    cmp.retime(entries, records, scene, 2)
    assert records[0].status == "failed" and records[0].row()["time_repeats"] == 0
    assert log() == [("jittery", "4")] * 2


def _fake_render(wall_per_spp: float, cpu_per_spp: float | None):
    """A stand-in for the render path that records CPU time (as the capture of issue 30 adds it)."""
    import numpy as np

    def render(entry, scene, spp, seed, checkpoints=(), stop=None):
        image = np.full((scene.camera.height, scene.camera.width, 3), 0.5, np.float32)
        result = RenderResult(image, OVERHEAD + wall_per_spp * spp, spp, seed)
        if cpu_per_spp is not None:
            result.cpu_time_s = OVERHEAD + cpu_per_spp * spp
        return result
    return render


def test_cpu_basis_spends_the_budget_in_cpu_seconds(scene, monkeypatch):
    """With --time-basis cpu the calibration reads CPU time: a render whose CPU time per sample is half its
    wall time (two threads, say) buys twice the samples of a CPU budget; without CPU times it falls back to
    the whole call's CPU time."""
    (entry,) = resolve(["tests.user_renderers:Jittery"])
    monkeypatch.setattr(runner, "render_checked", _fake_render(PER_SPP, PER_SPP / 2))
    (wall,) = cmp.calibrate_time_budget([entry], scene, 2.0, 0, repeats=2, basis="wall")
    (cpu,) = cmp.calibrate_time_budget([entry], scene, 2.0, 0, repeats=2, basis="cpu")
    assert (wall.spp, wall.basis) == (28, "wall") and (cpu.spp, cpu.basis) == (56, "cpu")
    # A renderer that measures no CPU time of its own: the whole call's (runner.cpu_time), here a quarter of
    # its wall time, stands in; never wall time under the CPU name.
    monkeypatch.setattr(runner, "render_checked", _fake_render(PER_SPP, None))
    monkeypatch.setattr(runner, "measure", lambda call: ((r := call()), Timing(r.time_s, r.time_s / 4, 1.0, 1.0, 0.02)))
    (fallback,) = cmp.calibrate_time_budget([entry], scene, 2.0, 0, repeats=2, basis="cpu")
    assert fallback.basis == "cpu" and fallback.spp > 3 * wall.spp


@pytest.mark.parametrize("foreign, basis, spp", [(0.0, "wall", 28), (2.0, "cpu", 56)])
def test_auto_basis_is_cpu_when_other_work_took_cores_during_calibration(scene, monkeypatch, foreign, basis, spp):
    """--time-basis auto: the calibration renders' foreign CPU decides, every renderer alike. 2 cores of other
    processes' CPU beside a render of one thread on 2 cores (2 + 1 > 2.5) is contention: the budget becomes
    CPU seconds (twice the samples here: CPU per sample is half the wall); none leaves it in wall seconds."""
    entries = resolve(["tests.user_renderers:Jittery", "tests.user_renderers:FlatGrey"])
    monkeypatch.setattr(runner, "render_checked", _fake_render(PER_SPP, PER_SPP / 2))
    monkeypatch.setattr(runner, "threads_of", lambda info: 1)
    monkeypatch.setattr(cmp, "machine_cores", lambda: 2)
    monkeypatch.setattr(runner, "measure", lambda call: ((r := call()), Timing(r.time_s, r.cpu_time_s, 1.0, 1.0,
                                                                                0.02, foreign)))
    choices = cmp.calibrate_time_budget(entries, scene, 2.0, 0, repeats=2, basis="auto")
    assert [(c.spp, c.basis) for c in choices] == [(spp, basis)] * 2


def test_repeats_carry_cpu_time_when_the_render_path_records_it(scene, monkeypatch):
    (entry,) = resolve(["tests.user_renderers:Jittery"])
    rec = runner.run_one(entry, scene, 16, 0, None)
    rec.cpu_time_s = 0.5  # the first render's, as a RunRecord with the capture's columns holds it
    monkeypatch.setattr(runner, "render_checked", _fake_render(PER_SPP, PER_SPP / 4))
    cmp.retime([entry], [rec], scene, 3)
    row = rec.row()
    assert json.loads(row["cpu_time_samples_s"]) == [0.5, 0.5, 0.5]
    assert rec.cpu_time_s == 0.5 and row["cpu_time_s_low"] == row["cpu_time_s_high"] == 0.5


def test_an_unbiased_run_gets_the_gates_agreement_verdict():
    """judge_agreement gives an unbiased render the gate's agreement test (family-wise α = 0.01 at seed 0): the
    reference plus its own noise passes; the same 1% dark (Biased1Percent: ~30 sd on the whole image at 64 spp)
    fails; a renderer that declares another estimator gets no verdict."""
    from cornell_harness.store.references import load_reference

    scene = resolve_scene("cornell-box")
    ref = load_reference(scene)
    fair, dark, consistent = resolve(["tests.user_renderers:ScaledMitsubaNoise", "tests.user_renderers:Biased1Percent",
                                      "tests.user_renderers:ShrinkingBias"])
    ok, bad, other = (runner.run_one(e, scene, 64, 0, ref) for e in (fair, dark, consistent))
    for rec in (ok, bad, other):
        cmp.judge_agreement(rec, scene, ref)
    assert ok.row()["agreement"] == "pass" and ok.agreement_p_min > 1e-5
    assert bad.row()["agreement"] == "fail" and bad.agreement_p_min < 1e-9
    assert "agreement" not in other.row()
