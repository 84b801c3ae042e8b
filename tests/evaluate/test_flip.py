"""HDR-FLIP as a metric (cornell_harness.evaluate.flip): its exposure range, its map and mean, its place in the registry."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import CORNELL
from cornell_harness.evaluate import flip, metrics
from cornell_harness.evaluate.convergence import parse_target
from cornell_harness.evaluate.registry import COLOUR_METRICS, IMAGE_METRICS, METRICS
from cornell_harness.gate.config import GateConfigError, load_config
from cornell_harness.store.exr import read_exr


@pytest.fixture(scope="module")
def reference() -> np.ndarray:
    return read_exr(CORNELL.parent / "reference.exr")


@pytest.fixture(scope="module")
def crop(reference) -> np.ndarray:
    """64 × 64 pixels around the light (FLIP costs about 0.1 s per exposure at 256 × 256): 7 exposures."""
    return reference[16:80, 96:160]


def _noisy(ref: np.ndarray, rel_sd: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.maximum(ref * (1.0 + rel_sd * rng.standard_normal(ref.shape)), 0.0).astype(np.float32)


def test_an_image_against_itself_scores_zero(crop):
    assert flip.flip_parameters(crop)["numExposures"] == 7
    assert flip.flip_mean(crop, crop) == 0.0
    assert not np.any(flip.flip_map(crop, crop))


def test_the_larger_perturbation_scores_higher(crop):
    small, large = (flip.flip_mean(_noisy(crop, sd, 1), crop) for sd in (0.05, 0.3))
    assert 0.0 < small < large < 1.0
    # A uniformly 20 % too bright image is a visible difference too, though it adds no edges.
    assert flip.flip_mean(crop * 1.2, crop) > 0.01


def test_aces_maps_x_max_to_the_target():
    a, b, c, d, e, f = flip.ACES_COEFFICIENTS
    x = flip.tone_mapper_input_for()
    assert (a * x * x + b * x + c) / (d * x * x + e * x + f) == pytest.approx(flip.EXPOSED_TARGET, rel=1e-12)
    assert x > 0


def test_explicit_exposures_are_what_the_library_picks(reference):
    """Our parameters equal flip_evaluator's own choice on the reference (it computes in float32), and so
    do the maps."""
    img = _noisy(reference, 0.2, 2)
    ours = flip.flip_parameters(reference)
    auto_map, _, auto = flip.flip_library().evaluate(flip.flip_input(reference), flip.flip_input(img), "HDR",
                                                      applyMagma=False, computeMeanError=False, parameters={})
    assert ours["numExposures"] == auto["numExposures"] and ours["tonemapper"] == auto["tonemapper"]
    for key in ("ppd", "startExposure", "stopExposure"):
        assert ours[key] == pytest.approx(auto[key], rel=1e-6, abs=1e-6), key
    assert ours["stopExposure"] - ours["startExposure"] > 1  # the light and the walls: several stops apart
    np.testing.assert_allclose(flip.flip_map(img, reference), auto_map[..., 0], atol=1e-4)


def test_mostly_black_and_black_references():
    """Where half the pixels are black the median is 0 (the library would expose 26 stops down); ours is the lit
    pixels' median."""
    ref = np.zeros((16, 16, 3), np.float32)
    ref[:4] = 0.4
    ref[0, 0] = 8.0
    p = flip.flip_parameters(ref)
    x_max = flip.tone_mapper_input_for()
    assert p["startExposure"] == pytest.approx(np.log2(x_max / 8.0))
    assert p["stopExposure"] == pytest.approx(np.log2(x_max / 0.4)) and p["numExposures"] == 5  # log2(20)
    assert flip.flip_mean(ref, ref) == 0.0 and flip.flip_mean(ref * 2, ref) > 0
    black = np.zeros_like(ref)
    assert flip.flip_parameters(black) is None and np.isnan(flip.flip_mean(ref, black))


def test_broken_and_negative_pixels_count_as_black(crop):
    img = crop.copy()
    img[5, 5] = [np.nan, 1.0, 1.0]
    img[6, 6] = [-1.0, -1.0, -1.0]
    zeroed = crop.copy()
    zeroed[5, 5] = zeroed[6, 6] = 0.0
    assert flip.flip_mean(img, crop) == flip.flip_mean(zeroed, crop) > 0


def test_flip_mean_is_a_registered_radiance_metric_that_a_gate_can_budget(crop, tmp_path):
    m = METRICS["flip_mean"]
    assert m.better == "low" and m.per_image and "flip_mean" in IMAGE_METRICS and "flip_mean" in COLOUR_METRICS
    img = _noisy(crop, 0.1, 3)
    assert metrics.image_metrics(img, crop)["flip_mean"] == flip.flip_mean(img, crop)
    assert "flip_mean" not in metrics.image_metrics(img, crop, quantity="ambient_occlusion")
    assert parse_target("flip_mean=0.05") == ("flip_mean", 0.05)
    gate = '[[expect]]\nscene = "cornell-box"\nrenderer = "pathtracer"\nspp = 4\nmax = {{ {} = 0.1 }}\n'
    (tmp_path / "ok.toml").write_text(gate.format("flip_mean"))
    assert load_config(tmp_path / "ok.toml").expectations[0].max == {"flip_mean": 0.1}
    (tmp_path / "typo.toml").write_text(gate.format("flip_maen"))
    with pytest.raises(GateConfigError, match="did you mean 'flip_mean'"):
        load_config(tmp_path / "typo.toml")
