"""benchmarks/embree_floor.c, the floor of a ray query: it builds, runs, and answers the question ours answers.

``benchmarks/embree_floor.py`` times Embree's own calls from C against the toolkit's query
(:func:`cornell_harness.renderers.core.embree.closest_triangles`) on the rays our path tracer traces. The floor
means something only if the C program does the same work: the same scene, the same rays, the same hits. Here
it is compiled (``cc``, which ``scripts/setup.sh --tests`` installs), run on a few thousand camera and
first-bounce rays of ``cornell-box``, and its answers in every configuration are checked against ours
(:func:`benchmarks.embree_floor.check_agreement`), which must also reject answers that differ.
"""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from benchmarks import embree_floor as ef
from cornell_harness.renderers.core.embree import EmbreeScene, closest_triangles, ray_record
from cornell_harness.scenes.library import resolve_scene

RAYS = 2048


@pytest.fixture(scope="module")
def floor(tmp_path_factory):
    if shutil.which("cc") is None:
        pytest.fail("no C compiler (cc) on PATH: scripts/setup.sh --tests installs one")
    tmp = tmp_path_factory.mktemp("floor")
    scene = resolve_scene("cornell-box")
    program = ef.build(tmp)
    embree = EmbreeScene(*ef.scene_arrays(scene))
    out = {}
    for batch, (o, d) in ef.ray_batches(scene, RAYS).items():
        path = tmp / f"{batch}.bin"
        ef.write_batch(path, scene, o, d)
        timings = ef.run_floor(program, path, 2, tmp / f"{batch}-hits.bin")
        prim = np.empty(len(o), np.int32)
        closest_triangles(embree.handle, o, d, prim, ray_record())
        out[batch] = (o, d, prim, timings, ef.read_hits(tmp / f"{batch}-hits.bin", len(o)))
    return scene, out


def test_the_batches_are_the_path_tracers_camera_and_bounce_rays(floor):
    _, out = floor
    camera_o, _, camera_prim, _, _ = out["camera"]
    bounce_o, bounce_d, _, _, _ = out["bounce"]
    assert len(camera_o) == RAYS and 0 < len(bounce_o) <= RAYS
    assert np.ptp(camera_o, axis=0).max() == 0.0  # a pinhole: every camera ray leaves the eye
    assert 0.25 < np.mean(camera_prim >= 0) < 1.0  # the image's top rows: the box's ceiling, and beyond it
    assert np.ptp(bounce_o, axis=0).min() > 0.0 and np.allclose(np.linalg.norm(bounce_d, axis=1), 1, atol=1e-6)


def test_the_c_program_times_every_configuration(floor):
    _, out = floor
    for _, _, _, timings, _ in out.values():
        assert timings.pop("device").startswith("embree 4")
        assert set(timings) == {(*c, t) for c in ef.CONFIGS for t in (1, 2)}
        assert all(wall > 0 and cpu > 0 for wall, cpu in timings.values())


def test_the_c_program_hits_what_our_query_hits(floor):
    scene, out = floor
    for o, d, prim, _, hits in out.values():
        differ = ef.check_agreement(scene, o, d, prim, hits)
        assert all(differ[c] == 0 for c in ef.CONFIGS if c[0] == "robust" and not c[2])


def test_our_coherent_camera_query_is_the_c_programs_coherent_call(floor):
    _, out = floor
    o, d, _, _, hits = out["camera"]
    embree = EmbreeScene(*ef.scene_arrays(resolve_scene("cornell-box")))
    ef.check_coherent(embree.handle, o, d, hits)
    wrong = dict(hits)
    t, p = hits["robust", 16, 1]
    wrong["robust", 16, 1] = (t, np.where(np.arange(len(p)) == np.flatnonzero(p >= 0)[0], p + 1, p))
    with pytest.raises(AssertionError):
        ef.check_coherent(embree.handle, o, d, wrong)


@pytest.mark.parametrize("change", ["other triangle", "farther", "missed"])
def test_the_agreement_check_rejects_other_answers(floor, change):
    scene, out = floor
    o, d, prim, _, hits = out["bounce"]
    t, p = (a.copy() for a in hits["robust", 8, 0])
    i = int(np.flatnonzero(prim >= 0)[0])
    if change == "other triangle":
        p[i] = (p[i] + 1) % len(ef.scene_arrays(scene)[1])
    elif change == "farther":
        t[i] *= 1.001
    else:
        p[i] = -1
    with pytest.raises(AssertionError):
        ef.check_agreement(scene, o, d, prim, {**hits, ("robust", 8, 0): (t, p)})
