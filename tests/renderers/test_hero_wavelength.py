"""The path tracer's ``spectral = "hero"`` mode (src/cornell_harness/renderers/hero_wavelength.py) against closed forms, and its rules.

Monte Carlo tolerances are z-tests of the image mean, whose standard error
comes from the spread of the pixels (every pixel of a furnace has the same
expectation, and pixels are independent); each test states its false-alarm
rate α (two-sided, Šidák over its channels and cases). Seeds are fixed, so a
verdict is reproducible; α says how often a correct renderer would fail over
fresh seeds.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math

import numpy as np
import pytest

from tests import mutants
from tests.renderers.test_pathtracer import z_crit
from cornell_harness.adapters.registry import resolve
from cornell_harness.adapters.settings import SettingsError
from cornell_harness.scenes.analytic import SPECTRAL_FURNACE_EMISSION, furnace_radiance, spectral_furnace_radiance, spectral_furnace_scene
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.model import Diffuse
from cornell_harness.scenes.spectra import emission_rgb
from cornell_harness.renderers.pathtracer import PathTracer

pytest.importorskip("embreex")

HERO = {"spectral": "hero"}


def mean_z(image: np.ndarray, expected) -> np.ndarray:
    """z of the image mean against ``expected`` per channel, the standard error from the pixels' spread."""
    px = image.astype(np.float64).reshape(-1, 3)
    se = px.std(axis=0, ddof=1) / math.sqrt(px.shape[0])
    return (px.mean(axis=0) - np.asarray(expected)) / se


#: (max_depth, spp, seed, sampler): unbounded (ρ ≤ 0.85, so up to ~7x the emission in the green band) and cut
#: at 3 segments; pmj02 (the default) and independent numbers.
FURNACE_CASES = [(-1, 64, 11, "pmj02"), (3, 32, 5, "pmj02"), (-1, 32, 3, "independent")]


def check_spectral_furnace(renderer, max_depth: int = -1, spp: int = 64, seed: int = 11, sampler: str = "pmj02",
                           tests: int = len(FURNACE_CASES)) -> None:
    """The hero image of the spectral furnace (16², ``spp``) has the closed form's mean in every channel:
    |z| below the Šidák bound for α = 1e-3 over ``tests`` cases × 3 channels."""
    scene = spectral_furnace_scene(max_depth, res=16)
    img = renderer.render(scene, spp, seed, settings={**HERO, "sampler": sampler}).image
    z = mean_z(img, spectral_furnace_radiance(max_depth))
    assert np.all(np.abs(z) < z_crit(1e-3, 3 * tests)), (z, img.reshape(-1, 3).mean(axis=0))


@pytest.mark.parametrize("max_depth, spp, seed, sampler", FURNACE_CASES)
def test_hero_matches_the_spectral_furnace(max_depth, spp, seed, sampler):
    """L(λ)/(1-ρ(λ)) (or the series cut at max_depth) per wavelength, projected as emission_rgb projects an
    emitter (cornell_harness.scenes.analytic.spectral_furnace_radiance). α = 1e-3 over the 9 channel tests."""
    check_spectral_furnace(PathTracer(threads=2), max_depth, spp, seed, sampler)


def test_rgb_rendering_of_the_same_scene_misses_it():
    """The RGB path tracer on the scene's RGB projection converges to Le_c/(1-ρ_c) per channel, not to the
    spectral answer: its mean agrees with the former (α = 1e-3 over 3 channels) and is > 50 standard errors off
    the latter in some channel at 16 spp (the difference is 44% in red, 13% in green; the test resolves ~1%).
    That is the error of RGB rendering that issue 33 is about, far beyond the noise."""
    scene = spectral_furnace_scene(res=16)
    img = PathTracer(threads=2).render(scene, 16, seed=11).image
    rho, le = scene.materials["grey"].reflectance, scene.meshes[0].radiance
    rgb_answer = [furnace_radiance(r, e, -1) for r, e in zip(rho, le)]
    assert np.all(np.abs(mean_z(img, rgb_answer)) < z_crit(1e-3, 3))
    assert np.abs(mean_z(img, spectral_furnace_radiance())).max() > 50


