"""Renderers that declare ``stops_early``: a stop rule ends the render at a checkpoint, and what it returns is
the render of that many spp, the samples a longer render would have started with (one render path, so the
gate's looks at a stopped render and at a full one see the same images)."""

from __future__ import annotations

import numpy as np
import pytest

from cornell_harness.adapters.api import attribute
from cornell_harness.adapters.registry import RendererEntry, resolve
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.workflows.render import RenderError, render_checked

pytest.importorskip("embreex")


class StopAt:
    """Stops at ``spp``; remembers every checkpoint it was shown."""

    def __init__(self, spp: int):
        self.spp, self.seen = spp, []

    def __call__(self, checkpoint) -> bool:
        self.seen.append(checkpoint.spp)
        return checkpoint.spp == self.spp


@pytest.mark.parametrize("name, scene", [("pathtracer", "cornell-box"), ("ao", "cornell-box-ao"),
                                         ("mitsuba", "cornell-box"), ("mitsuba", "cornell-box-ao")])
def test_a_stopped_render_is_the_render_of_its_spp(name, scene):
    (entry,) = resolve([name])
    if not entry.available:
        pytest.skip(entry.reason)
    assert attribute(entry.renderer, "stops_early")
    scene = resolve_scene(scene).with_resolution(24, 16)
    looks = [4, 8, 16, 32]
    stop = StopAt(8)
    stopped = render_checked(entry, scene, 32, 5, looks, stop)
    assert stop.seen == [4, 8] and stopped.spp == 8
    assert [c.spp for c in stopped.checkpoints] == [4, 8]
    full = render_checked(entry, scene, 32, 5, looks)
    assert full.spp == 32
    np.testing.assert_array_equal(stopped.image, full.checkpoints[1].image)
    np.testing.assert_array_equal(stopped.image, stopped.checkpoints[-1].image)
    if stopped.variance is not None:  # the variance of the image it returns, at its spp
        assert np.mean(stopped.variance) > 1.5 * np.mean(full.variance)


def test_a_renderer_that_does_not_declare_it_is_not_stopped():
    (entry,) = resolve(["tests.user_renderers:StopsNever"])
    stop = StopAt(8)
    result = render_checked(entry, resolve_scene("cornell-box"), 32, 0, [8, 16, 32], stop)
    assert result.spp == 32 and stop.seen == []


def test_a_stop_off_the_checkpoints_is_an_error():
    class Liar:
        name, stops_early = "liar", True

        def unavailable_reason(self):
            return None

        def version(self):
            return "1"

        def render(self, scene, spp, seed, checkpoints=(), stop=None):
            from cornell_harness.adapters.api import RenderResult

            image = np.zeros((scene.camera.height, scene.camera.width, 3), np.float32)
            return RenderResult(image, 0.0, 3, seed)

    entry = RendererEntry("liar", "liar", Liar(), None)
    with pytest.raises(RenderError, match="stopped early at 3 spp, which is not one of its checkpoints"):
        render_checked(entry, resolve_scene("cornell-box").with_resolution(8, 8), 16, 0, [8, 16], lambda c: True)
