"""The orientation note: a flipped or mirrored image is named, a correct one never is (fixed seeds).

A fixed-seed sample of ``benchmarks/orientation.py``'s measurement (BENCHMARKS.md): correct renders noted are
false alarms, and each transform of them must be caught.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cornell_harness.adapters.registry import resolve
from cornell_harness.evaluate.orientation import RATIO, TRANSFORMS, check_orientation, noise_rel_mse
from cornell_harness.scenes.library import resolve_scene, scene_names
from cornell_harness.store.references import Reference, load_reference
from cornell_harness.workflows.render import render_checked

FLIP, MIRROR, BOTH = TRANSFORMS


def _reference(image: np.ndarray, variance: float | None = None, spp: int = 1024) -> Reference:
    var = None if variance is None else np.full_like(image, variance)
    return Reference(image.astype(np.float32), var, None, {"spp": spp, "noise_spp": 1}, Path("."))


def _gradient(h=64, w=96) -> np.ndarray:
    rows, cols = np.mgrid[0:h, 0:w] / np.array([h, w])[:, None, None]
    return np.stack([0.2 + rows, 0.2 + cols, 0.2 + rows * cols], axis=-1)


def test_each_transform_is_named_and_the_image_as_it_is_is_not():
    ref = _reference(_gradient())
    assert check_orientation(ref.image, ref).note is None
    for name, transform in TRANSFORMS.items():
        result = check_orientation(transform(ref.image), ref)
        assert result.looks == name and result.note.startswith(f"image looks {name}: "), result
        assert result.transformed[name] < RATIO * result.rel_mse


def test_a_scene_symmetric_under_every_transform_is_never_noted():
    """A uniform image (the furnaces) agrees as well transformed as not: the ratio is 1, whatever the noise."""
    ref = _reference(np.full((32, 32, 3), 0.5))
    noisy = ref.image + np.random.default_rng(0).normal(0, 0.2, ref.image.shape)
    assert check_orientation(noisy, ref).looks is None


def test_not_noted_within_the_noise_of_its_spp():
    """The ratio holds for a slightly asymmetric scene flipped, but its relMSE as it is lies within what noise
    gives at 1 spp: not noted then; at 1024 spp (noise far below) it is."""
    image = 1.0 + 0.02 * _gradient()
    ref = _reference(image, variance=1e-6, spp=1024)
    flipped = image[::-1]
    assert check_orientation(flipped, ref).looks == FLIP
    assert check_orientation(flipped, ref, spp=1024).looks == FLIP
    low = check_orientation(flipped, ref, spp=1)
    assert low.looks is None and low.rel_mse < 2 * low.noise_rel_mse


def test_noise_rel_mse_is_what_noise_model_draws_give():
    """The expected relMSE of noise on block means, against draws of that noise (256², 8-pixel blocks)."""
    rng = np.random.default_rng(1)
    image = rng.uniform(0.1, 1.0, (256, 256, 3))
    ref = _reference(image, variance=1e-3, spp=64)
    expected = noise_rel_mse(ref, 4)
    sd = np.sqrt(1e-3 * (64 / 4 + 1))  # a 4-spp image minus the reference (noise.difference_variance)
    drawn = [check_orientation(image + rng.normal(0, sd, image.shape), ref).rel_mse for _ in range(20)]
    assert np.mean(drawn) == pytest.approx(expected, rel=0.1)


def test_no_false_alarm_on_noise_model_draws_of_every_stored_scene():
    """Every stored scene at 1 and 16 spp, 4 Gaussian draws each of its reference's noise model (seed 0): none
    noted as it is; each transform that changes the scene is caught."""
    rng = np.random.default_rng(0)
    for name in scene_names():
        ref = load_reference(resolve_scene(name).at_frame(0))
        itself = check_orientation(ref.image, ref).transformed
        for spp in (1, 16):
            sd = np.sqrt(np.asarray(ref.variance, np.float64) * ref.spp / spp)
            for _ in range(4):
                image = ref.image + sd * rng.standard_normal(ref.image.shape)
                assert check_orientation(image, ref, spp).looks is None, (name, spp)
                for t, transform in TRANSFORMS.items():
                    if itself[t] > 1e-3:  # the scene is not (nearly) symmetric under it
                        assert check_orientation(transform(image), ref, spp).looks is not None, (name, spp, t)


def test_no_false_alarm_on_path_tracer_renders_and_every_flip_caught():
    """Our path tracer's renders of cornell-box at 1 and 4 spp, seeds 0-4: none noted; flipped, mirrored (the
    red and green walls swap) and rotated, each named."""
    scene = resolve_scene("cornell-box")
    ref = load_reference(scene)
    (entry,) = resolve(["pathtracer"])
    for spp in (1, 4):
        for seed in range(5):
            image = render_checked(entry, scene, spp, seed).image
            assert check_orientation(image, ref, spp).note is None, (spp, seed)
            for name, transform in TRANSFORMS.items():
                assert check_orientation(transform(image), ref, spp).looks == name, (spp, seed, name)
