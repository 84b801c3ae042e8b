"""The images of ``probes``, ``ambient``, ``ao`` and ``whitted`` (independent sampler), pinned bit for bit.

Taken before these renderers drew their numbers through the sampler
(:mod:`cornell_harness.renderers.core.sampler`) and adopted the toolkit's one ``SampleLd``
(:mod:`cornell_harness.renderers.core.direct`), hit prologue and bundled kernel parameters
(issue 27). Any refactoring of the toolkit or these integrators must keep
them. A deliberate change of the estimator (a sampler's numbers, another
dimension layout, reordered arithmetic) changes them: then re-pin, and say
in the commit which pins changed and why.

Renders are small (low resolution, few samples, small probe grids) so each
takes well under a second once compiled.
"""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from cornell_harness.scenes.library import resolve_scene
from cornell_harness.renderers.ambient import AOAmbient
from cornell_harness.renderers.ao import AORenderer
from cornell_harness.renderers.probes import IrradianceProbes
from cornell_harness.renderers.whitted import Whitted

pytest.importorskip("embreex")

RENDERERS = {"probes": IrradianceProbes, "ambient": AOAmbient, "ao": AORenderer, "whitted": Whitted}
_PROBES = {"grid": 3, "rays_per_probe": 64, "bounces": 2, "iterations": 2}

#: (renderer, scene, width, spp, seed, settings) -> sha256 of image then variance (if any), float32 bytes.
PINNED = {
    ("probes", "cornell-box", 24, 2, 7, (("sampler", "independent"),) + tuple(_PROBES.items())):
        "ac4fed6793a0317bb9274b4c41d6485440f9d6d06e0c585ab85cb84fe229e489",
    ("probes", "two-rooms", 16, 2, 3, (("sampler", "independent"),) + tuple(dict(_PROBES, grid=4).items())):
        "c9f78154833042b7d891da81cc8a29f9903c5678fdece25d684d43e9c66440dc",
    ("probes", "furnace", 8, 2, 1, (("sampler", "independent"), ("grid", 2), ("rays_per_probe", 32),
                                    ("bounces", 3), ("iterations", 0))):
        "236b8e5dddfaccceab4a0ed5b15001f608f37706649eb10e47d59214a913fbb5",
    ("ambient", "cornell-box", 24, 4, 7, (("sampler", "independent"), ("ao_samples", 2))):
        "7eec652560998d7541594822f35696c4332fd5455fed49f1da93acd6a6f86bc6",
    ("ambient", "cornell-box-caustics", 24, 4, 5, (("sampler", "independent"),)):
        "9d91b2cc0f98cc6de0317d39df714299c8b0f35113c64ca23d5413ce4ed5211e",
    ("ambient", "light-panel", 16, 4, 1, (("sampler", "independent"), ("ambient", "none"))):
        "77a36639bdfae66a80c317e2f4cf9a5f486440864eb669847a59bf732145b9db",
    ("ao", "cornell-box-ao", 24, 8, 7, (("sampler", "independent"),)):
        "4bd3d5d692e79e83b970b48266633f317bf25b6da6aeb858eb731c610658da41",
    ("whitted", "cornell-box-caustics", 24, 4, 3, (("sampler", "independent"), ("ambient", "ao"),
                                                   ("light_samples", 2))):
        "d2dd27145648ed168f378fb7c6ed4e212d936b40313c398ff38de15ef1dee29f",
    ("whitted", "cornell-box", 16, 2, 1, (("sampler", "independent"),)):
        "1fc5dd02285ead9b8c5eba4cc8707213247938c7225f856a057252ac2097c132",
    ("whitted", "cornell-box-caustics", 16, 2, 5, (("sampler", "independent"), ("ambient", "none"),
                                                   ("transparent_shadows", "boolean"), ("light_samples", 3))):
        "90ddbef25a56ee03dddb5aaff513bd52db1adffd7b6bd175243d00e1c4cdbd0b",
}


def full_settings(renderer, given: dict) -> dict:
    """The renderer's declared defaults with ``given`` over them, as the render path hands them in."""
    declared = {s.name: s.default for s in renderer.settings}
    assert set(given) <= set(declared), set(given) - set(declared)
    return declared | given


def image_hash(result) -> str:
    data = np.ascontiguousarray(result.image, np.float32).tobytes()
    if result.variance is not None:
        data += np.ascontiguousarray(result.variance, np.float32).tobytes()
    return hashlib.sha256(data).hexdigest()


def render_case(case):
    name, scene_name, width, spp, seed, settings = case
    scene = resolve_scene(scene_name)
    cam = scene.camera
    scene = scene.with_resolution(width, max(1, round(width * cam.height / cam.width)))
    renderer = RENDERERS[name](threads=2)
    return renderer.render(scene, spp, seed, settings=full_settings(renderer, dict(settings)))


@pytest.mark.parametrize("case", sorted(PINNED, key=str), ids=lambda c: f"{c[0]}-{c[1]}-{c[2]}px-{c[3]}spp-seed{c[4]}")
def test_image_is_bit_identical_to_the_pinned_one(case):
    assert image_hash(render_case(case)) == PINNED[case]
