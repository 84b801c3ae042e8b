"""The Mitsuba 3 export renders bit for bit as the Mitsuba adapter does, from Python and from the ``mitsuba`` executable.

Like with like: the adapter (``src/cornell_harness/renderers/mitsuba3.py``) renders in passes (:func:`cornell_harness.adapters.api.spp_passes`:
1, 1, 2, 4, ... samples), pass ``k`` calling ``mi.render(scene, spp=n, seed=pass_seed(seed, k))`` on the
dictionary scene, and averages them in float64. The exported file's sampler has ``seed = $seed``, to which
Mitsuba adds the seed ``mi.render`` is given (0 by default and from the executable). So

- one pass (spp 1): the file loaded with ``seed = pass_seed(seed, 0)`` and rendered plainly (or run by the
  ``mitsuba`` executable with ``-D seed=...``) is the adapter's image;
- several passes: the file loaded with seed 0 and rendered pass by pass with the adapter's pass seeds,
  accumulated by the adapter's own :func:`cornell_harness.renderers.mitsuba3.run_passes`, is the adapter's image.

Both are asserted bit for bit (same variant, ``llvm_ad_rgb`` here: :func:`cornell_harness.renderers.mitsuba3._select_variant`).
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from cornell_harness.adapters.api import pass_seed
from cornell_harness.scenes.export import export_scene
from cornell_harness.scenes.export import mitsuba as export_mitsuba
from cornell_harness.scenes.export.ply import read_ply
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.model import SceneError
from cornell_harness.store.exr import read_exr
from cornell_harness.renderers import mitsuba3
from cornell_harness.renderers.mitsuba3 import Mitsuba3

mi = pytest.importorskip("mitsuba")

RES = 32
SCENES = ["cornell-box", "cornell-box-caustics"]


@pytest.fixture(scope="module")
def variant() -> str:
    return Mitsuba3().variant()[0]  # sets the adapter's variant: mi.load_file below runs in it


def small(name: str):
    return resolve_scene(name).with_resolution(RES, RES)


@pytest.mark.parametrize("name", SCENES)
def test_the_export_renders_one_pass_as_the_adapter(tmp_path, variant, name):
    scene, seed = small(name), 11
    xml = export_scene(scene, "mitsuba", tmp_path)
    ours = Mitsuba3().render(scene, 1, seed).image
    loaded = mi.load_file(str(xml), spp=1, seed=pass_seed(seed, 0))
    theirs = np.asarray(mi.render(loaded), dtype=np.float32)
    assert ours.mean() > 0.01  # a real image, not two black ones
    np.testing.assert_array_equal(theirs, ours)


@pytest.mark.parametrize("name", SCENES)
def test_the_export_renders_many_passes_as_the_adapter(tmp_path, variant, name):
    scene, spp, seed = small(name), 8, 5  # passes of 1, 1, 2, 4 samples
    xml = export_scene(scene, "mitsuba", tmp_path)
    ours = Mitsuba3().render(scene, spp, seed).image
    loaded = mi.load_file(str(xml), spp=spp)  # file seed 0 (its default): each pass adds its own

    def sums(n: int, s: int):
        return (np.asarray(mi.render(loaded, spp=n, seed=s), dtype=np.float64) * n,)

    per_pass = max(1, mitsuba3.MAX_SAMPLES_PER_PASS // (RES * RES))
    _, theirs, *_ = mitsuba3.run_passes(spp, seed, per_pass, (), sums, lambda acc, n: (acc[0] / n).astype(np.float32))
    np.testing.assert_array_equal(theirs, ours)
    # and a different seed gives a different image: the comparison can fail
    assert not np.array_equal(Mitsuba3().render(scene, spp, seed + 1).image, ours)


def mitsuba_executable() -> Path:
    exe = Path(sys.executable).parent / "mitsuba"
    if not exe.exists():
        pytest.skip(f"no mitsuba executable beside {sys.executable}")
    return exe


def test_the_mitsuba_executable_renders_the_export_as_the_adapter(tmp_path, variant):
    """``mitsuba DIR/scene.xml -o out.exr -D spp=1 -D seed=S`` (the executable picks llvm_ad_rgb, as the adapter)."""
    scene, seed = small("cornell-box-caustics"), 3
    xml = export_scene(scene, "mitsuba", tmp_path / "export")
    out = tmp_path / "out.exr"
    env = {**os.environ, "DRJIT_LIBLLVM_PATH": os.environ.get("DRJIT_LIBLLVM_PATH") or mitsuba3.find_llvm()[0] or ""}
    run = subprocess.run([str(mitsuba_executable()), str(xml), "-o", str(out), "-D", "spp=1",
                          "-D", f"seed={pass_seed(seed, 0)}"], capture_output=True, text=True, timeout=120, env=env)
    assert run.returncode == 0, run.stderr[-2000:]
    if variant not in run.stdout + run.stderr:
        pytest.skip(f"the executable rendered in another variant than the adapter's {variant}")
    np.testing.assert_array_equal(read_exr(out)[..., :3], Mitsuba3().render(scene, 1, seed).image)


def test_the_file_declares_its_defaults_and_the_scene_settings(tmp_path):
    scene = small("cornell-box-caustics").with_max_depth(4)
    xml = export_scene(scene, "mitsuba", tmp_path)
    root = ET.parse(xml).getroot()
    assert root.tag == "scene" and root.get("version") == "3.0.0"
    defaults = {d.get("name"): d.get("value") for d in root.findall("default")}
    assert defaults == {"spp": str(export_mitsuba.DEFAULT_SPP), "seed": "0", "resx": str(RES), "resy": str(RES)}
    assert root.find("integrator").get("type") == "path"
    assert root.find("integrator/integer[@name='max_depth']").get("value") == "4"
    sensor = root.find("sensor")
    assert sensor.find("film/rfilter").get("type") == "box"
    assert sensor.find("film/integer[@name='width']").get("value") == "$resx"
    assert sensor.find("sampler").get("type") == "independent"
    assert sensor.find("sampler/integer[@name='seed']").get("value") == "$seed"
    shapes = root.findall("shape")
    plys = [s for s in shapes if s.get("type") == "ply"]
    assert len(plys) == len(scene.meshes) and len(shapes) == len(scene.meshes) + len(scene.spheres)
    assert all(s.find("boolean[@name='face_normals']").get("value") == "true" for s in plys)
    assert [len(s.findall("emitter")) for s in plys] == [int(m.is_emitter) for m in scene.meshes]
    for shape, mesh in zip(plys, scene.meshes):  # every mesh, in the unit frame, as the adapter has it
        v, t = read_ply(tmp_path / shape.find("string[@name='filename']").get("value"))
        np.testing.assert_array_equal(v, export_mitsuba.unit_vertices(scene, mesh).astype(np.float64))
        np.testing.assert_array_equal(t, mesh.triangles)


def test_names_that_xml_or_mitsuba_would_misread_are_written_safely(tmp_path, variant):
    """A material named like a ``$`` parameter, names with ``--`` (ends an XML comment) or a newline."""
    scene = small("cornell-box")
    odd = {"white": "$spp", "red": "r--e\nd"}
    scene = dataclasses.replace(
        scene, name="x---y", materials={odd.get(k, k): dataclasses.replace(m, name=odd.get(k, k))
                                        for k, m in scene.materials.items()},
        meshes=tuple(dataclasses.replace(m, name=m.name + "/--$seed", material=odd.get(m.material, m.material))
                     for m in scene.meshes))
    xml = export_scene(scene, "mitsuba", tmp_path)
    ET.parse(xml)
    loaded = mi.load_file(str(xml), spp=1, seed=pass_seed(2, 0))
    np.testing.assert_array_equal(np.asarray(mi.render(loaded), dtype=np.float32), Mitsuba3().render(scene, 1, 2).image)


def test_an_ambient_occlusion_scene_is_refused(tmp_path):
    with pytest.raises(SceneError, match="quantity"):
        export_scene(resolve_scene("cornell-box-ao"), "mitsuba", tmp_path / "x")
    assert not (tmp_path / "x").exists()


def test_an_unknown_plugin_is_not_written():
    with pytest.raises(ValueError, match="plugin type 'plastic'"):
        export_mitsuba.to_xml({"type": "scene", "b": {"type": "plastic"}}, {})


def test_a_spectral_scene_exports_its_spectra_and_renders_as_the_adapter(tmp_path):
    """cornell-box-measured: the file holds the measured spectra as ``irregular`` plugins (the light's flat surface
    padded to 360-830 nm), the emission times the film's rescale, and in the spectral variant renders one pass bit
    for bit as the adapter."""
    scene, seed = small("cornell-box-measured"), 7
    xml = export_scene(scene, "mitsuba", tmp_path)
    root = ET.parse(xml).getroot()
    spectra = {e.get("name"): e for e in root.iter("spectrum")}
    assert len(list(root.iter("spectrum"))) == 5 and not list(root.iter("rgb"))
    waves = [float(x) for x in spectra["radiance"].find("string[@name='wavelengths']").get("value").split(",")]
    assert waves == [400.0, 500.0, 600.0, 700.0]
    flat = [e for e in root.iter("spectrum") if e.find("string[@name='values']").get("value") == "0.78, 0.78, 0.78, 0.78"]
    assert len(flat) == 1 and flat[0].find("string[@name='wavelengths']").get("value") == "360.0, 400.0, 700.0, 830.0"
    ours = Mitsuba3().render(scene, 1, seed)
    assert ours.info["variant"].endswith("_spectral")
    loaded = mi.load_file(str(xml), spp=1, seed=pass_seed(seed, 0))
    theirs = np.asarray(mi.render(loaded), dtype=np.float32)
    assert ours.image.mean() > 0.01
    np.testing.assert_array_equal(theirs, ours.image)
    (tmp_path / "rgb").mkdir()
    rgb = export_mitsuba.write(scene, tmp_path / "rgb", spectral=False)
    assert not list(ET.parse(rgb).getroot().iter("spectrum"))
    Mitsuba3().variant()  # back to the RGB variant the module's other tests load files in


def test_a_spectral_export_carries_the_films_rescale_and_names_its_variant(tmp_path):
    """The light's values are the scene's times 1 / (Mitsuba's MI_CIE_Y_NORMALIZATION · colour-science's Σȳ),
    computed here from colour-science's table; reflectances are not scaled; the printed command names the variant."""
    import colour

    scene = small("cornell-box-measured")
    xml = export_scene(scene, "mitsuba", tmp_path)
    def values(e) -> list[float]:
        return [float(x) for x in e.find("string[@name='values']").get("value").split(",")]

    spectra = list(ET.parse(xml).getroot().iter("spectrum"))
    (written,) = [values(e) for e in spectra if e.get("name") == "radiance"]
    y_sum = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].values[:, 1].sum()
    scale = 1.0 / (export_mitsuba.MI_CIE_Y_NORMALIZATION * y_sum)
    assert scale == pytest.approx(0.999002, abs=1e-6)  # 0.1%: the walls' z of +4.5 at 512 spp without it
    np.testing.assert_allclose(written, np.array(scene.spectral.spectra["light"].values) * scale, rtol=1e-15)
    reflectances = {tuple(values(e)[-2:]) for e in spectra if e.get("name") == "reflectance"}
    assert reflectances == {tuple(s.values[-2:]) for n, s in scene.spectral.spectra.items() if n != "light"}
    command = export_mitsuba.render_command(scene, xml)
    assert command.startswith(f"mitsuba -m llvm_ad_spectral {xml} -o ") and "scalar_spectral" in command
    assert export_mitsuba.render_command(small("cornell-box"), xml).startswith(f"mitsuba {xml} -o ")


