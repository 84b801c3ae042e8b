"""The one render path: the only call of a renderer's ``render``, and the checks of what it returned.

Kept light (no SciPy, no pandas) because the sandbox's child process imports it too:
a time-limited render must not spend its budget loading SciPy.
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from cornell_harness.adapters.api import (Checkpoint, ReferenceFit, RenderResult, SequenceResult, attribute,
                                          frame_seed)
from cornell_harness.adapters.registry import RendererEntry
from cornell_harness.adapters.settings import declared, resolve_settings
from cornell_harness.evaluate.reference_fit import fitted_image
from cornell_harness.scenes.model import Scene
from cornell_harness.store.references import load_reference


class RenderError(ValueError):
    """A renderer returned something the harness cannot use (wrong shape, wrong spp), or a sandboxed render
    failed; ``traceback`` is then the child process's own (the parent's would show only this raise)."""

    def __init__(self, message: str, traceback: str = ""):
        super().__init__(message)
        self.traceback = traceback


class RenderTimeout(RuntimeError):
    """A sandboxed render was killed at its time limit; ``time_s`` is how long it ran."""

    def __init__(self, message: str, time_s: float):
        super().__init__(message)
        self.time_s = time_s


def render_checked(entry: RendererEntry, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = (),
                   stop: Callable[[Checkpoint], bool] | None = None) -> RenderResult:
    """``entry``'s render with its settings, its image, variance and checkpoints checked; may raise.

    A renderer that declares settings gets every one of them, validated, typed and with its default filled in
    (whatever ``entry`` was built with); one that declares none keeps the plain signature. This is the only
    place settings are resolved for a render: renderers never validate them again. ``stop`` goes to a renderer
    that declares ``stops_early`` (:class:`cornell_harness.adapters.api.Declarations`); it may then return a
    result at one of ``checkpoints`` below ``spp``.
    """
    kwargs = {}
    if checkpoints:
        kwargs["checkpoints"] = list(checkpoints)
    if declared(entry.renderer):
        kwargs["settings"] = resolve_settings(entry.renderer, entry.settings)
    if stop is not None and attribute(entry.renderer, "stops_early"):
        kwargs["stop"] = stop
    fit = attribute(entry.renderer, "reference_fit")
    if fit is not None and kwargs.get("settings", {}).get(fit.setting) == fit.value:
        result = _fitted_render(entry.renderer, fit, scene, spp, seed, kwargs)
    else:
        result = entry.renderer.render(scene, spp, seed, **kwargs)
    if "stop" in kwargs and result.spp != spp and result.spp not in checkpoints:
        raise RenderError(f"stopped early at {result.spp} spp, which is not one of its checkpoints")
    expected = (scene.camera.height, scene.camera.width, 3)
    result.image = _checked_image(result.image, expected, "an image")
    if result.variance is not None:
        result.variance = _checked_image(result.variance, expected, "a variance image")
    for c in result.checkpoints:
        c.image = _checked_image(c.image, expected, f"a checkpoint image at {c.spp} spp")
    return result


def render_sequence_checked(entry: RendererEntry, scene: Scene, spp: int, seed: int,
                            frames: Sequence[int]) -> SequenceResult:
    """``entry``'s render of ``frames`` of animated ``scene``, every frame checked as :func:`render_checked` checks
    an image; may raise. The one render path of a sequence, in this process or a sandbox's child.

    A renderer that declares ``sequences`` (:class:`cornell_harness.adapters.api.Declarations`) renders them
    itself, carrying its state from frame to frame; any other renders each frame on its own, as the still scene
    ``scene.at_frame(i)`` with seed :func:`~cornell_harness.adapters.api.frame_seed` ``(seed, i)``, through
    :func:`render_checked`.
    """
    frames = list(frames)
    if not attribute(entry.renderer, "sequences"):
        return SequenceResult([render_checked(entry, scene.at_frame(i), spp, frame_seed(seed, i)) for i in frames])
    kwargs = {"settings": resolve_settings(entry.renderer, entry.settings)} if declared(entry.renderer) else {}
    if not callable(getattr(entry.renderer, "render_sequence", None)):
        raise RenderError("declares sequences = True but has no render_sequence method")
    result = entry.renderer.render_sequence(scene, spp, seed, frames=frames, **kwargs)
    if not isinstance(result, SequenceResult) or len(result.frames) != len(frames):
        got = len(result.frames) if isinstance(result, SequenceResult) else type(result).__name__
        raise RenderError(f"render_sequence returned {got} frames, expected a SequenceResult of {len(frames)}")
    for i, frame in zip(frames, result.frames):
        cam = scene.at_frame(i).camera
        expected = (cam.height, cam.width, 3)
        frame.image = _checked_image(frame.image, expected, f"an image at frame {i}")
        if frame.variance is not None:
            frame.variance = _checked_image(frame.variance, expected, f"a variance image at frame {i}")
    return result


#: What a fitted render records under ``info["oracle"]``.
ORACLE_NOTE = ("fitted to the stored reference: the least-squares constant per channel, an oracle no renderer "
               "could compute from the scene (two renders)")


def _fitted_render(renderer, fit: ReferenceFit, scene: Scene, spp: int, seed: int, kwargs: dict) -> RenderResult:
    """The oracle ``fit`` declares (:class:`cornell_harness.adapters.api.ReferenceFit`): two renders with the same seed,
    D and D + B, and D + c·B with c fitted to the stored reference (per checkpoint too); no variance image (the
    renders' samples are correlated and their covariance is not kept)."""
    reference = load_reference(scene).image  # no reference: refused before anything renders
    settings = kwargs["settings"]
    direct, unit = (renderer.render(scene, spp, seed, **{**kwargs, "settings": {**settings, **changed}})
                    for changed in (fit.without, fit.unit))
    image, c = fitted_image(direct.image, unit.image, reference)
    shots = [Checkpoint(a.spp, fitted_image(a.image, b.image, reference)[0], a.time_s + b.time_s,
                        cpu_time_s=_sum(a.cpu_time_s, b.cpu_time_s))
             for a, b in zip(direct.checkpoints, unit.checkpoints)]
    info = {**direct.info, fit.setting: fit.value, fit.record: [float(x) for x in c], "oracle": ORACLE_NOTE}
    if "rays" in direct.info and "rays" in unit.info:
        info["rays"] = direct.info["rays"] + unit.info["rays"]
    if "setup_s" in direct.info and "setup_s" in unit.info:
        info["setup_s"] = direct.info["setup_s"] + unit.info["setup_s"]
    return RenderResult(image, direct.time_s + unit.time_s, direct.spp, direct.seed, shots, info, None,
                        cpu_time_s=_sum(direct.cpu_time_s, unit.cpu_time_s))


def _sum(a: float | None, b: float | None) -> float | None:
    """The CPU time of two renders, None when either did not measure it."""
    return None if a is None or b is None else a + b


def _checked_image(image, expected: tuple[int, int, int], what: str) -> np.ndarray:
    image = np.asarray(image, dtype=np.float32)
    if image.shape != expected:
        raise RenderError(f"returned {what} of shape {image.shape}, expected {expected}")
    return image
