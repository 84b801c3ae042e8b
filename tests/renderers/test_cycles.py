"""The cycles renderer: every Cycles default that would break agreement, set and read back from Blender; the
bounce convention and Cycles' own Russian roulette against the furnace's closed form; the unjittered first
sample left out; and a deliberate error in the scene Cycles renders (glass IOR 1.33) failing against a Mitsuba
reference that the right scene passes.

Every render runs Blender in a child process (bpy is never imported here: src/cornell_harness/renderers/cycles.py).
scripts/setup.sh --tests installs bpy, so these run in CI.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
import pytest

from cornell_harness.adapters.registry import resolve
from cornell_harness.evaluate.reference_agreement import reference_agreement
from cornell_harness.evaluate.regions import region_masks
from cornell_harness.scenes.analytic import furnace_radiance, furnace_scene
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.model import SceneError
from cornell_harness.store.references import load_reference
from cornell_harness.workflows.reference_build import build_reference
from cornell_harness.workflows.reference_verify import verify_reference
from cornell_harness.renderers import cycles as cycles_module
from cornell_harness.renderers.cycles import Cycles

if Cycles().unavailable_reason():
    pytest.skip(Cycles().unavailable_reason(), allow_module_level=True)


def test_every_default_that_breaks_agreement_is_set(monkeypatch):
    monkeypatch.setenv("CBOX_THREADS", "1")
    result = Cycles().render(furnace_scene(0.8, max_depth=5, res=8), 4, 1, settings={"batches": 2})
    info = result.info
    cyc = info["cycles"]
    assert info["blender"] == Cycles().version() == "5.0.1" and info["batches"] == 3 and info["threads"] == 1
    assert (info["view_transform"], info["look"], info["exposure"], info["gamma"]) == ("Standard", "None", 0.0, 1.0)
    assert info["exr"] == {"color_depth": "32", "colorspace": "Linear Rec.709", "codec": "ZIP"}
    assert info["working_space"] == "Linear Rec.709" and info["dither_intensity"] == 0.0
    assert not cyc["use_denoising"] and not cyc["use_adaptive_sampling"] and not cyc["use_guiding"]
    assert cyc["sample_clamp_direct"] == 0.0 and cyc["sample_clamp_indirect"] == 0.0
    assert cyc["blur_glossy"] == 0.0 and cyc["caustics_reflective"] and cyc["caustics_refractive"]
    assert cyc["light_sampling_threshold"] == 0.0 and cyc["film_exposure"] == 1.0
    assert (cyc["pixel_filter_type"], cyc["filter_width"]) == ("BOX", 1.0)
    # max_depth 5 (segments) is 3 bounces after the first hit, for every kind of bounce.
    assert {cyc[k] for k in ("max_bounces", "diffuse_bounces", "glossy_bounces", "transmission_bounces",
                             "volume_bounces", "transparent_max_bounces")} == {3}
    # 4 spp are batches of 1, 1 and 2 (batch_plan); the last is samples 1 and 2 of 3: sample 0 (the pixel's centre) left out.
    assert (cyc["use_sample_subset"], cyc["sample_offset"], cyc["sample_subset_length"], cyc["samples"]) == \
        (True, 1, 2, 3)
    assert info["world"] == {"color": [0.0, 0.0, 0.0, 1.0], "strength": 0.0}
    assert info["resolution"] == [8, 8, 100] and not info["film_transparent"]
    assert info["camera"]["sensor_fit"] == "HORIZONTAL" and info["camera"]["type"] == "PERSP"
    assert info["materials"] == {"grey:box": "FRONT"}  # the emitter's light sampling: its front only
    assert result.variance is not None and result.image.shape == (8, 8, 3)


@pytest.mark.parametrize(("max_depth", "bounces"), [(2, 0), (3, 1), (40, 38), (-1, 1024), (5000, 1024)])
def test_max_depth_counts_segments_and_cycles_bounces_after_the_first_hit(max_depth, bounces):
    assert cycles_module.max_bounces(furnace_scene(0.8, max_depth=max_depth)) == bounces


def test_max_depth_1_is_refused_naming_the_field():
    with pytest.raises(SceneError, match="render.max_depth.*max_depth 1"):
        cycles_module.max_bounces(furnace_scene(0.8, max_depth=1))


@pytest.mark.parametrize("max_depth", [2, 4, -1])
def test_the_furnace_gives_its_closed_form(max_depth, monkeypatch):
    """Albedo 0.8, every face emitting 1: Le Σ_{k<D} ρ^k (1.8, 2.952; 5 unbounded, where Cycles' own roulette
    ends the paths). Wrong by one bounce is 0.64 or more away; the standard error is about 0.002."""
    monkeypatch.setenv("CBOX_THREADS", "2")
    result = Cycles().render(furnace_scene(0.8, max_depth=max_depth, res=16), 256, 3, settings={"batches": 8})
    exact = furnace_radiance(0.8, 1.0, max_depth)
    mean = result.image.astype(np.float64).mean(axis=(0, 1))
    se = np.sqrt(result.variance.astype(np.float64).sum(axis=(0, 1))) / result.image[..., 0].size
    z = (mean - exact) / se
    assert np.all(np.abs(z) < 4), (mean, exact, se)


def test_a_render_leaves_no_temporary_file(tmp_path, monkeypatch):
    """Blender makes a ``blender_*`` folder in the temporary directory, which a child ending by ``os._exit`` never
    removes: the child's temporary directory is the run's own folder, removed with it."""
    outer = tmp_path / "tmp"
    outer.mkdir()
    monkeypatch.setenv("TMPDIR", str(outer))
    monkeypatch.setattr(tempfile, "tempdir", str(outer))
    monkeypatch.setenv("CBOX_THREADS", "1")
    Cycles().render(furnace_scene(0.5, max_depth=2, res=4), 2, 0)
    assert cycles_module._child_version()
    assert sorted(p.name for p in outer.iterdir()) == []


def test_no_sample_sits_at_the_pixel_centre(tmp_path, monkeypatch):
    """Cycles puts sample 0 of every render at the pixel's centre, whatever the seed: 32 renders of 1 spp would
    all see the same point of each pixel. The light's edge pixels (10% to 90% lit, in the 256-spp render) show it:
    at the centre they read 1% or 200% of their mean radiance (measured), with the sample left out the same."""
    monkeypatch.setenv("CBOX_THREADS", "2")
    scene = resolve_scene("cornell-box", ["camera.resolution=64,64"])
    cycles_module.write_plan(scene, tmp_path, [(1, 100 + k) for k in range(32)] + [(256, 7)], 2)
    cycles_module.run_child(tmp_path)
    ones = np.mean([cycles_module.read_exr(tmp_path / f"batch-{k}.exr") for k in range(32)], axis=0)
    many = cycles_module.read_exr(tmp_path / "batch-32.exr")
    light = scene.meshes[[m.name for m in scene.meshes].index("light")].radiance[0]
    edge = (many[..., 0] > 0.1 * light) & (many[..., 0] < 0.9 * light)
    assert edge.sum() >= 10
    ratio = ones[edge, 0].sum() / many[edge, 0].sum()
    assert 0.9 < ratio < 1.1, ratio


def test_a_failing_child_is_one_error_quoting_its_line(tmp_path):
    cycles_module.write_plan(furnace_scene(0.8, res=4), tmp_path, [(1, 1)], 1)
    plan = json.loads((tmp_path / "plan.json").read_text())
    plan["materials"]["grey"]["type"] = "velvet"
    (tmp_path / "plan.json").write_text(json.dumps(plan))
    with pytest.raises(RuntimeError, match=r"status 2: cycles: ValueError: material 'grey:box': type 'velvet'"):
        cycles_module.run_child(tmp_path)


# ------------------------------------------------- power: a wrong scene against a Mitsuba reference

SMALL = ["camera.resolution=64,64"]
REF_SPP, CYCLES_SPP, BATCHES = 1024, 512, 8


def _caustics(*overrides: str):
    return resolve_scene("cornell-box-caustics", [*SMALL, *overrides])


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """cornell-box-caustics at 64², built with Mitsuba (1024 spp, 8 batches): the right scene's reference."""
    (mitsuba,) = resolve(["mitsuba"])
    if not mitsuba.available:
        pytest.skip(f"mitsuba unavailable: {mitsuba.reason}")
    folder = Path(tmp_path_factory.mktemp("ref"))
    build_reference(_caustics(), REF_SPP, BATCHES, mitsuba, folder=folder)
    return load_reference(_caustics(), folder)