def test_a_spectral_emitter_seen_directly_is_its_emission_rgb():
    """max_depth 1: the camera sees the emitting walls only, so the image is the emission spectrum through the
    wavelength sampling alone: its mean is emission_rgb(L) (α = 1e-3 over 3 channels), the scene model's scale."""
    scene = spectral_furnace_scene(max_depth=1, res=16)
    img = PathTracer(threads=2).render(scene, 16, seed=4, settings=HERO).image
    want = np.array(emission_rgb(SPECTRAL_FURNACE_EMISSION))
    assert np.all(np.abs(mean_z(img, want)) < z_crit(1e-3, 3)), (img.reshape(-1, 3).mean(axis=0), want)


def test_same_seed_same_image_at_any_thread_count():
    scene = spectral_furnace_scene(res=12)
    a = PathTracer(threads=1).render(scene, 8, seed=9, settings=HERO)
    b = PathTracer(threads=2).render(scene, 8, seed=9, settings=HERO)
    assert a.image.tobytes() == b.image.tobytes() and a.variance.tobytes() == b.variance.tobytes()
    assert a.info["spectral"] == "hero"


def test_hero_reads_the_spectra_not_their_rgb_projection():
    """The two RGB conventions project the albedo differently, and the RGB renders differ; the hero render reads
    the spectra only (its emitter sampling, by the emitters' RGB power, is the same under both), so its image is
    bit for bit the same."""
    a, b = (spectral_furnace_scene(3, res=8, convention=c) for c in ("illuminant_E", "scene_light"))
    assert a.materials["grey"].reflectance != b.materials["grey"].reflectance
    ra, rb = (PathTracer(threads=2).render(s, 4, seed=2, settings=HERO) for s in (a, b))
    assert ra.image.tobytes() == rb.image.tobytes()
    assert PathTracer(threads=2).render(a, 4, 2).image.tobytes() != PathTracer(threads=2).render(b, 4, 2).image.tobytes()


@pytest.mark.parametrize("sampler", ["independent", "pmj02"])
def test_reported_variance_is_the_pixels_spread_as_in_rgb(sampler):
    """The film's variance of the mean holds for hero images as for RGB ones. In the furnace every pixel has the
    closed form's expectation, so z = (pixel − expected)/√variance should have unit spread; over 3 × 256 pixels
    at 256 spp the hero's sd is near the RGB path tracer's on the same scene (at its own RGB answer) and near 1.
    Over seeds 1-8 (measured): independent sd 0.98-1.12, ratio to RGB 0.97-1.12; pmj02, whose variance comes from
    8 batches (a t-like z of 7 degrees of freedom, sd ≥ √(7/5) = 1.18), sd 1.17-1.42, ratio 0.93-1.17. The
    bounds leave room for that spread; a variance 4x off would move the sd 2x."""
    scene = spectral_furnace_scene(-1, res=16)
    rho, le = scene.materials["grey"].reflectance, scene.meshes[0].radiance
    sd = {}
    for mode, expected in (("rgb", [furnace_radiance(r, e, -1) for r, e in zip(rho, le)]),
                           ("hero", spectral_furnace_radiance(-1))):
        r = PathTracer(threads=2).render(scene, 256, seed=8, settings={"spectral": mode, "sampler": sampler})
        sd[mode] = ((r.image.astype(np.float64) - expected) / np.sqrt(r.variance.astype(np.float64))).std()
    (lo, hi), ratio = {"independent": ((0.85, 1.3), 0.2), "pmj02": ((1.0, 1.65), 0.3)}[sampler]
    assert lo < sd["hero"] < hi and abs(sd["hero"] / sd["rgb"] - 1.0) < ratio, sd


#: (max_depth, res, spp, seed, sampler) -> sha256 of image then variance, float32 bytes (as
#: tests/renderers/test_pathtracer_pinned.py): the hero estimator's numbers, pinned bit for bit. A deliberate
#: change (wavelength sampling, the tables, the sensor weights) changes it: re-pin and say so in the commit.
PINNED = {(-1, 8, 4, 3, "pmj02"): "574d3ad44d0987479fd60485965fb101a12ddc70979fbb56a4da0a6ec2fd3e3b"}


@pytest.mark.parametrize("case", sorted(PINNED))
def test_hero_image_is_bit_identical_to_the_pinned_one(case):
    max_depth, res, spp, seed, sampler = case
    r = PathTracer(threads=2).render(spectral_furnace_scene(max_depth, res=res), spp, seed,
                                     settings={**HERO, "sampler": sampler})
    data = np.ascontiguousarray(r.image, np.float32).tobytes() + np.ascontiguousarray(r.variance, np.float32).tobytes()
    assert hashlib.sha256(data).hexdigest() == PINNED[case]


