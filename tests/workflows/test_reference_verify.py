"""``cbox reference verify``'s workflow: a second engine against the stored reference, and the recorded verdict.

Power on real renders: a reference built wrong with Mitsuba (the glass's IOR 1.33 instead of 1.5; the mirror's
reflectance 1.0 instead of 0.95) fails against an independent Mitsuba render of the right scene, and one built
right passes. The scene is cornell-box-caustics at 64² (128² for the mirror, slow), seeds fixed.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from cornell_harness.adapters.registry import resolve
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.loader import load_scene
from cornell_harness.store.references import (PROVENANCE_FILE, REFERENCE_SEED_BASE, VERDICTS_FILE, load_reference,
                                              record_verdict, recorded_verdicts, verdict_line)
from cornell_harness.workflows.reference_build import build_reference
from cornell_harness.evaluate.reference_agreement import reference_agreement
from cornell_harness.evaluate.regions import region_masks
from cornell_harness.workflows.reference_verify import VERIFY_SEED_BASE, VerifyError, render_engine, verify_reference
from tests.conftest import CORNELL


def _entry(spec: str):
    (entry,) = resolve([spec])
    return entry


def test_an_independent_render_of_the_same_scene_passes_and_the_verdict_keeps_the_reference_valid(write_scene,
                                                                                                    tmp_path):
    scene = load_scene(write_scene())
    engine = _entry("tests.user_renderers:SeededNoise")
    ref = build_reference(scene, spp=64, batches=4, entry=engine)
    v = verify_reference(scene, ref, engine, spp=64, batches=4)
    assert v.agreement.passed, v.agreement.message()
    assert v.record["seeds"] == [VERIFY_SEED_BASE, VERIFY_SEED_BASE + 3]  # none of the reference's seeds
    assert VERIFY_SEED_BASE > REFERENCE_SEED_BASE + ref.provenance["batches"]
    provenance = (tmp_path / PROVENANCE_FILE).read_bytes()
    # A scene file of the user's own: the verdict goes beside its reference, whose files are not touched.
    assert record_verdict(ref.folder, v.record) == tmp_path / VERDICTS_FILE
    assert (tmp_path / PROVENANCE_FILE).read_bytes() == provenance
    again = load_reference(scene)  # still valid: same scene hash, same images
    np.testing.assert_array_equal(again.image, ref.image)
    recorded = recorded_verdicts(ref.folder)
    rec = recorded["seeded-noise"]
    assert rec["passed"] and rec["spp"] == 64 and rec["engine"] == "seeded-noise" and "command" in rec
    assert json.loads((tmp_path / VERDICTS_FILE).read_text()) == recorded
    assert verdict_line(recorded) == f"verified by seeded-noise: max |z| {rec['max_abs_z']:.1f} (1 region, 64 spp)"
    assert verdict_line({}) == "not verified"


def test_a_second_engine_adds_its_verdict_beside_the_first(write_scene):
    scene = load_scene(write_scene())
    engine = _entry("tests.user_renderers:SeededNoise")
    ref = build_reference(scene, spp=8, batches=2, entry=engine)
    v = verify_reference(scene, ref, engine, spp=8, batches=2)
    record_verdict(ref.folder, {**v.record, "engine": "first"})
    record_verdict(ref.folder, {**v.record, "engine": "second", "passed": False})
    recorded = recorded_verdicts(ref.folder)
    assert list(recorded) == ["first", "second"]
    assert "verified by first" in verdict_line(recorded) and "DISAGREES with second" in verdict_line(recorded)


def test_a_rebuilt_reference_shows_no_verdict_recorded_on_its_old_images(write_scene):
    scene = load_scene(write_scene())
    engine = _entry("tests.user_renderers:SeededNoise")
    ref = build_reference(scene, spp=8, batches=2, entry=engine)
    record_verdict(ref.folder, verify_reference(scene, ref, engine, spp=8, batches=2).record)
    assert list(recorded_verdicts(ref.folder)) == ["seeded-noise"]
    build_reference(scene, spp=8, batches=4, entry=engine)  # other seeds, other images
    assert recorded_verdicts(ref.folder) == {}
    assert "seeded-noise" in json.loads((ref.folder / VERDICTS_FILE).read_text())  # kept, but not shown


def test_one_batch_takes_the_engines_own_variance_and_is_refused_without_one(write_scene):
    cornell = load_scene(CORNELL)
    ref = load_reference(cornell)
    unbiased = verify_reference(cornell, ref, _entry("tests.user_renderers:ScaledMitsubaNoise"), spp=64, batches=1)
    assert unbiased.agreement.passed, unbiased.agreement.message()
    assert unbiased.record["variance"] == "the engine's own variance of its mean"
    biased = verify_reference(cornell, ref, _entry("tests.user_renderers:Biased1Percent"), spp=64, batches=1)
    assert not biased.agreement.passed
    assert {f[0] for f in biased.agreement.failures} >= {"whole image", "walls", "light"}
    scene = load_scene(write_scene())
    noise = _entry("tests.user_renderers:SeededNoise")
    with pytest.raises(VerifyError, match="reports no variance"):
        verify_reference(scene, build_reference(scene, spp=4, batches=2, entry=noise), noise, spp=4, batches=1)
    with pytest.raises(VerifyError, match="multiple"):
        verify_reference(scene, load_reference(scene), noise, spp=10, batches=4)


# ---------------------------------------------------------------- power, with Mitsuba on both sides

SMALL = ["camera.resolution=64,64"]
SPP, BATCHES = 1024, 8


def _caustics(*overrides: str):
    return resolve_scene("cornell-box-caustics", [*SMALL, *overrides])


def _mitsuba():
    entry = _entry("mitsuba")
    if not entry.available:
        pytest.skip(f"mitsuba unavailable: {entry.reason}")
    return entry


@pytest.fixture(scope="module")
def right_render():
    """The right scene rendered once by Mitsuba at the verification's seeds: (image, variance), shared."""
    image, variance, *_ = render_engine(_caustics(), _mitsuba(), SPP, BATCHES)
    return image, variance


