"""What every renderer of ours shares as a harness adapter: threads, availability, version, features.

The adapter interface is the renderer API's (:class:`harness.adapters.api.Renderer`,
and what a renderer may declare, :class:`harness.adapters.api.Declarations`);
our renderers (path tracer, photon mapper, SPPM, probes, AO, ambient, SSAO)
differ only in their integrator and settings, so the rest is written once here.
"""

from __future__ import annotations

import time
from typing import Callable

from harness.scenes.model import Scene
from renderers.core.geometry import SceneGeometry

#: Scene features the shared toolkit models (renderers/core): every renderer of ours inherits them.
TOOLKIT_FEATURES = frozenset({"triangle_mesh", "sphere", "diffuse", "mirror", "dielectric", "area_light",
                              "pinhole_camera", "box_filter"})


class ToolkitRenderer:
    """Base of our adapters: ``threads`` worker threads (None: :func:`harness.adapters.api.default_threads`)."""

    features = TOOLKIT_FEATURES
    approximations: tuple[str, ...] = ()

    def __init__(self, threads: int | None = None):
        self.threads = threads

    def unavailable_reason(self) -> str | None:
        try:  # Embree's library comes in embreex's wheel (renderers.core.embree)
            from renderers.core.embree import library

            library()
        except (ImportError, OSError) as e:
            return f"Embree is not available ({e}); pip install embreex"
        return None

    def version(self) -> str:
        from importlib.metadata import version

        return f"cornell-harness {version('cornell-harness')} (embreex {version('embreex')})"


def warmed_geometry(scene: Scene, warm_up: Callable[[SceneGeometry], object]) -> tuple[SceneGeometry, float]:
    """The scene's Embree geometry after ``warm_up(geom)`` compiled (or loaded from numba's cache) the
    renderer's kernels, and the seconds both took: the set-up a render's time leaves out. The rays the
    warm-up traced are not counted in ``geom.rays``."""
    t0 = time.perf_counter()
    geom = SceneGeometry(scene)
    warm_up(geom)
    geom.rays = 0
    return geom, time.perf_counter() - t0
