"""cbox sequence's workflow: every frame scored by the one scorer, the temporal figures per (renderer, seed), a
stateful renderer lagging and flickering less than a stateless one, failures as rows, results written."""

from __future__ import annotations

import json
import math

import pandas as pd
import pytest

from cornell_harness.adapters.registry import resolve
from cornell_harness.evaluate.score import score_image
from cornell_harness.reports.sequence import lag_flicker_plot, write_sequence_report
from cornell_harness.workflows.sequence_run import run_sequence, scene_motion, write_sequence_results
from tests.sequence_fakes import moving_light, references


def entries(*specs):
    return resolve([f"tests.sequence_fakes:{s}" for s in specs])


@pytest.fixture(scope="module")
def scene():
    return moving_light(frames=18, stop=5, size=12)


def test_scene_motion_finds_the_stop_and_the_floor(scene):
    refs = references(scene)
    motion = scene_motion(scene, list(range(18)), refs)
    assert motion.change == 5  # the light's last move; frames 12-17 are the steady ones
    assert motion.floor == pytest.approx(math.sqrt(4e-6))
    assert motion.masks.shape == (18, 12, 12) and not motion.masks[6:].any()


def test_frames_are_scored_as_stills_and_a_history_lags_but_flickers_less(scene, tmp_path):
    refs = references(scene)
    noisy, smooth = entries("NoisyTruth", "ExponentialTruth[hysteresis=0.8]")
    out = run_sequence([noisy, smooth], scene, 4, [0, 1], refs)
    assert len(out.frame_rows) == 2 * 2 * 18 and len(out.sequence_rows) == 4
    first = out.frame_rows[0]
    assert first["frame"] == 0 and first["status"] == "ok"
    expected = score_image(out.images[first["renderer"]][0], refs[0], 4).values
    assert first["rmse"] == expected["rmse"] and first["delta_e2000_mean"] == expected["delta_e2000_mean"]
    by = {(r["renderer"], r["seed"]): r for r in out.sequence_rows}
    for seed in (0, 1):
        stateless, history = by[(noisy.name, seed)], by[(smooth.name, seed)]
        assert history["flicker"] < 0.6 * stateless["flicker"]
        assert history["lag"] > stateless["lag"]
        assert stateless["flicker_floor"] == pytest.approx(math.sqrt(4e-6)) and stateless["change_frame"] == 5
        assert json.loads(history["info_state"]) == {"hysteresis": 0.8, "frames": 18}
    paths = write_sequence_results(tmp_path, out)
    assert len(pd.read_csv(paths[0])) == 72 and len(pd.read_csv(paths[1])) == 4
    assert json.loads(paths[2].read_text())[0]["spp"] == 4


def test_a_history_too_long_for_the_sequence_has_not_settled_and_says_so(scene, tmp_path):
    """Hysteresis 0.97 (a time constant of 33 frames) on 18 frames, the light stopping at 5: the steady frames
    12-17 still fall, so the lag is inf, more than the 12 frames shown after the change: inf in sequences.csv,
    null beside its bound in the strict JSON; the report's table says "> 12" and its plane draws the point at the
    right edge, marked; hysteresis 0.8 settles."""
    slow, quick = entries("ExponentialTruth[hysteresis=0.97]", "ExponentialTruth[hysteresis=0.8]")
    out = run_sequence([slow, quick], scene, 4, [0, 1], references(scene))
    rows = {(r["renderer"], r["seed"]): r for r in out.sequence_rows}
    for seed in (0, 1):
        assert rows[(slow.name, seed)]["lag"] == math.inf and rows[(slow.name, seed)]["lag_bound"] == 12
        assert 0 <= rows[(quick.name, seed)]["lag"] < 12
    paths = write_sequence_results(tmp_path, out)
    csv = pd.read_csv(paths[1]).set_index(["renderer", "seed"])
    assert csv.loc[(slow.name, 0), "lag"] == math.inf and csv.loc[(slow.name, 0), "lag_bound"] == 12
    strict = json.loads(paths[2].read_text())[0]
    assert strict["lag"] is None and strict["lag_bound"] == 12
    html = write_sequence_report(tmp_path, "moving", out.frame_rows, out.sequence_rows, out.images,
                                 [r.image for r in references(scene)], "cbox sequence").read_text()
    assert "&gt; 12 (not settled)" in html
    plane = lag_flicker_plot(pd.DataFrame(out.sequence_rows), {slow.name: "#111", quick.name: "#222"})
    assert plane.count('class="point censored"') + plane.count('class="point on-front censored"') == 1
    assert f"{slow.name}: lag &gt; 12 frames (not settled)" in plane  # its tooltip
    assert 'class="censored-arrow"' in plane


def test_a_renderer_failure_is_a_failed_row(scene):
    (bad,) = entries("ForgetsFrames")
    out = run_sequence([bad], scene, 1, [0], references(scene), time_limit_s=120)
    (row,) = out.sequence_rows
    assert row["status"] == "failed" and "expected a SequenceResult of 18" in row["reason"]
    assert out.frame_rows == [] and out.images == {}