def _verdict(built_from, tmp_path, engine_render):
    """Build a reference of ``built_from`` with Mitsuba and judge the right scene's independent render against it."""
    build_reference(built_from, SPP, BATCHES, _mitsuba(), folder=tmp_path / "ref")
    ref = load_reference(built_from, tmp_path / "ref")
    return reference_agreement(ref.image, ref.variance, *engine_render, region_masks(_caustics()))


def test_a_reference_built_right_passes(tmp_path, right_render):
    a = _verdict(_caustics(), tmp_path, right_render)
    assert a.passed, a.message()
    assert {r.name for r in a.regions} == {"whole image", "caustic", "glass-shadow", "mirror", "glass", "walls"}


def test_a_reference_built_with_the_wrong_ior_fails_in_the_caustic(tmp_path, right_render):
    """Glass of IOR 1.33 focuses the caustic less: the stored caustic is ~26% darker (measured z ≈ 6)."""
    a = _verdict(_caustics("materials.glass.int_ior=1.33"), tmp_path, right_render)
    assert not a.passed
    assert a.failures[0][0] == "caustic" and a.failures[0][2] > 0


@pytest.mark.slow
def test_a_reference_built_with_a_perfect_mirror_fails_in_the_mirror(tmp_path):
    """Mirror reflectance 1.0 instead of 0.95: the stored mirror is ~5% brighter. At 64² and 1024 spp the mirror's
    196 pixels give z = −3.46, at the edge of the level; at 128² (849 pixels) z = −8.6 (measured)."""
    size = ["camera.resolution=128,128"]
    mitsuba = _mitsuba()
    wrong = resolve_scene("cornell-box-caustics", [*size, "materials.mirror.reflectance=1,1,1"])
    build_reference(wrong, SPP, BATCHES, mitsuba, folder=tmp_path / "ref")
    v = verify_reference(resolve_scene("cornell-box-caustics", size), load_reference(wrong, tmp_path / "ref"),
                         mitsuba, SPP, BATCHES)
    assert not v.agreement.passed
    mirror = next(r for r in v.agreement.regions if r.name == "mirror")
    assert (mirror.p < v.agreement.level).any() and (mirror.z < 0).all()


@pytest.mark.slow
def test_the_stored_caustics_reference_passes_against_mitsuba_at_other_seeds():
    mitsuba = _mitsuba()
    scene = resolve_scene("cornell-box-caustics")
    v = verify_reference(scene, load_reference(scene), mitsuba, spp=256, batches=8)
    assert v.agreement.passed, v.agreement.message()
