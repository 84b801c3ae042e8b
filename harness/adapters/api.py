"""The renderer API: the one module of the harness a renderer imports (besides the scene model).

A renderer is a small class (state: the renderer's own handles) that
satisfies :class:`Renderer`. Everything it needs from the harness is here:
what it returns (:class:`RenderResult`, :class:`Checkpoint`), the auxiliary
images it may give (:data:`AOVS`), the kinds of estimate it may declare
(:data:`ESTIMATORS`), its settings (:class:`Setting`, :class:`SettingsError`),
the seed and pass helpers every renderer shares (:func:`pass_key`,
:func:`pass_seed`, :func:`spp_passes`) and the thread count
(:func:`default_threads`). Discovery, settings resolution and the render path
live elsewhere (:mod:`harness.adapters.registry`, :mod:`harness.workflows.render`)
and a renderer never imports them.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Protocol, Sequence, runtime_checkable

import numpy as np

from harness.adapters.seeds import pass_key, pass_seed, spp_passes
from harness.adapters.settings import Setting, SettingsError
from harness.scenes.model import Scene

__all__ = ["AOVS", "ESTIMATORS", "Checkpoint", "RenderResult", "Renderer", "Setting", "SettingsError",
           "THREADS_VARIABLE", "default_threads", "machine_cores", "pass_key", "pass_seed", "spp_passes"]

#: Auxiliary images (AOVs) a renderer may return, defined as Intel Open Image Denoise expects them (its
#: documentation, "RT" filter): the surface seen through each pixel at the first non-delta hit, following
#: mirrors and glass, averaged over the pixel's samples like the image; (H, W, 3) float32.
#: ``albedo``: its reflectance times the specular chain's tint, in [0, 1]; ``normal``: its unit normal
#: (world space) on the side the ray arrives from, in [-1, 1]; both 0 where the path leaves the scene.
AOVS = ("albedo", "normal")
#: What an adapter's ``estimator`` may say; the first is the default of an adapter that says nothing.
ESTIMATORS = ("unbiased", "consistent", "biased")


@dataclass
class Checkpoint:
    """The image after the first ``spp`` samples per pixel, and the time to get there."""

    spp: int
    image: np.ndarray
    time_s: float
    aovs: dict = field(default_factory=dict)  # name (AOVS) -> (H, W, 3) float32, when asked for


@dataclass
class RenderResult:
    """What a render returns.

    ``image`` is linear-sRGB radiance, float32, shape (height, width, 3).
    ``time_s`` is wall time of the render proper (scene set-up excluded,
    JIT compilation included unless the adapter warmed up beforehand).
    ``info`` carries adapter details worth recording (e.g. Mitsuba's variant).
    ``variance``, when the renderer can give it, is the per-pixel variance of
    ``image`` (of the mean, not of one sample), float32 (height, width, 3).
    ``aovs`` holds the auxiliary images (:data:`AOVS`) the caller asked for.
    """

    image: np.ndarray
    time_s: float
    spp: int
    seed: int
    checkpoints: list[Checkpoint] = field(default_factory=list)
    info: dict = field(default_factory=dict)
    variance: np.ndarray | None = None
    aovs: dict = field(default_factory=dict)


@runtime_checkable
class Renderer(Protocol):
    name: str
    features: frozenset[str]
    approximations: tuple[str, ...]

    def unavailable_reason(self) -> str | None: ...

    def version(self) -> str: ...

    def render(self, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = ()) -> RenderResult: ...


#: The environment variable that sets :func:`default_threads` (a Dask worker's share is set through it).
THREADS_VARIABLE = "CBOX_THREADS"


def machine_cores() -> int:
    """The machine's CPU count (at least 1): the threads without ``$CBOX_THREADS``, and what a host's workers share."""
    return os.cpu_count() or 1


def default_threads() -> int:
    """Worker threads: ``$CBOX_THREADS`` (a positive integer) or the machine's CPU count.

    Raises :class:`SettingsError` (one of the CLI's user errors) naming
    ``CBOX_THREADS`` if it is set to anything else.
    """
    env = os.environ.get(THREADS_VARIABLE)
    if env:
        try:
            threads = int(env)
        except ValueError:
            threads = 0
        if threads < 1:
            raise SettingsError(f"{THREADS_VARIABLE}: expected a positive integer (worker threads), got {env!r}")
        return threads
    return machine_cores()
