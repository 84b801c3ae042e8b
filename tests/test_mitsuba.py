"""Mitsuba 3 adapter: LLVM detection, scene conversion, agreement with the stored reference."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import CORNELL
from harness.evaluate import noise as stats
from harness.store.references import load_reference
from harness.scenes.loader import load_scene
from renderers import mitsuba3
from renderers.mitsuba3 import Mitsuba3

mi = pytest.importorskip("mitsuba")

# Two-sided z-test at alpha = 0.001: a correct renderer fails it once in 1000 seeds.
Z_CRIT = 3.29


@pytest.fixture
def fresh_llvm_probe(monkeypatch):
    mitsuba3.find_llvm.cache_clear()
    yield monkeypatch
    mitsuba3.find_llvm.cache_clear()


def test_llvm_env_var_missing_file(fresh_llvm_probe, tmp_path):
    fresh_llvm_probe.setenv("DRJIT_LIBLLVM_PATH", str(tmp_path / "libLLVM.so.19.1"))
    path, note = mitsuba3.find_llvm()
    assert path is None and "does not exist" in note


def test_llvm_env_var_too_old(fresh_llvm_probe, tmp_path):
    lib = tmp_path / "libLLVM.so.15"
    lib.write_bytes(b"")
    fresh_llvm_probe.setenv("DRJIT_LIBLLVM_PATH", str(lib))
    path, note = mitsuba3.find_llvm()
    assert path is None and "LLVM 15" in note and "17 or newer" in note


def test_llvm_env_var_respected(fresh_llvm_probe, tmp_path):
    lib = tmp_path / "libLLVM-19.so"
    lib.write_bytes(b"")
    fresh_llvm_probe.setenv("DRJIT_LIBLLVM_PATH", str(lib))
    assert mitsuba3.find_llvm()[0] == str(lib)


@pytest.mark.parametrize("name, major", [("libLLVM.so.19.1", 19), ("libLLVM-17.so", 17), ("libLLVM-14.so.1", 14),
                                         ("libLLVM.so", None)])
def test_llvm_version_from_file_name(name, major):
    assert mitsuba3._llvm_major(f"/usr/lib/{name}") == major


def test_scene_is_mi_cornell_box():
    """Our cornell-box equals mi.cornell_box() shape by shape (bounding boxes), material and light."""
    scene = load_scene(CORNELL)
    Mitsuba3().variant()
    d = mi.cornell_box()
    ours = {m.name: m for m in scene.meshes}
    for name in ("floor", "ceiling", "back", "green-wall", "red-wall", "small-box", "large-box", "light"):
        shape = mi.load_dict({k: v for k, v in d[name].items() if k not in ("bsdf", "emitter")})
        bbox = shape.bbox()
        lo, hi = np.ravel(bbox.min), np.ravel(bbox.max)
        np.testing.assert_allclose(ours[name].vertices.min(0), lo, atol=2e-6, err_msg=name)
        np.testing.assert_allclose(ours[name].vertices.max(0), hi, atol=2e-6, err_msg=name)
        assert ours[name].material == d[name]["bsdf"]["id"]
        assert scene.materials[ours[name].material].reflectance == tuple(d[ours[name].material]["reflectance"]["value"])
    assert ours["light"].radiance == tuple(d["light"]["emitter"]["radiance"]["value"])
    cam = d["sensor"]
    assert scene.camera.fov_deg == cam["fov"] and scene.camera.fov_axis == cam["fov_axis"]
    assert (scene.camera.width, scene.camera.height) == (cam["film"]["width"], cam["film"]["height"])


def test_same_seed_same_image_and_checkpoints():
    scene = load_scene(CORNELL).with_resolution(32, 32)
    r = Mitsuba3()
    a = r.render(scene, 8, seed=5, checkpoints=[1, 2, 4, 8])
    b = r.render(scene, 8, seed=5)
    c = r.render(scene, 8, seed=6)
    assert np.array_equal(a.image, b.image)
    assert not np.array_equal(a.image, c.image)
    assert [k.spp for k in a.checkpoints] == [1, 2, 4, 8]
    assert np.array_equal(a.checkpoints[-1].image, a.image)
    times = [k.time_s for k in a.checkpoints]
    assert times == sorted(times)
    assert a.image.dtype == np.float32 and a.image.shape == (32, 32, 3)


def test_low_spp_render_agrees_with_stored_reference():
    """Mean radiance of a 16-spp render is within noise of the 16384-spp reference.

    The z-score uses the reference's variance image (see harness.evaluate.noise); the
    test is two-sided at alpha = 0.001. Mean radiance must also be within 1%.
    """
    scene = load_scene(CORNELL)
    ref = load_reference(scene)
    spp = 16
    img = Mitsuba3().render(scene, spp, seed=1).image
    z = stats.mean_radiance_z(img, ref.image, ref.variance, ref.spp, spp)
    assert abs(z) < Z_CRIT, z
    rel = img.mean(dtype=np.float64) / ref.image.mean(dtype=np.float64) - 1
    assert abs(rel) < 0.01, rel
