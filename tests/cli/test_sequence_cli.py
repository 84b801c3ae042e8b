"""cbox sequence end to end: on a stand-in animated scene (results, report with its figures and animations), and on
the stored cornell-box-moving-light with its per-frame references (a few frames, 1 spp); --frames checked."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from PIL import Image

from cornell_harness.scenes import library
from cornell_harness.workflows import sequence_run
from tests.conftest import cbox_in_process
from tests.sequence_fakes import moving_light, references


@pytest.fixture
def stand_in(monkeypatch):
    scene = moving_light(frames=9, stop=2, size=10)
    monkeypatch.setattr(library, "resolve_scene", lambda name, overrides=(): scene)
    monkeypatch.setattr(sequence_run, "sequence_references", lambda sc, frames: references(sc, frames))
    return scene


def test_sequence_writes_results_and_report(stand_in, tmp_path, capsys):
    code, _, err = cbox_in_process(
        capsys, "sequence", "--scene", "moving", "-r", "tests.sequence_fakes:NoisyTruth",
        "-r", "tests.sequence_fakes:ExponentialTruth[hysteresis=0.5]",
        "-r", "tests.sequence_fakes:ExponentialTruth[hysteresis=0.9]", "--spp", "2", "--seeds", "2",
        "--out", str(tmp_path))
    assert code == 0, err
    assert "flicker" in err and "lag" in err
    rows = json.loads((tmp_path / "sequences.json").read_text())
    assert len(rows) == 6 and {r["seed"] for r in rows} == {0, 1}
    html = (tmp_path / "sequence.html").read_text()
    assert html.count('class="series"') == 3  # error against frame: one line per renderer
    assert "sequence-lag-flicker" in html and "frame 8" in html
    anims = sorted(tmp_path.glob("anim-*.png"))
    assert len(anims) == 3
    with Image.open(anims[0]) as im:
        assert im.n_frames == 9 and im.size == (30, 10)  # render | reference | error
        im.seek(8)
        assert np.asarray(im.convert("RGB")).any()


def test_a_lag_that_did_not_settle_is_printed_as_a_bound(monkeypatch, tmp_path, capsys):
    """Hysteresis 0.97 on 18 frames, the light stopping at 5: not settled within the 12 frames after it."""
    scene = moving_light(frames=18, stop=5, size=12)
    monkeypatch.setattr(library, "resolve_scene", lambda name, overrides=(): scene)
    monkeypatch.setattr(sequence_run, "sequence_references", lambda sc, frames: references(sc, frames))
    code, _, err = cbox_in_process(capsys, "sequence", "--scene", "moving", "-r",
                                   "tests.sequence_fakes:ExponentialTruth[hysteresis=0.97]", "--spp", "4",
                                   "--seeds", "1", "--out", str(tmp_path))
    assert code == 0, err
    assert "lag > 12 frames (not settled)" in err


def test_a_failed_renderer_exits_1(stand_in, tmp_path, capsys):
    code, _, err = cbox_in_process(capsys, "sequence", "--scene", "moving", "-r", "tests.sequence_fakes:ForgetsFrames",
                                   "--seeds", "1", "--out", str(tmp_path))
    assert code == 1 and "failed" in err
    assert json.loads((tmp_path / "sequences.json").read_text())[0]["status"] == "failed"


def test_sequence_on_the_stored_moving_light(tmp_path, capsys):
    """The real scene and its stored per-frame references: frames 10-15 (the light stops at frame 12) with the
    path tracer, stateless, at 1 spp. Lag follows the change; the noise of 1 spp flickers above the floor of
    the 1024-spp references."""
    code, _, err = cbox_in_process(capsys, "sequence", "--scene", "cornell-box-moving-light", "-r", "pathtracer",
                                   "--frames", "10-15", "--spp", "1", "--seeds", "1", "--out", str(tmp_path))
    assert code == 0, err
    (row,) = json.loads((tmp_path / "sequences.json").read_text())
    assert row["status"] == "ok" and (row["frames"], row["first_frame"], row["change_frame"]) == (6, 10, 12)
    assert row["flicker"] > 3 * row["flicker_floor"] > 0 and row["lag"] >= 0 and row["ghosting"] > 0
    frames = pd.read_csv(tmp_path / "frames.csv")
    assert frames["frame"].tolist() == list(range(10, 16)) and (frames["delta_e2000_mean"] > 0).all()
    assert (tmp_path / "anim-pathtracer.png").is_file()


@pytest.mark.parametrize("frames, message", [("3,5", "must be consecutive"), ("140-150", "frames are 0..143")])
def test_frames_must_be_consecutive_and_in_the_scene(frames, message, tmp_path, capsys):
    code, _, err = cbox_in_process(capsys, "sequence", "--scene", "cornell-box-moving-light", "-r", "pathtracer",
                                   "--frames", frames, "--out", str(tmp_path))
    assert code == 2 and "--frames" in err and message in err, err