def test_the_setting_is_declared_with_rgb_the_default():
    (entry,) = resolve(["pathtracer[spectral=hero]"])
    assert entry.settings["spectral"] == "hero" and entry.name == 'pathtracer[spectral="hero"]'
    assert resolve(["pathtracer"])[0].settings["spectral"] == "rgb"
    with pytest.raises(SettingsError, match="spectral='hero4': expected one of rgb, hero"):
        resolve(["pathtracer[spectral=hero4]"])


def test_rgb_only_fields_are_refused_with_the_field_named():
    with pytest.raises(ValueError, match="'cornell-box' has no spectra"):
        PathTracer().render(resolve_scene("cornell-box"), 1, 0, settings=HERO)
    scene = spectral_furnace_scene(res=4)
    grey = dataclasses.replace(scene, materials={**scene.materials, "other": Diffuse("other", (0.5, 0.5, 0.5))},
                               meshes=(dataclasses.replace(scene.meshes[0], material="other"),))
    with pytest.raises(ValueError, match="material 'other'.s reflectance is RGB only"):
        PathTracer().render(grey, 1, 0, settings=HERO)
    rgb_light = dataclasses.replace(scene, spectral=dataclasses.replace(scene.spectral, emitters={}))
    with pytest.raises(ValueError, match="mesh 'box'.s emission is RGB only"):
        PathTracer().render(rgb_light, 1, 0, settings=HERO)
    with pytest.raises(ValueError, match="AOVs"):
        PathTracer().render(scene, 1, 0, settings=HERO, aovs=("albedo", "normal"))


# -- the measured Cornell box against Mitsuba's spectral reference ------------------------------------------

MEASURED = "cornell-box-measured"


@pytest.mark.slow  # two 64-spp renders of 256² (~6 s on a quiet 2-core machine, ~40 s on a busy one)
def test_hero_agrees_with_the_spectral_reference_and_rgb_does_not():
    """cornell-box-measured (issue 33): the hero image passes the agreement test (the gate's: tiles of 16, the
    regions, the whole image; α = 0.01 family-wise) against the stored Mitsuba spectral reference, and the RGB
    path tracer on the scene's RGB projection does not (measured here: hero's smallest p 1.4e-4 against the
    per-test level 4.3e-6; RGB's 109 of 789 tests reject, worst z = 130 in blue on the red wall, tile mean
    +193%). Skipped where the scene and its reference are not stored (they come from the ``measured`` branch)."""
    from cornell_harness.evaluate.agreement import agreement_test
    from cornell_harness.evaluate.regions import region_masks
    from cornell_harness.scenes.library import references_root
    from cornell_harness.store.references import load_reference

    if not (references_root() / MEASURED / "reference.exr").exists():
        pytest.skip(f"no stored {MEASURED} reference in this tree")
    scene = resolve_scene(MEASURED)
    ref = load_reference(scene)
    masks = region_masks(scene)
    verdict = {}
    for mode in ("hero", "rgb"):
        r = PathTracer(threads=2).render(scene, 64, seed=0, settings={"spectral": mode})
        verdict[mode] = agreement_test(r.image, r.variance, ref.image, ref.variance, tile=16, alpha=0.01,
                                       regions=masks)
    assert verdict["hero"].passed, verdict["hero"].failures[:3]
    assert not verdict["rgb"].passed and max(abs(f["z"]) for f in verdict["rgb"].failures) > 10


# -- the mutants (tests/mutants/spectral.py) ------------------------------------------------------------

SPECTRAL_MUTANTS = sorted(mutants.SPECTRAL)


@pytest.mark.slow  # each compiles a copy of the toolkit and the hero integrator (~30-60 s)
@pytest.mark.parametrize("name", SPECTRAL_MUTANTS)
def test_mutant_is_caught(name, tmp_path_factory):
    """Each spectral mutant fails the spectral furnace (the closed form; the gate's cornell-box-measured expectation
    fails each too: tests/gate/test_gate_power.py::test_gate_detects_mutant)."""
    assert len(SPECTRAL_MUTANTS) == 3
    module = mutants.load_module(name, tmp_path_factory.mktemp("hero-mutants"))
    with pytest.raises(AssertionError):
        check_spectral_furnace(module.PathTracer(threads=2), *FURNACE_CASES[0])
