"""The path tracer's images, pinned bit for bit.

Hashes taken before the path tracer was restructured onto the shared
toolkit (``renderers/core/``); any refactoring of the toolkit or the
integrator must keep them. A deliberate change of the estimator (another
sampler, another dimension layout) changes them: then re-pin, and say so in
the commit.
"""

from __future__ import annotations

import dataclasses
import hashlib

import numpy as np
import pytest

from harness.scenes.library import resolve_scene
from renderers.pathtracer import PathTracer

pytest.importorskip("embreex")

#: (scene, max_depth override or None, spp, seed) -> sha256 of image then variance, float32 bytes.
PINNED = {
    ("cornell-box", None, 4, 7): "5b659f8a4b954982508a4d2fca1cc7d195a9056bdde86ea0939d6e9670bbbfb1",
    ("cornell-box", 3, 4, 2): "b3f104b5d945e3d12b71bf6703668ca8e6fa5e20687852575886038c7c527e96",
    ("furnace", None, 8, 3): "abd42d5aa4aa3bd8219a99ac1d4691b791ae8188e67b72569ec9d48d4445f47a",
    ("light-panel", None, 4, 1): "c2338581d9094e1cdde5c3f0dffc8ca421d257242e36dee7044738588c05466e",
}


def image_hash(result) -> str:
    data = np.ascontiguousarray(result.image, np.float32).tobytes()
    return hashlib.sha256(data + np.ascontiguousarray(result.variance, np.float32).tobytes()).hexdigest()


@pytest.mark.parametrize("case", sorted(PINNED, key=str), ids=lambda c: f"{c[0]}-depth{c[1]}-{c[2]}spp-seed{c[3]}")
def test_image_is_bit_identical_to_the_pinned_one(case):
    name, max_depth, spp, seed = case
    scene = resolve_scene(name)
    if max_depth is not None:
        scene = dataclasses.replace(scene, max_depth=max_depth)
    assert image_hash(PathTracer(threads=2).render(scene, spp, seed)) == PINNED[case]
