"""benchmarks/pathtracer_c.c, our estimator compiled from C: it builds, and renders what our path tracer renders.

``benchmarks/pathtracer_c.py`` times the C program against our numba path tracer and Mitsuba 3 to decide
whether a compiled kernel would pay. The timing means something only if the C program does our work: here it
is compiled (``cc``, which ``scripts/setup.sh --tests`` installs) and its estimates of a few thousand paths,
and its whole image at 2 spp, are checked against our path tracer's with ``sampler = independent``, bit for
bit; and the check is shown to reject a scene file that differs from the scene (other pass keys, other depth).
No Monte Carlo verdicts: every comparison is exact, so nothing here can fail by chance.
"""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from benchmarks import pathtracer_c as pc
from cornell_harness.renderers.pathtracer import PathTracer
from cornell_harness.scenes.library import resolve_scene

PATHS = 2048
SPP = 2


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    if shutil.which("cc") is None:
        pytest.fail("no C compiler (cc) on PATH: scripts/setup.sh --tests installs one")
    tmp = tmp_path_factory.mktemp("pathtracer_c")
    scene = resolve_scene("cornell-box")
    passes = pc.pass_keys(SPP, 0)
    pc.write_scene(tmp / "scene.bin", scene, passes)
    return tmp, scene, passes, pc.build(tmp)


@pytest.mark.parametrize("pass_index, first", [(0, 0), (1, 40000)])
def test_its_estimates_are_our_kernels_bit_for_bit(built, pass_index, first):
    tmp, scene, passes, program = built
    assert pc.check_estimates(program, tmp / "scene.bin", scene, passes, pass_index, first, first + PATHS,
                              tmp) == PATHS


@pytest.mark.parametrize("change", ["other pass keys", "other max depth"])
def test_the_check_rejects_a_scene_file_that_is_not_the_scene(built, change):
    tmp, scene, passes, program = built
    path = tmp / "other.bin"
    if change == "other pass keys":
        pc.write_scene(path, scene, pc.pass_keys(SPP, 1))
    else:
        pc.write_scene(path, scene.with_max_depth(3), passes)
    with pytest.raises(AssertionError):
        pc.check_estimates(program, path, scene, passes, 0, 0, PATHS, tmp)


@pytest.mark.parametrize("threads", [1, 2])
def test_its_render_is_our_path_tracers_image(built, threads):
    tmp, scene, _, program = built
    r = pc.render_c(program, tmp / "scene.bin", scene, SPP, threads, threads == 2, tmp / "sums.bin")
    ours = PathTracer(threads=1).render(scene, SPP, 0, settings={"sampler": "independent"})
    assert r["device"].startswith("embree 4") and r["paths"] == SPP * scene.camera.width * scene.camera.height
    assert r["rays"] == ours.info["rays"] and r["cpu_s"] > 0 and (r["query_cpu_s"] > 0) == (threads == 2)
    # Exact on 2 threads too: a pixel's 2 samples are 2 passes, and a + b is the sum whether one thread's film
    # or two films merged holds them.
    np.testing.assert_array_equal(r["image"], ours.image)
    np.testing.assert_array_equal(r["variance"], ours.variance)
