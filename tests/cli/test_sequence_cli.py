"""cbox sequence end to end on a stand-in animated scene: results, report with its figures and animations."""

from __future__ import annotations

import json

import numpy as np
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


def test_a_failed_renderer_exits_1(stand_in, tmp_path, capsys):
    code, _, err = cbox_in_process(capsys, "sequence", "--scene", "moving", "-r", "tests.sequence_fakes:ForgetsFrames",
                                   "--seeds", "1", "--out", str(tmp_path))
    assert code == 1 and "failed" in err
    assert json.loads((tmp_path / "sequences.json").read_text())[0]["status"] == "failed"