#: Samples per pixel of the executable's render of the spectral export: enough that the missing 0.1% rescale moves
#: the walls' mean by about 4.5 standard errors (z computed by the harness's scorer against the stored reference).
SPECTRAL_SPP = 512
#: |z| above this in any region (or the image's mean) fails: two-sided 6.3e-5 per region for a Gaussian z, and
#: the scorer's z is conservative (channels bounded as fully correlated), so at most 4.5e-4 over 6 regions + image.
SPECTRAL_Z = 4.0


@pytest.mark.slow
def test_the_mitsuba_executable_renders_the_spectral_export_within_noise_of_the_reference(tmp_path):
    """``cbox export`` of cornell-box-measured, then the command it prints (``mitsuba -m llvm_ad_spectral``) at
    512 spp, scored against the stored reference: every region's mean z and the image's within ±4. The same
    image without the rescale (divided by it: images are linear in the emission) fails, so the check can."""
    from cornell_harness.evaluate.regions import region_masks
    from cornell_harness.evaluate.score import score_image
    from cornell_harness.store.references import load_reference

    scene = resolve_scene("cornell-box-measured")
    xml = export_scene(scene, "mitsuba", tmp_path / "export")
    out = tmp_path / "x.exr"
    env = {**os.environ, "DRJIT_LIBLLVM_PATH": os.environ.get("DRJIT_LIBLLVM_PATH") or mitsuba3.find_llvm()[0] or ""}
    variant = export_mitsuba.SPECTRAL_VARIANTS[0 if env["DRJIT_LIBLLVM_PATH"] else 1]  # the command's, or its fallback
    assert variant in export_mitsuba.render_command(scene, xml)
    run = subprocess.run([str(mitsuba_executable()), "-m", variant, str(xml), "-o", str(out), "-D",
                          f"spp={SPECTRAL_SPP}", "-D", "seed=5"], capture_output=True, text=True, timeout=900, env=env)
    assert run.returncode == 0, run.stderr[-2000:]
    reference, masks = load_reference(scene), region_masks(scene)
    image = read_exr(out)[..., :3].astype(np.float64)

    def zs(img) -> dict:
        result = score_image(img, reference, SPECTRAL_SPP, masks=masks, with_flip=False)
        return {r: v["mean_z"] for r, v in result.regions.items()} | {"image": result.noise["noise_mean_radiance_z"]}

    scored = zs(image)
    assert set(scored) == {"walls", "blocks", "floor", "light", "bleed-red", "bleed-green", "image"}
    assert all(abs(z) < SPECTRAL_Z for z in scored.values()), scored
    unscaled = zs(image / export_mitsuba.spectral_scale())
    assert max(abs(z) for z in unscaled.values()) > SPECTRAL_Z, unscaled
