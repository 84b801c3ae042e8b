"""Mitsuba 3 adapter: LLVM detection, scene conversion, agreement with the stored reference."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import CORNELL
from cornell_harness.evaluate import noise as stats
from cornell_harness.store.references import load_reference
from cornell_harness.scenes.export.mitsuba import bsdf_dict
from cornell_harness.scenes.loader import load_scene
from cornell_harness.scenes.transforms import unit_frame
from cornell_harness.renderers import mitsuba3
from cornell_harness.renderers.mitsuba3 import Mitsuba3

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

    The z-score uses the reference's variance image (see cornell_harness.evaluate.noise); the
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


CAUSTICS = CORNELL.parent.parent / "cornell-box-caustics" / "scene.toml"
#: Mitsuba stores the converted scene in float32: ~1e-7 relative in the unit frame, ~1e-6 scene units back.
F32_SCENE = 1e-5


def _bsdf_kind(bsdf) -> str:
    """Mitsuba's plugin class of a loaded BSDF, from its description (``SmoothDiffuse[...]``)."""
    return str(bsdf).split("[", 1)[0]


def test_caustics_scene_conversion():
    """cornell-box-caustics in Mitsuba: each sphere's centre and radius, each shape's BSDF type and parameters.

    Shapes are found by the ids ``scene_dict`` gives them (``mesh_i``,
    ``sphere_i``); sphere geometry is mapped back from the unit frame
    (:func:`cornell_harness.scenes.transforms.unit_frame`) to scene units.
    """
    from cornell_harness.scenes.materials import Dielectric, Diffuse, Mirror

    scene = load_scene(CAUSTICS)
    Mitsuba3().variant()
    centre, k = unit_frame(scene)
    shapes = {sh.id(): sh for sh in mi.load_dict(mitsuba3.scene_dict(scene, 4)).shapes()}
    objects = {f"mesh_{i}": m for i, m in enumerate(scene.meshes)}
    objects |= {f"sphere_{i}": s for i, s in enumerate(scene.spheres)}
    assert sorted(shapes) == sorted(objects)
    for sid, obj in objects.items():
        sh = shapes[sid]
        material = scene.materials[obj.material]
        if sid.startswith("sphere"):
            assert not sh.is_mesh()
            lo, hi = np.ravel(sh.bbox().min), np.ravel(sh.bbox().max)
            np.testing.assert_allclose((lo + hi) / 2 / k + centre, obj.center, atol=F32_SCENE, err_msg=sid)
            np.testing.assert_allclose((hi - lo) / 2 / k, [obj.radius] * 3, atol=F32_SCENE, err_msg=sid)
        else:
            assert sh.is_mesh()
            verts = np.asarray(mi.traverse(sh)["vertex_positions"], dtype=np.float64).reshape(-1, 3)
            np.testing.assert_allclose(verts / k + centre, obj.vertices, atol=F32_SCENE, err_msg=sid)
        bsdf = sh.bsdf()
        params = mi.traverse(bsdf)
        if isinstance(material, Diffuse):
            assert _bsdf_kind(bsdf) == "SmoothDiffuse", sid
            np.testing.assert_allclose(np.ravel(params["reflectance.value"]), material.reflectance, rtol=1e-6)
        elif isinstance(material, Mirror):
            assert _bsdf_kind(bsdf) == "SmoothConductor", sid
            np.testing.assert_allclose(np.ravel(params["specular_reflectance.value"]), material.reflectance, rtol=1e-6)
        else:
            assert isinstance(material, Dielectric)
            assert _bsdf_kind(bsdf) == "SmoothDielectric", sid
            assert params["eta"] == pytest.approx(material.int_ior / material.ext_ior, rel=1e-6)
    kinds = {_bsdf_kind(shapes[sid].bsdf()) for sid in objects}
    assert kinds == {"SmoothDiffuse", "SmoothConductor", "SmoothDielectric"}


@pytest.mark.parametrize("cos", [0.95, 0.6, 0.2, -0.2, -0.6, -0.95])
def test_mitsuba_specular_bsdfs_sample_as_ours(cos):
    """Mitsuba's conductor (material "none") and dielectric, as ``bsdf_dict`` makes them, sample as ours do.

    In Mitsuba's local frame (normal +z): the mirror's weight is its
    reflectance at every angle (Fresnel factor 1) and nothing from behind; the
    dielectric reflects with probability R (our Fresnel) with weight 1, and
    refracts with weight η_ti² in the direction of our ``refract``, also from
    inside and past the critical angle. float32 in Mitsuba: rtol 1e-5.
    """
    import math

    from cornell_harness.scenes.materials import Dielectric, Mirror
    from cornell_harness.renderers.core.bsdf import dielectric_sample, fresnel_dielectric

    Mitsuba3().variant()
    import drjit as dr

    wi = (math.sqrt(1 - cos * cos), 0.0, cos)  # Mitsuba's si.wi: towards the viewer, our ωo
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(*wi)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
    ctx = mi.BSDFContext()

    rho = (0.95, 0.5, 0.2)
    mirror = mi.load_dict(bsdf_dict(Mirror("m", rho)))
    _, w = mirror.sample(ctx, si, 0.5, mi.Point2f(0.5, 0.5))
    np.testing.assert_allclose(np.ravel(w), rho if cos > 0 else (0.0, 0.0, 0.0), rtol=1e-5, atol=1e-7)

    glass = mi.load_dict(bsdf_dict(Dielectric("g", 1.5, 1.0)))
    r = fresnel_dielectric(cos, 1.5)[0]
    for u in (0.001, 0.999):
        bs, w = glass.sample(ctx, si, u, mi.Point2f(0.5, 0.5))
        ours, _, weight, ok = dielectric_sample(wi, (0.0, 0.0, 1.0), cos, 1.5, u)
        assert ok
        assert float(np.ravel(bs.pdf)[0]) == pytest.approx(r if u < r else 1.0 - r, rel=1e-5)
        np.testing.assert_allclose(np.ravel(w), [weight] * 3, rtol=1e-5)
        np.testing.assert_allclose(np.ravel(bs.wo), ours, atol=1e-6)


def test_bsdf_dict_refuses_an_unknown_material():
    from dataclasses import dataclass

    @dataclass(frozen=True)
    class Plastic:
        name: str

    with pytest.raises(ValueError, match="material 'shiny': Plastic has no Mitsuba translation"):
        bsdf_dict(Plastic("shiny"))
