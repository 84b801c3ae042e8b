"""The toolkit's closest-hit query (:func:`cornell_harness.renderers.core.embree.closest_triangles`) asked as
coherent rays, as the path tracer asks its camera rays: 16-ray packets with Embree's coherent flag.

The flag changes no hit but where a ray meets the edge two triangles share at one distance; there Embree's
coherent traversal may name the other triangle. Such a ray is the proof that the flag reaches Embree: camera
ray 311243 of the path tracer's first pass on ``cornell-box`` (seed 0, the default sampler) lies on the
diagonal of the quad of triangles 6 and 7, and the two queries break the tie differently (Embree 4.4 as
embreex bundles it; ``benchmarks/embree_floor.py`` finds 2 such rays in a million camera rays).
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("embreex")

from cornell_harness.renderers.core import embree  # noqa: E402
from cornell_harness.renderers.core.camera import camera_basis, camera_rays  # noqa: E402
from cornell_harness.renderers.core.embree import COHERENT_PACKET, EmbreeScene, closest_triangles, ray_record  # noqa: E402
from cornell_harness.renderers.core.rays import ray_buffer  # noqa: E402
from cornell_harness.renderers.core.sampler import SAMPLER_SETTING, pass_stream  # noqa: E402
from cornell_harness.scenes.library import resolve_scene  # noqa: E402
from cornell_harness.scenes.model import triangle_arrays  # noqa: E402

TIED_RAY = 311243  # on the shared edge of triangles 6 and 7 (one quad of cornell-box), at one distance


@pytest.fixture(scope="module")
def box():
    scene = resolve_scene("cornell-box")
    tri = triangle_arrays(scene)
    return scene, EmbreeScene(tri["vertices"].astype(np.float32), tri["triangles"])


def first_pass_camera_rays(scene, first: int, n: int):
    """Camera rays of paths first .. first+n-1 of the path tracer's first pass, seed 0, as Embree gets them."""
    cam = scene.camera
    pixels = cam.width * cam.height
    rays = ray_buffer(n)
    camera_rays(camera_basis(cam), cam.width, cam.height, first, pixels,
                pass_stream(SAMPLER_SETTING.default, 0, 0, pixels, 0), rays)
    return rays.o32, rays.d32


def test_the_coherent_flag_reaches_embree(box):
    scene, scene_embree = box
    first = TIED_RAY // COHERENT_PACKET * COHERENT_PACKET  # the packet the path tracer's unit puts it in
    o, d = first_pass_camera_rays(scene, first, COHERENT_PACKET)
    default, coherent = np.empty(COHERENT_PACKET, np.int32), np.empty(COHERENT_PACKET, np.int32)
    closest_triangles(scene_embree.handle, o, d, default, ray_record())
    closest_triangles(scene_embree.handle, o, d, coherent, ray_record(), True)
    k = TIED_RAY - first
    assert {default[k], coherent[k]} == {6, 7}  # the two triangles of one quad: the tie broken both ways
    assert np.array_equal(np.delete(default, k), np.delete(coherent, k))  # every other ray: the same triangle


def test_any_batch_length_and_width_leave_the_coherent_arguments_as_they_were(box):
    """A batch ending in a part-filled packet answers its rays as a longer batch does, and neither packet width
    writes over the coherent call's arguments, which the record holds from its making on."""
    scene, scene_embree = box
    cam = scene.camera
    middle = cam.width * cam.height // 2 + cam.width // 4  # the middle row from a quarter in: every ray hits
    o, d = first_pass_camera_rays(scene, middle, 4 * COHERENT_PACKET)
    rec = ray_record()
    arguments = rec[embree._ARGS:].copy()
    whole, part = np.empty(len(o), np.int32), np.empty(len(o) - 3, np.int32)
    closest_triangles(scene_embree.handle, o, d, whole, rec, True)
    closest_triangles(scene_embree.handle, o[:part.size], d[:part.size], part, rec, True)
    assert np.array_equal(part, whole[:part.size]) and np.all(whole >= 0)
    closest_triangles(scene_embree.handle, o, d, whole, rec)
    assert np.array_equal(rec[embree._ARGS:], arguments) and arguments[0] == 1 << 16
