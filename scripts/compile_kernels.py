"""Compile our renderers' numba kernels, and the harness's, into numba's on-disk cache (``__pycache__``).

``scripts/setup.sh`` runs this once after installing, so that the first ``cbox demo`` (or render) does not
spend its first minute compiling: on this 2-core machine the demo took 3:42 with cold caches and 2:50 with
warm ones (BENCHMARKS.md, issue 34). Each of our renderers (:class:`cornell_harness.renderers.core.adapter.ToolkitRenderer`,
found through the ``cbox.renderers`` entry points) renders each demo scene it can model at 8×8, 2 spp with
checkpoints (numba compiles per argument type, not per size), and HDR-FLIP scores one tiny image. A renderer
that is unavailable or fails is reported on one line and skipped: compiling is an optimisation, never a reason
for setup to fail. Run: ``.venv/bin/python scripts/compile_kernels.py`` (about a minute, once).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from cornell_harness.adapters.registry import discover, missing_features
from cornell_harness.cli.run import DEMO_SCENES
from cornell_harness.evaluate.flip import flip_map
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.renderers.core.adapter import ToolkitRenderer


def main() -> int:
    started = time.perf_counter()
    scenes = [resolve_scene(name).with_resolution(8, 8) for name in DEMO_SCENES]
    for name, entry in discover().items():
        if not (entry.available and isinstance(entry.renderer, ToolkitRenderer)):
            continue
        for scene in scenes:
            if missing_features(entry.renderer, scene):
                continue
            try:
                entry.renderer.render(scene, 2, 0, checkpoints=[1, 2], settings=entry.settings)
            except Exception as e:  # noqa: BLE001 (reported; the render itself will say why, later)
                print(f"compile_kernels: {name} on {scene.name}: {type(e).__name__}: {e}", file=sys.stderr)
    flip_map(np.full((8, 8, 3), 0.5), np.full((8, 8, 3), 0.4))
    print(f"compile_kernels: done in {time.perf_counter() - started:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