def _agreement(reference, rendered):
    """Cycles' render of ``rendered`` (512 spp in 8 batches, one child) judged against the right scene's
    reference, region by region."""
    result = Cycles().render(rendered, CYCLES_SPP, 2_000_000_000, settings={"batches": BATCHES})
    return reference_agreement(reference.image, reference.variance, result.image, result.variance,
                               region_masks(_caustics()))


def test_cycles_rendering_the_right_scene_agrees_with_mitsuba(reference):
    a = _agreement(reference, _caustics())
    assert a.passed, a.message()
    assert {r.name for r in a.regions} == {"whole image", "caustic", "glass-shadow", "mirror", "glass", "walls"}


def test_cycles_rendering_glass_of_ior_1_33_fails_in_the_caustic(reference):
    """Glass of IOR 1.33 focuses the caustic less: Cycles' caustic is darker than the reference's."""
    a = _agreement(reference, _caustics("materials.glass.int_ior=1.33"))
    assert not a.passed
    assert a.failures[0][0] == "caustic" and a.failures[0][2] < 0


@pytest.mark.slow
def test_cycles_rendering_a_perfect_mirror_fails_in_the_mirror(tmp_path):
    """Mirror reflectance 1.0 instead of 0.95 (5% brighter) needs more pixels: 128², as the Mitsuba power test."""
    (mitsuba,) = resolve(["mitsuba"])
    size = ["camera.resolution=128,128"]
    right = resolve_scene("cornell-box-caustics", size)
    build_reference(right, REF_SPP, BATCHES, mitsuba, folder=tmp_path)
    ref = load_reference(right, tmp_path)
    wrong = resolve_scene("cornell-box-caustics", [*size, "materials.mirror.reflectance=1,1,1"])
    result = Cycles().render(wrong, REF_SPP, 2_000_000_000, settings={"batches": BATCHES})
    a = reference_agreement(ref.image, ref.variance, result.image, result.variance, region_masks(right))
    assert not a.passed
    mirror = next(r for r in a.regions if r.name == "mirror")
    assert (mirror.p < a.level).any() and (mirror.z > 0).all()


@pytest.mark.slow
@pytest.mark.parametrize("name", ["cornell-box", "cornell-box-caustics"])
def test_the_stored_reference_passes_against_cycles(name):
    """What `cbox reference verify --scene NAME --engine cycles --spp 256 --batches 8` checks (docs/references.md)."""
    scene = resolve_scene(name)
    (engine,) = resolve(["cornell_harness.renderers.cycles:Cycles"])
    v = verify_reference(scene, load_reference(scene), engine, spp=256, batches=8)
    assert v.agreement.passed, v.agreement.message()
