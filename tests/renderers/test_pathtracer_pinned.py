"""The path tracer's images, pinned bit for bit, per sampler.

The ``independent`` hashes were taken before the path tracer was restructured
onto the shared toolkit (``src/cornell_harness/renderers/core/``), and held through the move of
ray queries to Embree's C API; the ``pmj02`` ones when that sampler (the
default) came. Any refactoring of the toolkit or the integrator must keep
them. A deliberate change of the estimator (a sampler's numbers, another
dimension layout) changes them: then re-pin, and say so in the commit.
"""

from __future__ import annotations

import dataclasses
import hashlib

import numpy as np
import pytest

from cornell_harness.scenes.library import resolve_scene
from cornell_harness.renderers.pathtracer import PathTracer

pytest.importorskip("embreex")

#: (scene, max_depth override or None, spp, seed, sampler) -> sha256 of image then variance, float32 bytes.
PINNED = {
    ("cornell-box", None, 4, 7, "independent"): "5b659f8a4b954982508a4d2fca1cc7d195a9056bdde86ea0939d6e9670bbbfb1",
    ("cornell-box", 3, 4, 2, "independent"): "b3f104b5d945e3d12b71bf6703668ca8e6fa5e20687852575886038c7c527e96",
    ("furnace", None, 8, 3, "independent"): "abd42d5aa4aa3bd8219a99ac1d4691b791ae8188e67b72569ec9d48d4445f47a",
    ("light-panel", None, 4, 1, "independent"): "c2338581d9094e1cdde5c3f0dffc8ca421d257242e36dee7044738588c05466e",
    ("cornell-box", None, 16, 7, "pmj02"): "d1e4d6afcc295f26c1435d7ddf99ba7f5374ffa905630302719ecc54864f8d10",
    ("furnace", None, 16, 3, "pmj02"): "6cf676cb8c33d9cbd57fd13e0792d23b17f39dd047ff3d4e2c60b22b286c578e",
}


def image_hash(result) -> str:
    data = np.ascontiguousarray(result.image, np.float32).tobytes()
    return hashlib.sha256(data + np.ascontiguousarray(result.variance, np.float32).tobytes()).hexdigest()


@pytest.mark.parametrize("case", sorted(PINNED, key=str), ids=lambda c: f"{c[0]}-depth{c[1]}-{c[2]}spp-seed{c[3]}-{c[4]}")
def test_image_is_bit_identical_to_the_pinned_one(case):
    name, max_depth, spp, seed, sampler = case
    scene = resolve_scene(name)
    if max_depth is not None:
        scene = dataclasses.replace(scene, max_depth=max_depth)
    assert image_hash(PathTracer(threads=2).render(scene, spp, seed, settings={"sampler": sampler})) == PINNED[case]
