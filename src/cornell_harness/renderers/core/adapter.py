"""What every renderer of ours shares as a harness adapter: threads, availability, version, features.

The adapter interface is the renderer API's (:class:`cornell_harness.adapters.api.Renderer`,
and what a renderer may declare, :class:`cornell_harness.adapters.api.Declarations`);
our renderers (path tracer, photon mapper, SPPM, probes, AO, ambient, SSAO)
differ only in their integrator and settings, so the rest is written once here.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from cornell_harness.adapters.api import Stopwatch
from cornell_harness.scenes.model import Scene
from cornell_harness.renderers.core import film
from cornell_harness.renderers.core.geometry import SceneGeometry
from cornell_harness.renderers.core.rays import add_unoccluded, shadow_buffer

#: Scene features the shared toolkit models (src/cornell_harness/renderers/core): every renderer of ours inherits them.
TOOLKIT_FEATURES = frozenset({"triangle_mesh", "sphere", "diffuse", "mirror", "dielectric", "area_light",
                              "pinhole_camera", "box_filter"})


class ToolkitRenderer:
    """Base of our adapters: ``threads`` worker threads (None: :func:`cornell_harness.adapters.api.default_threads`)."""

    features = TOOLKIT_FEATURES
    approximations: tuple[str, ...] = ()

    def __init__(self, threads: int | None = None):
        self.threads = threads

    def unavailable_reason(self) -> str | None:
        try:  # Embree's library comes in embreex's wheel (cornell_harness.renderers.core.embree)
            from cornell_harness.renderers.core.embree import library

            library()
        except (ImportError, OSError) as e:
            return f"Embree is not available ({e}); pip install embreex"
        return None

    def version(self) -> str:
        from importlib.metadata import version

        return f"cornell-harness {version('cornell-harness')} (embreex {version('embreex')})"


def warmed_geometry(scene: Scene, warm_up: Callable[[SceneGeometry], object]) -> tuple[SceneGeometry, float]:
    """The scene's Embree geometry after ``warm_up(geom)`` compiled (or loaded from numba's cache) the
    renderer's kernels, and the seconds both took: the set-up a render's time leaves out. The kernels every
    renderer shares are warmed up too (:func:`warm_up_shared`). The rays the warm-up traced are not counted
    in ``geom.rays``."""
    clock = Stopwatch()
    geom = SceneGeometry(scene)
    warm_up_shared(geom)
    warm_up(geom)
    geom.rays = 0
    return geom, clock.wall()


def warm_up_shared(geom: SceneGeometry) -> None:
    """Compile (or load) the shared kernels a renderer's own warm-up may not reach: the film's
    (:func:`cornell_harness.renderers.core.film.warm_up`) and the shadow rays' (one segment). A warm-up of one path often
    casts no shadow ray, and then a process's first render compiled these inside its time: 0.9 s of a 1-spp
    Cornell box with a cold numba cache (a Dask worker's first cell; docs/timing.md)."""
    film.warm_up()
    shadow = shadow_buffer(1)
    for array in shadow:
        array[:] = 0
    shadow.d[:, 2] = shadow.t[:] = 1.0
    add_unoccluded(np.zeros((1, 3)), shadow, geom.unoccluded(shadow.o, shadow.d, shadow.t))
