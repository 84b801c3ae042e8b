"""Sequence renders: the stateless default (each frame alone, its seed frame_seed(seed, i)), a stateful renderer's
own render_sequence, and both in the sandbox as one job."""

from __future__ import annotations

import numpy as np
import pytest

from cornell_harness.adapters.api import attribute, frame_seed
from cornell_harness.adapters.registry import resolve
from cornell_harness.workflows.render import RenderError
from cornell_harness.workflows.sequence import frame_list, render_sequence
from tests.sequence_fakes import noisy, moving_light, truth


def entry(name: str, **settings):
    (e,) = resolve([f"tests.sequence_fakes:{name}"])
    return e.with_settings(settings) if settings else e


def test_stateless_default_renders_each_frame_alone_with_its_frame_seed():
    scene = moving_light(frames=6, stop=3)
    out = render_sequence(entry("NoisyTruth"), scene, 4, 7)
    assert len(out.frames) == 6 and out.state == {}
    for i, frame in enumerate(out.frames):
        assert frame.seed == frame_seed(7, i)
        np.testing.assert_array_equal(frame.image, noisy(scene.at_frame(i), 4, frame_seed(7, i)))
    # the light moves for three frames, then rests: the truth follows it
    assert not np.array_equal(truth(scene.at_frame(1)), truth(scene.at_frame(2)))
    np.testing.assert_array_equal(truth(scene.at_frame(3)), truth(scene.at_frame(5)))


def test_stateful_renderer_renders_the_sequence_itself_and_keeps_its_state():
    scene = moving_light(frames=5, stop=2)
    e = entry("ExponentialTruth", hysteresis=0.5)
    assert attribute(e.renderer, "sequences") is True
    assert attribute(resolve(["tests.sequence_fakes:NoisyTruth"])[0].renderer, "sequences") is False
    out = render_sequence(e, scene, 4, 3, frames=[0, 1, 2])
    assert out.state == {"hysteresis": 0.5, "frames": 3}
    fresh = [noisy(scene.at_frame(i), 4, frame_seed(3, i)) for i in range(3)]
    expected = 0.5 * (0.5 * fresh[0] + 0.5 * fresh[1]) + 0.5 * fresh[2]
    np.testing.assert_allclose(out.frames[2].image, expected, rtol=1e-6)


def test_sandboxed_sequence_is_one_job_with_the_same_frames_and_state():
    scene = moving_light(frames=4, stop=2)
    e = entry("ExponentialTruth", hysteresis=0.7)
    here = render_sequence(e, scene, 2, 5)
    there = render_sequence(e, scene, 2, 5, time_limit_s=120)
    assert there.state == here.state
    for a, b in zip(here.frames, there.frames):
        np.testing.assert_array_equal(a.image, b.image)
        assert a.seed == b.seed and b.time_s == pytest.approx(0.002)


def test_a_wrong_sequence_is_refused_here_and_in_the_sandbox():
    scene = moving_light(frames=4, stop=2)
    with pytest.raises(RenderError, match="3 frames, expected a SequenceResult of 4"):
        render_sequence(entry("ForgetsFrames"), scene, 1, 0)
    with pytest.raises(RenderError, match="3 frames") as err:
        render_sequence(entry("ForgetsFrames"), scene, 1, 0, time_limit_s=120)
    assert "render_sequence" in err.value.traceback


def test_frames_are_checked_against_the_scene():
    scene = moving_light(frames=4)
    assert frame_list(scene, [3, 1, 1]) == [1, 3]
    with pytest.raises(ValueError, match="frame 4 is outside the scene's 4 frames"):
        frame_list(scene, [0, 4])
