"""The one render path: the only call of a renderer's ``render``, and the checks of what it returned.

Kept light (NumPy only) because the sandbox's child process imports it too:
a time-limited render must not spend its budget loading SciPy.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from harness.adapters.api import RenderResult
from harness.adapters.registry import RendererEntry
from harness.adapters.settings import declared, resolve_settings
from harness.scenes.model import Scene


class RenderError(ValueError):
    """A renderer returned something the harness cannot use (wrong shape, wrong spp)."""


class RenderTimeout(RuntimeError):
    """A sandboxed render was killed at its time limit; ``time_s`` is how long it ran."""

    def __init__(self, message: str, time_s: float):
        super().__init__(message)
        self.time_s = time_s


def render_checked(entry: RendererEntry, scene: Scene, spp: int, seed: int,
                   checkpoints: Sequence[int] = ()) -> RenderResult:
    """``entry``'s render with its settings, its image, variance and checkpoints checked; may raise.

    A renderer that declares settings gets every one of them, validated, typed and with its default filled in
    (whatever ``entry`` was built with); one that declares none keeps the plain signature. This is the only
    place settings are resolved for a render: renderers never validate them again.
    """
    kwargs = {}
    if checkpoints:
        kwargs["checkpoints"] = list(checkpoints)
    if declared(entry.renderer):
        kwargs["settings"] = resolve_settings(entry.renderer, entry.settings)
    result = entry.renderer.render(scene, spp, seed, **kwargs)
    expected = (scene.camera.height, scene.camera.width, 3)
    result.image = _checked_image(result.image, expected, "an image")
    if result.variance is not None:
        result.variance = _checked_image(result.variance, expected, "a variance image")
    for c in result.checkpoints:
        c.image = _checked_image(c.image, expected, f"a checkpoint image at {c.spp} spp")
    return result


def _checked_image(image, expected: tuple[int, int, int], what: str) -> np.ndarray:
    image = np.asarray(image, dtype=np.float32)
    if image.shape != expected:
        raise RenderError(f"returned {what} of shape {image.shape}, expected {expected}")
    return image
